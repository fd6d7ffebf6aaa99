"""Detection time per step on a settled pile, against coal's own C++ collide-all.

    .venv/bin/python bench/bench_detection.py [--sizes 100 1000] [--steps 30]
        [--save poses.npz]

For each size: build the pile (bench/pile.py), let it settle with the core at 120 Hz,
then, on the same poses:

* ``detect``: ``Detection.detect`` (the compiled broad phase, narrow phase, patches,
  time of impact) stepping along the settled motion, its stored manifolds warm, with the
  step's dt (the margin of a pair at rest as ``World.step`` gives it);
* ``cold``: the same on a new detector every time (no stored manifold);
* ``coal``: coal's DynamicAABBTree ``update`` + ``collide`` with the default callback
  (C++ broad and narrow phase, one contact per pair, half-spaces in the tree), the poses
  already pushed; ``coal+push`` adds pushing the poses from Python; ``no planes``: the
  same without the half-spaces (each replaced by a 1 mm sphere at the origin, far below
  the floor's bodies): no body-plane pair at all, less work than ours, a lower bound.

Medians in ms, and the ratios detect / coal (same run, same machine). ``--save`` writes
the settled poses, for timing another detector on exactly the same input.
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import coal
import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from collres_ros.core.config import SolverSettings  # noqa: E402
from collres_ros.core.detection import Detection  # noqa: E402
from collres_ros.core.rotation import to_matrix  # noqa: E402
from collres_ros.core.shapes import make_geometry, shape_offset  # noqa: E402
from collres_ros.core.world import World  # noqa: E402
from pile import integrate, make_pile  # noqa: E402

DT = 1.0 / 120.0


def settle(size: int, settle_s: float, steps: int):
    """The pile after settling, and ``steps`` more (previous, current) pairs of states."""
    bodies, state = make_pile(size)
    world = World(bodies, SolverSettings())
    for _ in range(int(settle_s / DT)):
        state = world.step(state, integrate(state, world.dynamic, DT), DT).states
    frames = []
    for _ in range(steps):
        current = integrate(state, world.dynamic, DT)
        frames.append((state, current))
        state = world.step(state, current, DT).states
    return bodies, frames


def coal_ms(bodies, frames, planes: bool = True) -> tuple[float, float, int]:
    """Median ms of coal's collide-all without and with the pose push, and contacts;
    without ``planes`` the half-spaces are left out (no body-plane pair at all)."""
    manager = coal.DynamicAABBTreeCollisionManager()
    objects = []
    for spec in bodies:
        geometry = make_geometry(spec) if planes or spec.shape != 'plane' else coal.Sphere(1e-3)
        obj = coal.CollisionObject(geometry, coal.Transform3s())
        manager.registerObject(obj)
        objects.append(obj)
    manager.setup()
    offsets = np.array([shape_offset(spec) for spec in bodies])
    callback = coal.CollisionCallBackDefault()
    callback.data.request.num_max_contacts = 10 ** 8
    bare, pushed, contacts = [], [], []
    for _, current in frames:
        rotation = to_matrix(current.orientation)
        origin = current.position + np.einsum('nij,nj->ni', rotation, offsets)
        start = time.perf_counter()
        for obj, r, p in zip(objects, rotation, origin):
            obj.setTransform(coal.Transform3s(r, p))
            obj.computeAABB()
        middle = time.perf_counter()
        manager.update()
        manager.collide(callback)
        end = time.perf_counter()
        bare.append(end - middle)
        pushed.append(end - start)
        contacts.append(callback.data.result.numContacts())
    return (1000.0 * float(np.median(bare)), 1000.0 * float(np.median(pushed)),
            int(np.median(contacts)))


def detect_ms(bodies, frames, cold: bool) -> tuple[float, int]:
    """Median ms of Detection.detect over the frames (a new detector each time if cold)."""
    detector = Detection(bodies, SolverSettings())
    times, rows = [], []
    for previous, current in frames:
        if cold:
            detector = Detection(bodies, SolverSettings())
        start = time.perf_counter()
        contacts = detector.detect(previous, current, dt=DT)
        times.append(time.perf_counter() - start)
        rows.append(contacts.count)
    return 1000.0 * float(np.median(times[1:])), int(np.median(rows))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--sizes', type=int, nargs='+', default=[100, 1000])
    parser.add_argument('--steps', type=int, default=30)
    parser.add_argument('--settle', type=float, default=1.0, help='settling time, s')
    parser.add_argument('--save', default='', help='write the settled poses (npz)')
    args = parser.parse_args(argv)
    fmt = '{:>6} {:>8} {:>9} {:>9} {:>9} {:>10} {:>10} {:>12} {:>10} {:>14}'
    print(fmt.format('bodies', 'points', 'detect', 'cold', 'coal', 'coal+push', 'no planes',
                     'detect/coal', 'cold/coal', 'detect/no pl.'))
    saved = {}
    for size in args.sizes:
        bodies, frames = settle(size, args.settle, args.steps)
        warm, points = detect_ms(bodies, frames, cold=False)
        cold, _ = detect_ms(bodies, frames, cold=True)
        bare, pushed, _ = coal_ms(bodies, frames)
        finite, _, _ = coal_ms(bodies, frames, planes=False)
        print(fmt.format(size, points, f'{warm:.3f}', f'{cold:.3f}', f'{bare:.3f}',
                         f'{pushed:.3f}', f'{finite:.3f}', f'{warm / bare:.2f}',
                         f'{cold / bare:.2f}', f'{warm / finite:.2f}'), flush=True)
        for k, (previous, current) in enumerate(frames):
            for name, state in (('previous', previous), ('current', current)):
                saved[f'{size}_{k}_{name}_position'] = state.position
                saved[f'{size}_{k}_{name}_orientation'] = state.orientation
                saved[f'{size}_{k}_{name}_linear'] = state.linear
                saved[f'{size}_{k}_{name}_angular'] = state.angular
    print('ms per step at 120 Hz, medians; coal = DynamicAABBTree update + collide-all '
          '(C++), poses pushed beforehand; coal+push includes pushing them from Python')
    if args.save:
        np.savez(args.save, **saved)
    return 0


if __name__ == '__main__':
    sys.exit(main())
