"""Per-step time of World.step against coal's own detection, MuJoCo, PyBullet and Rapier.

    .venv/bin/python bench/bench_step.py [--sizes 10 100 1000] [--piles mixed cubes]
        [--steps 20] [--settle 1.0] [--peer-venv DIR | --no-peers] [--out FILE]

(``make bench`` runs it with the defaults.) For each pile (bench/pile.py: ``mixed``
cubes and spheres, ``cubes`` only) and size: build the pile, let it settle with the
core and a semi-implicit Euler integrator at 120 Hz, then time ``--steps`` more
steps of World.step on the default threads (``SOLVER_TUNING`` ``threads``: 2; median and
90th percentile of the whole step and of its detection and solve phases; contact points
per step and how many became solver rows, how many of those the velocity sweeps visited
(the active set: StepSolver::sweep), how many points carried a normal impulse, and
the solve's cost per row per velocity sweep in ns), and as many steps on one thread (the
same bits), timed apart: the ratio of the one-thread step to the default one is printed.
The two thread counts take turns by blocks of ``BLOCK`` timed steps, each block led by one
untimed step: a user runs one thread count throughout, and a step that follows steps on
the other count finds the pile's data where those left it (in the caches of the caller's
core after one-thread steps; the first step of a block took 0.5-3 % more than the block's
others on the 1000-body piles at 120 Hz); alternating blocks keep the machine's drift alike
on both. The same pile is then
settled and timed again at 30 Hz: the ratio of that step to the 120 Hz one is printed
(a step four times longer should not cost much more), and on a line of its own the 30 Hz
step's detection and solve, points and rows, each against the 120 Hz one. On the same
120 Hz final poses it times coal's own detection alone: the DynamicAABBTree broad phase
and narrow phase of ``collide`` (one contact per pair), the C++ calls only (the finite
bodies in the tree, each half-space queried against it, as half-spaces in the tree miss
pairs). Then MuJoCo (CG and Newton solvers), PyBullet and Rapier (``rapier3d``) step the
same pile in the peers' throw-away venv (``--peer-venv``, default $COLLRES_PEER_VENV or
~/.cache/collres_ros/peer-venv, outside the repository; set up with ``pip install mujoco
pybullet rapier3d`` when one is missing), reporting ms per step and contact points per
step. Ratios are ours / theirs in the same run. The table is also written as JSON
(``--out``, default ``bench_out/step.json``). Timings on a shared machine: read the
ratios, not the absolute numbers.

The columns above are the awake step (``solver.sleeping`` off). Then, per pile and size,
sleeping (``solver.sleeping`` on, the same run; ``--no-sleeping`` skips it):

* asleep: the pile, with one more box held still above it (its upstream applies no
  gravity yet), settled at 120 Hz until every island sleeps (the time it took); then
  ``--steps`` steps timed, and their ratio to the awake step;
* kept moving: the settled pile with a random velocity kick (0.2 m/s rms) on every body
  every step, so nothing ever sleeps, stepped by two worlds, sleeping on and off, on the
  same inputs in alternating order: the overhead of the bookkeeping (on / off - 1);
* the drop: the box released onto the sleeping pile: the step its first contact with the
  pile appears and the first wake before it, the bodies and islands woken by then and by
  the end, its vertical speed before and after the impact (the first IMPACT contact), the
  deepest penetration of the answers (a detector of its own on the answered poses), and
  the largest step time meanwhile.
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
BLOCK = 10             # timed steps in a row on one thread count


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


AWAKE = SolverSettings(sleeping=False)


def settled_steps(kind: str, size: int, steps: int, settle_s: float, dt: float):
    """Settle a pile at step ``dt``, then time ``steps`` more World.step calls (awake).

    Returns (bodies, final state, per-step lists: total s, detect s, solve s, contact
    points, solver rows, velocity sweeps).
    """
    bodies, state = make_pile(size, kind=kind)
    world = World(bodies, AWAKE)
    for _ in range(int(settle_s / dt)):
        state = world.step(state, integrate(state, world.dynamic, dt), dt).states
    timed = {key: [] for key in ('total', 'detect', 'solve', 'contacts', 'rows', 'sweeps',
                                 'carrying', 'swept', 'one_thread')}
    default_threads = world._params.threads
    # blocks of BLOCK steps on each thread count in turn, as a user runs one count
    # throughout (the machine's drift hits both alike); a block's first step, which pays
    # the switch (the data last touched by the other count's steps), is stepped untimed
    for block in range(2 * -(-steps // BLOCK)):
        one = block % 2 == 1
        world._params.threads = 1 if one else default_threads
        count = min(BLOCK, steps - (block // 2) * BLOCK)
        for k in range(1 + count):
            current = integrate(state, world.dynamic, dt)
            start = time.perf_counter()
            result = world.step(state, current, dt)
            elapsed = time.perf_counter() - start
            state = result.states
            if k == 0:
                continue
            if one:
                timed['one_thread'].append(elapsed)
                continue
            timed['total'].append(elapsed)
            timed['detect'].append(world.timing['detect'])
            timed['solve'].append(world.timing['solve'])
            timed['contacts'].append(result.report.contacts.count)
            timed['rows'].append(world.timing['rows'])
            timed['carrying'].append(int(np.count_nonzero(result.report.normal_impulse > 0.0)))
            # rows in the velocity sweeps (the manifolds the active set let in by the step's end)
            timed['swept'].append(int(world._solver.sweep_bodies[:, 2].sum()))
            timed['sweeps'].append(world.timing['iterations'])
    world._params.threads = default_threads
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
            'detect_30hz_ms': ms(slow['detect'], 50), 'solve_30hz_ms': ms(slow['solve'], 50),
            'one_thread_ms': ms(timed['one_thread'], 50),
            'contacts_30hz': int(np.median(slow['contacts'])),
            'rows_30hz': int(np.median(slow['rows'])),
            'carrying': int(np.median(timed['carrying'])),
            'carrying_30hz': int(np.median(slow['carrying'])),
            'swept': int(np.median(timed['swept'])),
            'swept_30hz': int(np.median(slow['swept'])),
            'coal_ms': coal_ms, 'coal_contacts': coal_contacts,
            'largest_speed': float(np.abs(state.linear).max()),
            '_scene': describe(bodies, state)}


PEER_PACKAGES = ('mujoco', 'pybullet', 'rapier3d')


def sleeping(kind: str, size: int, steps: int, awake_ms: float, seed: int = 7) -> dict:
    """The sleeping figures of one pile (module docstring): asleep, kept moving, the drop."""
    from collres_ros.core.types import BodySpec, BodyStates
    bodies, state = make_pile(size, kind=kind)
    top = float(state.position[:, 2].max())
    drop = BodySpec('dropped', 'box', (0.1, 0.1, 0.1), mass=1.0, restitution=0.2,
                    static_friction=0.6, kinetic_friction=0.4)
    bodies = bodies + [drop]
    state = BodyStates(*(np.vstack([a, b]) for a, b in zip(
        (state.position, state.orientation, state.linear, state.angular),
        ([[0.0, 0.0, top + 1.0]], [[0.0, 0.0, 0.0, 1.0]], [[0.0] * 3], [[0.0] * 3]))))
    world = World(bodies, SolverSettings())
    box = len(bodies) - 1
    held = world.dynamic.copy()
    held[box] = False                      # the box's upstream applies no gravity yet
    t, limit = 0.0, 20.0
    while True:
        result = world.step(state, integrate(state, held, DT), DT)
        state, t = result.states, t + DT
        if result.sleeping[world.dynamic].all() or t > limit:
            break
    asleep_after = t
    times = []
    for _ in range(steps):
        current = integrate(state, held, DT)
        start = time.perf_counter()
        result = world.step(state, current, DT)
        times.append(time.perf_counter() - start)
        state = result.states
    asleep_ms = 1000.0 * float(np.median(times))
    counts = world.sleep.counts()
    # the drop: gravity on the box from now on; the same drop from the same poses by an
    # awake world (sleeping off) for comparison
    at_release = state.copy()
    drop = _drop(world, state, box, result.sleeping.copy())
    plain = _drop(World(bodies, AWAKE), at_release, box, np.zeros(len(bodies), bool))
    # kept moving: two worlds, the same kicked inputs, alternating order
    bodies_pile, moving = make_pile(size, kind=kind)
    worlds = {True: World(bodies_pile, SolverSettings()), False: World(bodies_pile, AWAKE)}
    rng = np.random.default_rng(seed)
    dyn = worlds[False].dynamic
    kicked = {True: [], False: []}
    for k in range(int(0.5 / DT) + 2 * steps):
        current = integrate(moving, dyn, DT)
        current.linear[dyn] += rng.normal(0.0, 0.2 / np.sqrt(3), (int(dyn.sum()), 3))
        out = None
        for flag in ((True, False) if k % 2 else (False, True)):
            start = time.perf_counter()
            res = worlds[flag].step(moving, current, DT)
            kicked[flag].append(time.perf_counter() - start)
            if not flag:
                out = res.states
            elif res.sleeping.any():
                raise AssertionError('a kicked body fell asleep')
        moving = out
    skip = int(0.5 / DT)
    on, off = (float(np.median(kicked[f][skip:])) for f in (True, False))
    return {'asleep_after_s': asleep_after, 'asleep_ms': asleep_ms,
            'asleep_ratio': asleep_ms / awake_ms, **counts,
            'moving_on_ms': 1000.0 * on, 'moving_off_ms': 1000.0 * off,
            'moving_overhead': on / off - 1.0,
            'drop': drop, 'drop_awake': plain}


def _drop(world: World, state, box: int, asleep_before: np.ndarray) -> dict:
    """The box (index ``box``, held still so far) released onto the pile: when the pile
    wakes and is touched, the impact, the answers' deepest penetration, the worst step."""
    from collres_ros.core.detection import Detection
    from collres_ros.core.types import ContactState
    probe = Detection(world.specs, AWAKE)   # penetration of the answers (a detector of its own)
    in_pile = world.dynamic.copy()
    in_pile[box] = False
    islands_before = world.sleep.counts()['sleeping_islands']
    log = {'first_wake': None, 'hit': None, 'impact': None, 'v_before': 0.0, 'v_after': 0.0,
           'deepest_m': 0.0, 'worst_ms': 0.0, 'woke_by_hit': 0}
    for k in range(int(1.5 / DT)):
        current = integrate(state, world.dynamic, DT)
        start = time.perf_counter()
        result = world.step(state, current, DT)
        log['worst_ms'] = max(log['worst_ms'], 1000.0 * (time.perf_counter() - start))
        c = result.report.contacts
        touching = ((c.body_a == box) & in_pile[c.body_b]) | \
            ((c.body_b == box) & in_pile[c.body_a])
        sleeping = np.zeros(len(in_pile), bool) if result.sleeping is None else result.sleeping
        woken = asleep_before & ~sleeping & in_pile
        if log['first_wake'] is None and woken.any():
            log['first_wake'] = k
        if log['hit'] is None and touching.any():
            log['hit'] = k
            log['woke_by_hit'] = int(woken.sum())   # woken since the release
        if log['impact'] is None and (touching
                                      & (result.report.state == ContactState.IMPACT)).any():
            log['impact'] = k
            log['v_before'] = float(state.linear[box, 2])
            log['v_after'] = float(result.states.linear[box, 2])
        if log['hit'] is not None:
            seen = probe.detect(result.states, result.states)
            mine = (seen.body_a == box) | (seen.body_b == box)
            if mine.any():
                log['deepest_m'] = max(log['deepest_m'], float(-seen.separation[mine].min()))
        state = result.states
        if log['hit'] is not None and k > log['hit'] + int(0.5 / DT):
            break
    log['woke_total'] = int((asleep_before & ~sleeping & in_pile).sum())
    log['islands_before'] = islands_before
    log['islands_after'] = world.sleep.counts()['sleeping_islands']
    return log


