"""Per-step time of World.step on a settled pile of boxes and spheres in a bin.

    .venv/bin/python bench/bench_step.py [--sizes 10 100 1000] [--steps 20]
        [--peers /tmp/peervenv/bin/python]

For each size: build the pile (bench/pile.py), let it settle with the core
and a semi-implicit Euler integrator at 120 Hz, then time ``--steps`` more
steps. Prints a table of the median and 90th percentile of the whole step,
its detection and solve phases, coal's own collide-all on the same poses
(DynamicAABBTree + narrow phase in C++, one contact per pair: the floor the
Python around it is measured against), the ratio (step - coal) / coal, and,
when a peer interpreter with mujoco / pybullet is given, their full step on
the same pile and our step over theirs (same run, same machine).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

import coal
import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from collres_ros.core.config import SolverSettings  # noqa: E402
from collres_ros.core.rotation import to_matrix  # noqa: E402
from collres_ros.core.shapes import make_geometry  # noqa: E402
from collres_ros.core.world import World  # noqa: E402
from pile import bin_half_width, describe, integrate, make_pile  # noqa: E402

DT = 1.0 / 120.0


def coal_collide_ms(bodies, state, repeats: int = 20) -> float:
    """Median ms of coal's own broad + narrow phase (collide-all) on these poses."""
    manager = coal.DynamicAABBTreeCollisionManager()
    objects = []
    rot = to_matrix(state.orientation)
    for spec, r, p in zip(bodies, rot, state.position):
        obj = coal.CollisionObject(make_geometry(spec), coal.Transform3s(r, p))
        obj.computeAABB()
        manager.registerObject(obj)
        objects.append(obj)
    manager.setup()
    callback = coal.CollisionCallBackDefault()
    callback.data.request.num_max_contacts = 10 ** 8
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        for obj, r, p in zip(objects, rot, state.position):
            obj.setTransform(coal.Transform3s(r, p))
            obj.computeAABB()
        manager.update()
        manager.collide(callback)
        times.append(time.perf_counter() - start)
    return 1000.0 * float(np.median(times))


def run(size: int, steps: int, settle_s: float) -> dict:
    bodies, state = make_pile(size)
    world = World(bodies, SolverSettings())
    for _ in range(int(settle_s / DT)):
        state = world.step(state, integrate(state, world.dynamic, DT), DT).states
    total, detect, solve, contacts = [], [], [], []
    for _ in range(steps):
        current = integrate(state, world.dynamic, DT)
        start = time.perf_counter()
        result = world.step(state, current, DT)
        total.append(time.perf_counter() - start)
        detect.append(world.timing['detect'])
        solve.append(world.timing['solve'])
        contacts.append(result.report.contacts.count)
        state = result.states
    ms = (lambda v, q: 1000.0 * float(np.percentile(v, q)))
    return {'size': size, 'contacts': int(np.median(contacts)),
            'step': (ms(total, 50), ms(total, 90)), 'detect': (ms(detect, 50), ms(detect, 90)),
            'solve': (ms(solve, 50), ms(solve, 90)), 'coal': coal_collide_ms(bodies, state),
            'speed': float(np.abs(state.linear).max()), 'bodies': bodies, 'state': state}


def peers(python: str, row: dict, steps: int) -> dict:
    scene = describe(row['bodies'], row['state'])
    scene.update(half_width=bin_half_width(row['size']), dt=DT, warmup=30, steps=steps)
    with tempfile.NamedTemporaryFile('w', suffix='.json', delete=False) as handle:
        json.dump(scene, handle)
    try:
        here = os.path.join(os.path.dirname(os.path.abspath(__file__)), 'peers.py')
        out = subprocess.run([python, here, handle.name], capture_output=True, text=True,
                             timeout=1800, check=True)
        return json.loads(out.stdout.strip().splitlines()[-1])
    except (OSError, subprocess.SubprocessError, ValueError) as error:
        print(f'peers: {error}', file=sys.stderr)
        return {'mujoco': None, 'pybullet': None}
    finally:
        os.unlink(handle.name)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--sizes', type=int, nargs='+', default=[10, 100, 1000])
    parser.add_argument('--steps', type=int, default=20)
    parser.add_argument('--settle', type=float, default=1.0, help='settling time, s')
    parser.add_argument('--peers', default='', help='python with mujoco/pybullet')
    args = parser.parse_args(argv)
    fmt = '{:>6} {:>8} {:>15} {:>15} {:>15} {:>9} {:>10} {:>10} {:>10} {:>8} {:>8}'
    print(fmt.format('bodies', 'contacts', 'step p50/p90', 'detect p50/p90', 'solve p50/p90',
                     'coal', '(step-c)/c', 'mujoco', 'pybullet', 'us/mj', 'us/pb'))
    for size in args.sizes:
        row = run(size, args.steps, args.settle)
        other = peers(args.peers, row, args.steps) if args.peers else \
            {'mujoco': None, 'pybullet': None}
        pair = (lambda v: f'{v[0]:.2f}/{v[1]:.2f}')
        peer = (lambda v: f'{v:.2f}' if v else 'n/a')
        ratio = (lambda v: f'{row["step"][0] / v:.2f}' if v else 'n/a')
        print(fmt.format(size, row['contacts'], pair(row['step']), pair(row['detect']),
                         pair(row['solve']), f'{row["coal"]:.2f}',
                         f'{(row["step"][0] - row["coal"]) / row["coal"]:.1f}',
                         peer(other['mujoco']), peer(other['pybullet']),
                         ratio(other['mujoco']), ratio(other['pybullet'])), flush=True)
    print('times in ms per step at 120 Hz; coal = collide-all on the same poses; '
          'us/mj, us/pb = our step / theirs (same run)')
    return 0


if __name__ == '__main__':
    sys.exit(main())
