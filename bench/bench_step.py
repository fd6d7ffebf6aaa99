"""Per-step time of World.step against coal's own detection, MuJoCo and PyBullet.

    .venv/bin/python bench/bench_step.py [--sizes 10 100 1000] [--piles mixed cubes]
        [--steps 20] [--settle 1.0] [--peer-venv DIR | --no-peers] [--out FILE]

(``make bench`` runs it with the defaults.) For each pile (bench/pile.py: ``mixed``
cubes and spheres, ``cubes`` only) and size: build the pile, let it settle with the
core and a semi-implicit Euler integrator at 120 Hz, then time ``--steps`` more
steps of World.step (median and 90th percentile of the whole step and of its
detection and solve phases; contact points per step and how many became solver
rows). On the same final poses it times coal's own detection alone: the
DynamicAABBTree broad phase and narrow phase of ``collide`` (one contact per pair),
the C++ calls only (the finite bodies in the tree, each half-space queried against
it, as half-spaces in the tree miss pairs). Then MuJoCo (CG and Newton solvers) and
PyBullet step the same pile in the peers' throw-away venv (``--peer-venv``, default
$COLLRES_PEER_VENV or ~/.cache/collres_ros/peer-venv, outside the repository; created
with ``pip install mujoco pybullet`` when missing), reporting ms per step and contact
points per step. Ratios are ours / theirs in the same run. The table is also written as JSON
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
PEER_ENGINES = ('mujoco_cg', 'mujoco_newton', 'pybullet')


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


def ours(kind: str, size: int, steps: int, settle_s: float) -> dict:
    bodies, state = make_pile(size, kind=kind)
    world = World(bodies, SolverSettings())
    for _ in range(int(settle_s / DT)):
        state = world.step(state, integrate(state, world.dynamic, DT), DT).states
    total, detect, solve, contacts, rows = [], [], [], [], []
    for _ in range(steps):
        current = integrate(state, world.dynamic, DT)
        start = time.perf_counter()
        result = world.step(state, current, DT)
        total.append(time.perf_counter() - start)
        detect.append(world.timing['detect'])
        solve.append(world.timing['solve'])
        contacts.append(result.report.contacts.count)
        rows.append(world.timing['rows'])
        state = result.states
    ms = (lambda v, q: 1000.0 * float(np.percentile(v, q)))
    coal_ms, coal_contacts = coal_detection(bodies, state)
    return {'pile': kind, 'bodies': size, 'contacts': int(np.median(contacts)),
            'rows': int(np.median(rows)),
            'step_ms': [ms(total, 50), ms(total, 90)],
            'detect_ms': [ms(detect, 50), ms(detect, 90)],
            'solve_ms': [ms(solve, 50), ms(solve, 90)],
            'coal_ms': coal_ms, 'coal_contacts': coal_contacts,
            'largest_speed': float(np.abs(state.linear).max()),
            '_scene': describe(bodies, state)}


def peer_python(venv: Path) -> Path | None:
    """The peers' interpreter, creating their venv (mujoco, pybullet) when missing."""
    python = venv / 'bin' / 'python'
    if python.exists():
        return python
    print(f'creating the peers\' venv {venv} (pip install mujoco pybullet) ...', flush=True)
    try:
        subprocess.run([sys.executable, '-m', 'venv', str(venv)], check=True)
        subprocess.run([str(python), '-m', 'pip', 'install', '-q', '--disable-pip-version-check',
                        'mujoco', 'pybullet'], check=True, timeout=1800)
    except (OSError, subprocess.SubprocessError) as error:
        print(f'peers: cannot create {venv}: {error}', file=sys.stderr)
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
        f'{row["detect_ms"][0] / row["coal_ms"]:.1f}', *[cell(v) for v in peer],
        *[ratio(v) for v in peer]), flush=True)


FORMAT = ('{:>6} {:>6} {:>13} {:>7} {:>7} {:>11} {:>14} {:>8} {:>15} {:>15} {:>15} '
          '{:>6} {:>6} {:>6}')


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
                        'coal (pts)', 'det/coal', 'mujoco CG', 'mujoco Newton', 'pybullet',
                        'us/cg', 'us/nt', 'us/pb'))
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
          'the same poses; us/x: our step / theirs (same run)')
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps({'dt': DT, 'rows': rows}, indent=1))
    print(f'written {args.out}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