def print_sleeping(row: dict) -> None:
    s = row['sleeping']
    print(f'  sleeping {row["pile"]} {row["bodies"]}: asleep after {s["asleep_after_s"]:.2f} s '
          f'({s["sleeping_islands"]} islands); asleep step {s["asleep_ms"]:.3f} ms = '
          f'{100 * s["asleep_ratio"]:.1f} % of the awake {row["step_ms"][0]:.2f} ms; kept '
          f'moving {s["moving_on_ms"]:.2f} ms on / {s["moving_off_ms"]:.2f} ms off '
          f'({100 * s["moving_overhead"]:+.1f} %)', flush=True)
    d, p = s['drop'], s['drop_awake']
    print(f'  drop onto the sleeping pile: first wake at step {d["first_wake"]}, first '
          f'contact at {d["hit"]} ({d["woke_by_hit"]} bodies woken by then, '
          f'{d["woke_total"]} by the end, of {s["sleeping_bodies"] - 1}; sleeping islands '
          f'{d["islands_before"]} -> {d["islands_after"]}), impact at {d["impact"]}: box '
          f'{d["v_before"]:.3f} -> {d["v_after"]:.3f} m/s, deepest penetration of the '
          f'answers {1000 * d["deepest_m"]:.3f} mm, worst step {d["worst_ms"]:.2f} ms; '
          f'awake: contact at {p["hit"]}, impact at {p["impact"]}: {p["v_before"]:.3f} -> '
          f'{p["v_after"]:.3f} m/s, deepest {1000 * p["deepest_m"]:.3f} mm', flush=True)


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
        f'{row["step_30hz_ms"] / row["step_ms"][0]:.2f}',
        f'{row["one_thread_ms"] / row["step_ms"][0]:.2f}', *[cell(v) for v in peer],
        *[ratio(v) for v in peer]), flush=True)
    # where the 30 Hz step's extra cost goes: detection (pairs that moved too far to keep
    # their stored points go to coal again) or the solve (more points become rows)
    print(f'{"":>13} at 30 Hz: step {row["step_30hz_ms"]:.2f} = detect '
          f'{row["detect_30hz_ms"]:.2f} ({row["detect_30hz_ms"] / row["detect_ms"][0]:.2f}x) '
          f'+ solve {row["solve_30hz_ms"]:.2f} ({row["solve_30hz_ms"] / row["solve_ms"][0]:.2f}x)'
          f', points/rows {row["contacts_30hz"]}/{row["rows_30hz"]} (rows '
          f'{row["rows_30hz"] / max(row["rows"], 1):.2f}x); rows carrying impulse '
          f'{row["carrying_30hz"]} against {row["carrying"]} at 120 Hz; rows swept '
          f'{row["swept_30hz"]} against {row["swept"]}', flush=True)


