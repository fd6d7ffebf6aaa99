"""Per-step time of World.step against coal's own detection, MuJoCo, PyBullet and Rapier.

    .venv/bin/python bench/bench_step.py [--sizes 10 100 1000] [--piles mixed cubes]
        [--steps 20] [--settle 1.0] [--peer-venv DIR | --no-peers] [--out FILE]

(``make bench`` runs it with the defaults.) For each pile (bench/pile.py: ``mixed``
cubes and spheres, ``cubes`` only) and size: build the pile, let it settle with the
core and a semi-implicit Euler integrator at 120 Hz, then time ``--steps`` more
steps of World.step (median and 90th percentile of the whole step and of its
detection and solve phases; contact points per step and how many became solver
rows, and the solve's cost per row per velocity sweep in ns). The same pile is then
settled and timed again at 30 Hz: the ratio of that step to the 120 Hz one is printed
(a step four times longer should not cost much more). On the same 120 Hz final poses it
times coal's own detection alone: the DynamicAABBTree broad phase and narrow phase of
``collide`` (one contact per pair), the C++ calls only (the finite bodies in the tree,
each half-space queried against it, as half-spaces in the tree miss pairs). Then MuJoCo
(CG and Newton solvers), PyBullet and Rapier (``rapier3d``) step the same pile in the
peers' throw-away venv (``--peer-venv``, default $COLLRES_PEER_VENV or
~/.cache/collres_ros/peer-venv, outside the repository; set up with ``pip install mujoco
pybullet rapier3d`` when one is missing), reporting ms per step and contact points per
step. Ratios are ours / theirs in the same run. The table is also written as JSON
(``--out``, default ``bench_out/step.json``). Timings on a shared machine: read the
ratios, not the absolute numbers.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import coal
import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from collres_ros.core.config import SolverSettings  # noqa: E402
from collres_ros.core.rotation import to_matrix  # noqa: E402
from collres_ros.core.shapes import make_geometry  # noqa: E402
from collres_ros.core.world import World  # noqa: E402
from pile import bin_half_width, describe, integrate, make_pile, PILES  # noqa: E402

DT = 1.0 / 120.0
ROOT = HERE.parent
PEER_ENGINES = ('mujoco_cg', 'mujoco_newton', 'pybullet', 'rapier')
SLOW_DT = 1.0 / 30.0   # s, the low-rate step compared with the 120 Hz one


def coal_detection(bodies, state, repeats: int = 20) -> tuple[float, int]:
    """(median ms, contacts) of coal's own broad + narrow phase on these poses.

    Only coal's C++ calls are timed (tree update, collide-all, one query per
    half-space); the transforms are set beforehand. Pairs closer than the
    speculative margin count, as in our detection (coal's security margin).
    """
    margin = SolverSettings().speculative_margin
    manager = coal.DynamicAABBTreeCollisionManager()
    planes, objects = [], []          # (the manager holds raw pointers: keep them alive)
    rot = to_matrix(state.orientation)
    for spec, r, p in zip(bodies, rot, state.position):
        obj = coal.CollisionObject(make_geometry(spec), coal.Transform3s(r, p))
        obj.computeAABB()
        objects.append(obj)
        if spec.shape == 'plane':
            planes.append(obj)
        else:
            manager.registerObject(obj)
    manager.setup()
    times, contacts = [], 0
    for _ in range(repeats):
        callback = coal.CollisionCallBackDefault()
        callback.data.request.num_max_contacts = 10 ** 8
        callback.data.request.security_margin = margin
        start = time.perf_counter()
        manager.update()
        manager.collide(callback)
        contacts = callback.data.result.numContacts()    # (each collide starts afresh)
        for plane in planes:
            manager.collide(plane, callback)
            contacts += callback.data.result.numContacts()
        times.append(time.perf_counter() - start)
    return 1000.0 * float(np.median(times)), int(contacts)


def settled_steps(kind: str, size: int, steps: int, settle_s: float, dt: float):
    """Settle a pile at step ``dt``, then time ``steps`` more World.step calls.

    Returns (bodies, final state, per-step lists: total s, detect s, solve s, contact
    points, solver rows, velocity sweeps).
    """
    bodies, state = make_pile(size, kind=kind)
    world = World(bodies, SolverSettings())
    for _ in range(int(settle_s / dt)):
        state = world.step(state, integrate(state, world.dynamic, dt), dt).states
    timed = {key: [] for key in ('total', 'detect', 'solve', 'contacts', 'rows', 'sweeps')}
    for _ in range(steps):
        current = integrate(state, world.dynamic, dt)
        start = time.perf_counter()
        result = world.step(state, current, dt)
        timed['total'].append(time.perf_counter() - start)
        timed['detect'].append(world.timing['detect'])
        timed['solve'].append(world.timing['solve'])
        timed['contacts'].append(result.report.contacts.count)
        timed['rows'].append(world.timing['rows'])
        timed['sweeps'].append(world.timing['iterations'])
        state = result.states
    return bodies, state, timed


def ours(kind: str, size: int, steps: int, settle_s: float) -> dict:
    bodies, state, timed = settled_steps(kind, size, steps, settle_s, DT)
    ms = (lambda v, q: 1000.0 * float(np.percentile(v, q)))
    coal_ms, coal_contacts = coal_detection(bodies, state)
    # solve cost per solver row per velocity sweep, ns (median over the timed steps)
    work = np.array(timed['rows'], float) * np.array(timed['sweeps'], float)
    per_row = np.array(timed['solve']) * 1e9 / np.maximum(work, 1.0)
    slow = settled_steps(kind, size, steps, max(settle_s, 30 * SLOW_DT), SLOW_DT)[2]
    return {'pile': kind, 'bodies': size, 'contacts': int(np.median(timed['contacts'])),
            'rows': int(np.median(timed['rows'])),
            'sweeps': int(np.median(timed['sweeps'])),
            'step_ms': [ms(timed['total'], 50), ms(timed['total'], 90)],
            'detect_ms': [ms(timed['detect'], 50), ms(timed['detect'], 90)],
            'solve_ms': [ms(timed['solve'], 50), ms(timed['solve'], 90)],
            'ns_per_row_sweep': float(np.median(per_row)),
            'step_30hz_ms': ms(slow['total'], 50),
            'rows_30hz': int(np.median(slow['rows'])),
            'coal_ms': coal_ms, 'coal_contacts': coal_contacts,
            'largest_speed': float(np.abs(state.linear).max()),
            '_scene': describe(bodies, state)}


PEER_PACKAGES = ('mujoco', 'pybullet', 'rapier3d')


def peer_python(venv: Path) -> Path | None:
    """The peers' interpreter, creating their venv (mujoco, pybullet, rapier3d) when missing."""
    python = venv / 'bin' / 'python'
    check = [str(python), '-c', 'import mujoco, pybullet, rapier3d']
    if python.exists() and subprocess.run(check, capture_output=True).returncode == 0:
        return python
    print(f'setting up the peers\' venv {venv} (pip install {" ".join(PEER_PACKAGES)}) ...',
          flush=True)
    try:
        if not python.exists():
            subprocess.run([sys.executable, '-m', 'venv', str(venv)], check=True)
        subprocess.run([str(python), '-m', 'pip', 'install', '-q', '--disable-pip-version-check',
                        *PEER_PACKAGES], check=True, timeout=1800)
    except (OSError, subprocess.SubprocessError) as error:
        print(f'peers: cannot set up {venv}: {error}', file=sys.stderr)
        return None
    return python


def peers(python: Path, row: dict, steps: int) -> dict:
    scene = dict(row['_scene'], half_width=bin_half_width(row['bodies']), dt=DT, warmup=30,
                 steps=steps)
    with tempfile.NamedTemporaryFile('w', suffix='.json', delete=False) as handle:
        json.dump(scene, handle)
    try:
        out = subprocess.run([str(python), str(HERE / 'peers.py'), handle.name],
                             capture_output=True, text=True, timeout=3600, check=True)
        return json.loads(out.stdout.strip().splitlines()[-1])
    except (OSError, subprocess.SubprocessError, ValueError) as error:
        print(f'peers: {error}', file=sys.stderr)
        return {name: None for name in PEER_ENGINES}
    finally:
        os.unlink(handle.name)


def print_row(row: dict) -> None:
    cell = (lambda v: f'{v["ms"]:.2f} ({v["contacts"]:.0f})' if v else 'n/a')
    ratio = (lambda v: f'{row["step_ms"][0] / v["ms"]:.2f}' if v else 'n/a')
    peer = [row['peers'].get(name) for name in PEER_ENGINES]
    print(FORMAT.format(
        row['pile'], row['bodies'], f'{row["step_ms"][0]:.2f}/{row["step_ms"][1]:.2f}',
        f'{row["detect_ms"][0]:.2f}', f'{row["solve_ms"][0]:.2f}',
        f'{row["contacts"]}/{row["rows"]}', f'{row["coal_ms"]:.2f} ({row["coal_contacts"]})',
        f'{row["detect_ms"][0] / row["coal_ms"]:.1f}', f'{row["ns_per_row_sweep"]:.0f}',
        f'{row["step_30hz_ms"] / row["step_ms"][0]:.2f}', *[cell(v) for v in peer],
        *[ratio(v) for v in peer]), flush=True)


FORMAT = ('{:>6} {:>6} {:>13} {:>7} {:>7} {:>11} {:>14} {:>8} {:>7} {:>7} {:>15} {:>15} '
          '{:>15} {:>15} {:>6} {:>6} {:>6} {:>6}')


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--sizes', type=int, nargs='+', default=[10, 100, 1000])
    parser.add_argument('--piles', nargs='+', default=list(PILES), choices=PILES)
    parser.add_argument('--steps', type=int, default=20)
    parser.add_argument('--settle', type=float, default=1.0, help='settling time, s')
    cache = Path(os.environ.get('XDG_CACHE_HOME', Path.home() / '.cache'))
    parser.add_argument('--peer-venv', type=Path, default=Path(os.environ.get(
        'COLLRES_PEER_VENV', cache / 'collres_ros' / 'peer-venv')))
    parser.add_argument('--no-peers', action='store_true', help='time the core only')
    parser.add_argument('--out', type=Path, default=ROOT / 'bench_out' / 'step.json')
    args = parser.parse_args(argv)
    python = None if args.no_peers else peer_python(args.peer_venv)
    print(FORMAT.format('pile', 'bodies', 'step p50/p90', 'detect', 'solve', 'points/rows',
                        'coal (pts)', 'det/coal', 'ns/row', '30/120', 'mujoco CG',
                        'mujoco Newton', 'pybullet', 'rapier', 'us/cg', 'us/nt', 'us/pb',
                        'us/rp'))
    rows = []
    for kind in args.piles:
        for size in args.sizes:
            row = ours(kind, size, args.steps, args.settle)
            row['peers'] = peers(python, row, args.steps) if python else \
                {name: None for name in PEER_ENGINES}
            print_row(row)
            del row['_scene']
            rows.append(row)
    print('ms per step at 120 Hz (contact points per step in brackets); points/rows: our '
          'contact points and solver rows; coal: its own broad + narrow phase alone on '
          'the same poses; ns/row: solve time per solver row per velocity sweep; 30/120: '
          'our step at 30 Hz / at 120 Hz on the same pile settled at each rate; us/x: our '
          'step / theirs (same run)')
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps({'dt': DT, 'rows': rows}, indent=1))
    print(f'written {args.out}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
