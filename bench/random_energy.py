"""A long random run of the no-energy-gain law (not in ``make test``: minutes, not seconds).

    .venv/bin/python bench/random_energy.py [--cases 100000] [--seed 0] [--clusters 0.2]

Each case is one ``World.step`` on hand-made contacts with the current state equal to
the previous one (every change comes from the contact impulses), e <= 1, any combine
rule but per_object (the textbook model that breaks momentum):

* a pair (spheres or boxes, the second possibly static) with 1-4 points on one normal,
  some coincident or collinear (degenerate patches), impact or persistent, as the
  fixed-seed property test in test/core/test_physics_properties.py draws them;
* with probability ``--clusters``, a cluster of 2-6 dynamic bodies without gravity,
  each touching pair with 1-4 points of its own normal.

A case fails when the kinetic energy after the step exceeds the one before by more than
1e-9 relative, or any output is not finite. Prints the count, the worst gain and the
first failing cases (seed and index: rerun one with ``--seed S --first I --cases 1``),
each of which is to become a plain regression test. Exit code 1 on any failure.
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), '..'))

from collres_ros.core.config import SolverSettings  # noqa: E402
from collres_ros.core.rotation import normalize, to_matrix  # noqa: E402
from collres_ros.core.types import (BodySpec, BodyStates, ContactKind, ContactSet,  # noqa: E402
                                    pair_manifolds)
from collres_ros.core.world import World  # noqa: E402

RULES = ('average', 'min', 'max', 'multiply')
FRICTION_RULES = ('geometric', 'average', 'min', 'max', 'multiply')


class Fixed:
    """A detector that returns the given contacts."""

    def __init__(self, contacts: ContactSet, settings: SolverSettings) -> None:
        self.contacts, self.settings, self.collision_filter = contacts, settings, None
        self.budget = (0, 0)      # nothing dropped by a step budget

    def detect(self, previous, current, active=None, threads=1) -> ContactSet:
        return self.contacts


def body(rng: np.random.Generator, name: str, static: bool = False) -> BodySpec:
    shape = 'sphere' if rng.random() < 0.5 else 'box'
    size = (rng.uniform(0.05, 1.0),) if shape == 'sphere' else tuple(rng.uniform(0.05, 1.0, 3))
    return BodySpec(name, shape, size, static=static, mass=float(rng.uniform(0.01, 100.0)),
                    restitution=float(rng.uniform(0.0, 1.0)),
                    static_friction=float(rng.uniform(0.0, 1.5)),
                    kinetic_friction=float(rng.uniform(0.0, 1.5)))


def patch(rng: np.random.Generator, centre: np.ndarray) -> np.ndarray:
    """1-4 points near ``centre``: random, or coincident, or on a line."""
    k = int(rng.integers(1, 5))
    points = centre + rng.uniform(-0.25, 0.25, (k, 3))
    kind = rng.random()
    if k > 1 and kind < 0.2:
        points[1:] = points[0] + rng.normal(0.0, 1e-7, (k - 1, 3)) * (rng.random() < 0.5)
    elif k > 2 and kind < 0.4:
        direction = rng.normal(size=3)
        points = centre + np.outer(rng.uniform(-0.25, 0.25, k), direction)
    return points


def case(rng: np.random.Generator, clusters: float):
    """(bodies, states, contacts, settings) of one random case."""
    n = int(rng.integers(2, 7)) if rng.random() < clusters else 2
    static_last = n == 2 and rng.random() < 0.5
    bodies = [body(rng, f'b{i}', static=static_last and i == 1) for i in range(n)]
    s = BodyStates.zeros(n)
    s.position[:] = rng.uniform(-1.0, 1.0, (n, 3)) * (0.2 if n == 2 else 0.6)
    s.orientation[:] = normalize(np.c_[rng.uniform(-5, 5, (n, 3)), rng.uniform(0.1, 1.0, n)])
    s.linear[:] = rng.uniform(-5.0, 5.0, (n, 3))
    s.angular[:] = rng.uniform(-5.0, 5.0, (n, 3))
    if static_last:
        s.linear[1] = s.angular[1] = 0.0
    pairs = [(i, j) for i in range(n) for j in range(i + 1, n)]
    if n > 2:   # a random connected set of touching pairs
        keep = int(rng.integers(n - 1, len(pairs) + 1))
        pairs = sorted(pairs[k] for k in rng.permutation(len(pairs))[:keep])
    a, b, point, normal, separation, kind = [], [], [], [], [], []
    for i, j in pairs:
        pts = patch(rng, 0.5 * (s.position[i] + s.position[j]))
        nrm = rng.normal(size=3)
        nrm /= max(np.linalg.norm(nrm), 1e-9)
        impact = ContactKind.IMPACT if rng.random() < 0.5 else ContactKind.PERSISTENT
        for p in pts:
            a.append(i)
            b.append(j)
            point.append(p)
            normal.append(nrm)
            separation.append(rng.uniform(-0.002, 0.002))
            kind.append(int(impact))
    m = len(a)
    contacts = ContactSet(np.array(a, np.int64), np.array(b, np.int64), np.array(point),
                          np.array(normal), np.array(separation), np.zeros(m),
                          np.array(kind, np.int8), np.arange(m, dtype=np.int64),
                          pair_manifolds(np.array(a, np.int64), np.array(b, np.int64)))
    settings = SolverSettings(restitution_rule=RULES[int(rng.integers(len(RULES)))],
                              friction_rule=FRICTION_RULES[int(rng.integers(5))],
                              restitution_threshold=float(rng.choice([0.0, 0.5])))
    return bodies, s, contacts, settings


def kinetic(world: World, s: BodyStates) -> float:
    energy = 0.0
    for i in np.flatnonzero(world.dynamic):
        rot = to_matrix(s.orientation[i])
        inertia = rot @ np.linalg.inv(world.inv_inertia_body[i]) @ rot.T
        energy += 0.5 / world.inv_mass[i] * s.linear[i] @ s.linear[i] \
            + 0.5 * s.angular[i] @ inertia @ s.angular[i]
    return float(energy)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--cases', type=int, default=100_000)
    parser.add_argument('--seed', type=int, default=0)
    parser.add_argument('--first', type=int, default=0, help='index of the first case')
    parser.add_argument('--clusters', type=float, default=0.2)
    args = parser.parse_args()
    started = time.perf_counter()
    failures, worst = [], -np.inf
    for index in range(args.first, args.first + args.cases):
        rng = np.random.default_rng([args.seed, index])
        bodies, s, contacts, settings = case(rng, args.clusters)
        world = World(bodies, settings, Fixed(contacts, settings))
        result = world.step(s, s.copy(), 0.01)
        out = result.states.copy()
        out.position, out.orientation = s.position, s.orientation
        outputs = (result.states.linear, result.states.angular, result.report.normal_impulse)
        finite = all(np.isfinite(x).all() for x in outputs)
        k0, k1 = kinetic(world, s), kinetic(world, out)
        gain = (k1 - k0) / max(k0, 1e-300)
        worst = max(worst, gain)
        if not finite or k1 > k0 * (1 + 1e-9) + 1e-12:
            failures.append((index, len(bodies), contacts.count, gain, finite))
    took = time.perf_counter() - started
    print(f'{args.cases} cases (seed {args.seed}) in {took:.1f} s: {len(failures)} failed; '
          f'largest relative energy change {worst:+.3g}')
    for index, n, m, gain, finite in failures[:20]:
        print(f'  case {index}: {n} bodies, {m} points, energy {gain:+.3g}, finite {finite}')
    return 1 if failures else 0


if __name__ == '__main__':
    sys.exit(main())