FORMAT = ('{:>6} {:>6} {:>13} {:>7} {:>7} {:>11} {:>14} {:>8} {:>7} {:>7} {:>7} {:>15} '
          '{:>15} {:>15} {:>15} {:>6} {:>6} {:>6} {:>6}')


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
    parser.add_argument('--no-sleeping', action='store_true', help='skip the sleeping figures')
    parser.add_argument('--out', type=Path, default=ROOT / 'bench_out' / 'step.json')
    args = parser.parse_args(argv)
    python = None if args.no_peers else peer_python(args.peer_venv)
    print(FORMAT.format('pile', 'bodies', 'step p50/p90', 'detect', 'solve', 'points/rows',
                        'coal (pts)', 'det/coal', 'ns/row', '30/120', '1thr/2', 'mujoco CG',
                        'mujoco Newton', 'pybullet', 'rapier', 'us/cg', 'us/nt', 'us/pb',
                        'us/rp'))
    rows = []
    for kind in args.piles:
        for size in args.sizes:
            row = ours(kind, size, args.steps, args.settle)
            row['peers'] = peers(python, row, args.steps) if python else \
                {name: None for name in PEER_ENGINES}
            print_row(row)
            if not args.no_sleeping:
                row['sleeping'] = sleeping(kind, size, args.steps, row['step_ms'][0])
                print_sleeping(row)
            del row['_scene']
            rows.append(row)
    print('ms per step at 120 Hz (contact points per step in brackets); points/rows: our '
          'contact points and solver rows; coal: its own broad + narrow phase alone on '
          'the same poses; ns/row: solve time per solver row per velocity sweep; 30/120: '
          'our step at 30 Hz / at 120 Hz on the same pile settled at each rate; 1thr/2: '
          'our step on one thread / on the default threads (SOLVER_TUNING threads: 2), '
          f'in alternating blocks of {BLOCK} steps of the same run; us/x: our step '
          '(default threads) / theirs (one thread; same run)')
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps({'dt': DT, 'rows': rows}, indent=1))
    print(f'written {args.out}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
