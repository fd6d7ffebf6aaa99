"""Does a pile come to rest? A pile of ``bench/pile.py`` dropped at one rate, its settling.

Usage::

    .venv/bin/python bench/bench_rest.py [--kind mixed|cubes] [--size 1000] [--rate 30]
        [--seconds 12] [--every 1] [--substep S] [--seed 1]

The simulator's loop (semi-implicit Euler under gravity, each answer integrated for one
period), sleeping on. Every ``--every`` s it prints: the bodies whose farthest point moves
faster than 0.05 m/s (Box2D's sleep speed) and the fastest, the deepest penetration of the
answer (any pair, and into the floor: a detector of its own on the answered poses), the
fastest approach left at a touching contact (the answered twists), solver rows and velocity
sweeps per step and the step's median time, and the sleeping bodies; at the end the time
the pile fell asleep. ``--substep``: ``solver.max_substep`` (s; default: the setting's).
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from collres_ros.core.config import SolverSettings
from collres_ros.core.detection import Detection
from collres_ros.core.world import World

from pile import PILES, integrate, make_pile  # noqa: I100


def figures(probe: Detection, state, dynamic: np.ndarray, radius: np.ndarray) -> dict:
    """Speeds (m/s, farthest point), deepest penetration (m), the fastest approach left at
    a contact within 1 mm (m/s)."""
    speed = np.linalg.norm(state.linear, axis=1) + np.linalg.norm(state.angular, axis=1) * radius
    speed = np.where(dynamic, speed, 0.0)
    seen = probe.detect(state, state)
    if seen.count == 0:
        return {'speed': speed, 'deepest': 0.0, 'floor': 0.0, 'approach': 0.0}
    a, b, point = seen.body_a, seen.body_b, seen.point
    va = state.linear[a] + np.cross(state.angular[a], point - state.position[a])
    vb = state.linear[b] + np.cross(state.angular[b], point - state.position[b])
    normal_speed = np.einsum('ij,ij->i', vb - va, seen.normal)
    touching = seen.separation < 1e-3
    on_floor = (a == 0) | (b == 0)
    return {'speed': speed, 'deepest': float(max(0.0, -seen.separation.min())),
            'floor': float(max(0.0, -seen.separation[on_floor].min())) if on_floor.any()
            else 0.0,
            'approach': float(max(0.0, -normal_speed[touching].min())) if touching.any()
            else 0.0}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--kind', choices=PILES, default='mixed')
    parser.add_argument('--size', type=int, default=1000)
    parser.add_argument('--rate', type=float, default=30.0, help='Hz')
    parser.add_argument('--seconds', type=float, default=12.0)
    parser.add_argument('--every', type=float, default=1.0, help='s between reports')
    parser.add_argument('--substep', type=float, default=SolverSettings().max_substep,
                        help='solver.max_substep, s')
    parser.add_argument('--seed', type=int, default=1)
    args = parser.parse_args(argv)
    dt = 1.0 / args.rate
    bodies, state = make_pile(args.size, seed=args.seed, kind=args.kind)
    world = World(bodies, SolverSettings(max_substep=args.substep))
    probe = Detection(world.specs, SolverSettings(sleeping=False))
    dynamic = world.dynamic
    radius = np.array([0.5 * np.linalg.norm(b.size) if b.shape == 'box' else b.size[0]
                       if b.shape == 'sphere' else 0.0 for b in bodies])
    steps = int(round(args.seconds * args.rate))
    every = max(1, int(round(args.every * args.rate)))
    asleep_at, times, rows, sweeps = None, [], [], []
    for k in range(steps):
        current = integrate(state, dynamic, dt)
        start = time.perf_counter()
        result = world.step(state, current, dt)
        times.append(time.perf_counter() - start)
        rows.append(world.timing['rows'])
        sweeps.append(world.timing['iterations'])
        state = result.states
        if asleep_at is None and result.sleeping[dynamic].all():
            asleep_at = (k + 1) * dt
        if (k + 1) % every == 0:
            f = figures(probe, state, dynamic, radius)
            print(f't {(k + 1) * dt:5.2f} s: {int((f["speed"] > 0.05).sum()):4d} faster than '
                  f'0.05 m/s (fastest {f["speed"].max():.3f}), deepest {f["deepest"] * 1e3:6.2f} '
                  f'mm, into the floor {f["floor"] * 1e3:5.2f} mm, approach left '
                  f'{f["approach"]:.3f} m/s, rows {np.mean(rows[-every:]):6.0f}, sweeps '
                  f'{np.mean(sweeps[-every:]):5.1f}, step {np.median(times[-every:]) * 1e3:6.1f} '
                  f'ms, asleep {int(result.sleeping[dynamic].sum())}', flush=True)
    print(f'{args.kind} {args.size} at {args.rate:g} Hz, max_substep {args.substep:g} s: '
          f'asleep after {asleep_at if asleep_at is None else round(asleep_at, 2)} s')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
