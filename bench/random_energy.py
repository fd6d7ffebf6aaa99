"""A long random run of the no-energy-gain law (not in ``make test``: minutes, not seconds).

    .venv/bin/python bench/random_energy.py [--cases 100000] [--clusters 5000] [--seed 0]
        [--first I] [--only manifolds|clusters] [--iterations] [--steps 3]

Two kinds of cases, each with e <= 1 and any combine rule but per_object (the textbook
model that breaks momentum), drawn as a hostile user would: step 1/30 to 1/1000 s, e 0,
0.5, 0.79 or 1 per body, static and kinetic friction 0-1.5, rolling resistance and
torsional friction 0-1 (mostly > 0), mass ratios up to 1000:1, cubes, long thin and flat
boxes, speeds 1e-4 to 20 m/s, restitution thresholds 0, 0.05 and 0.5 m/s:

* ``--cases`` hand-made manifolds through ``World.step``: a pair (the second possibly
  static) or, with probability 0.2, a cluster of 2-6 dynamic bodies, each touching pair
  with 1-4 points on one normal, at random, coincident or nearly (1e-12 to 1e-5 of the
  patch), collinear or nearly, the patch 0.1 mm to 0.5 m wide, impact or persistent,
  touching, overlapping or speculative (gaps up to 2 mm: the landing); gravity on in 40 %
  of them; in 30 % the same step is stepped twice (the second warm started from the
  first). The current state equals the previous one but for gravity's change.
* ``--clusters`` clusters of 2-6 spheres, capsules, cylinders and boxes overlapping a bit,
  with coal's contacts (``World.step`` with its own detection), stepped ``--steps`` steps
  (each from the last answer moved on by its twist): without gravity, or (half of them) on
  a fixed floor under gravity.

The law: without gravity no step ends with more kinetic energy than it began with (judged
at the solve's poses); with gravity, whose change dv of the twists is work done from
outside, sqrt(K_out) <= sqrt(K_in) + sqrt(K_dv) (K_dv the kinetic energy of dv: the
triangle inequality of the energy norm, since contact impulses never raise it). A case
fails when it is broken by more than 1e-9 relative + 1e-12 J, or any output is not finite.
With ``--iterations`` every case is also solved with velocity_iterations 1, 10, 100 and
1000 (each judged), and the run prints how far the answers are from the 1000-sweep one.

Prints the counts, the worst case (its relative change, kind, seed and index: rerun it
with ``--seed S --first I --cases 1 --only KIND``) and the first failing cases, each of
which is to become a plain regression test (test/core/test_energy_regressions.py). Exit
code 1 on any failure.
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), '..'))

from collres_ros.core.config import SolverSettings  # noqa: E402
from collres_ros.core.rotation import integrate, normalize, to_matrix  # noqa: E402
from collres_ros.core.types import (BodySpec, BodyStates, ContactKind, ContactSet,  # noqa: E402
                                    pair_manifolds)
from collres_ros.core.world import World  # noqa: E402

RULES = ('average', 'min', 'max', 'multiply')
FRICTION_RULES = ('geometric', 'average', 'min', 'max', 'multiply')
RESTITUTIONS = (0.0, 0.5, 0.79, 1.0)
STEPS = (1 / 30, 1 / 60, 1 / 120, 1 / 240, 1 / 1000)
THRESHOLDS = (0.0, 0.05, 0.5)
GRAVITY = np.array([0.0, 0.0, -9.81])
ITERATIONS = (1, 10, 100, 1000)


class Fixed:
    """A detector that returns the given contacts."""

    def __init__(self, contacts: ContactSet, settings: SolverSettings) -> None:
        self.contacts, self.settings, self.collision_filter = contacts, settings, None
        self.budget = (0, 0)      # nothing dropped by a step budget
        self.thread_runs = (0, 0, 0, 0)   # one thread: no runs posted for two

    def detect(self, previous, current, active=None, threads=1, dt=0.0) -> ContactSet:
        return self.contacts


def log_uniform(rng: np.random.Generator, low: float, high: float) -> float:
    return float(10 ** rng.uniform(np.log10(low), np.log10(high)))


def box_size(rng: np.random.Generator, base: float) -> tuple[float, ...]:
    """A cube-ish, long thin or flat box of longest edge about ``base`` (m)."""
    form = rng.random()
    if form < 0.3:      # long thin: two edges 1-10 % of the third
        size = base * np.array([1.0, log_uniform(rng, 0.01, 0.1), log_uniform(rng, 0.01, 0.1)])
    elif form < 0.6:    # flat: one edge 1-10 % of the others
        size = base * np.array([1.0, log_uniform(rng, 0.5, 1.0), log_uniform(rng, 0.01, 0.1)])
    else:
        size = base * rng.uniform(0.2, 1.0, 3)
    return tuple(float(s) for s in rng.permutation(size))


def material(rng: np.random.Generator) -> dict:
    return dict(restitution=float(rng.choice(RESTITUTIONS)),
                static_friction=float(rng.uniform(0.0, 1.5)),
                kinetic_friction=float(rng.uniform(0.0, 1.5)),
                rolling_resistance=float(rng.uniform(0.0, 1.0)) * (rng.random() < 0.8),
                torsional_friction=float(rng.uniform(0.0, 1.0)) * (rng.random() < 0.8))


def settings_of(rng: np.random.Generator) -> SolverSettings:
    return SolverSettings(restitution_rule=RULES[int(rng.integers(len(RULES)))],
                          friction_rule=FRICTION_RULES[int(rng.integers(len(FRICTION_RULES)))],
                          restitution_threshold=float(rng.choice(THRESHOLDS)))


def step_of(rng: np.random.Generator) -> float:
    return float(rng.choice(STEPS)) if rng.random() < 0.7 else log_uniform(rng, 1e-3, 1 / 30)


def masses(rng: np.random.Generator, n: int) -> list[float]:
    """The first 0.01-100 kg, the others within 1000:1 of it either way."""
    first = log_uniform(rng, 0.01, 100.0)
    return [first] + [first * log_uniform(rng, 1e-3, 1e3) for _ in range(n - 1)]


def twists(rng: np.random.Generator, s: BodyStates, reach: np.ndarray) -> None:
    """Random twists of one speed scale, 1e-4 to 20 m/s (points at ``reach`` m)."""
    n = len(reach)
    speed = log_uniform(rng, 1e-4, 20.0)
    s.linear[:] = rng.uniform(-1.0, 1.0, (n, 3)) * speed
    s.angular[:] = rng.uniform(-1.0, 1.0, (n, 3)) * (speed / reach[:, None]) \
        * log_uniform(rng, 0.1, 10.0)


def patch(rng: np.random.Generator, centre: np.ndarray, scale: float) -> np.ndarray:
    """1-4 points near ``centre`` within ``scale`` (m): random, or some coincident or nearly,
    or on a line or nearly."""
    k = int(rng.integers(1, 5))
    points = centre + rng.uniform(-1.0, 1.0, (k, 3)) * scale
    kind = rng.random()
    if k > 1 and kind < 0.25:
        near = float(rng.choice([0.0, 1e-12, 1e-9, 1e-7, 1e-5])) * scale
        points[1:] = points[0] + rng.normal(0.0, 1.0, (k - 1, 3)) * near
        some = int(rng.integers(1, k))
        if k > 2 and rng.random() < 0.5:   # only the first `some` + 1 together
            points[some + 1:] = centre + rng.uniform(-1.0, 1.0, (k - some - 1, 3)) * scale
    elif k > 2 and kind < 0.5:
        near = float(rng.choice([0.0, 1e-9, 1e-6, 1e-3])) * scale
        points = centre + np.outer(rng.uniform(-1.0, 1.0, k), rng.normal(size=3)) * scale \
            + rng.normal(size=(k, 3)) * near
    return points


def manifold_case(rng: np.random.Generator):
    """(bodies, states, contacts, settings, dt, gravity, twice) of one hand-made case."""
    n = int(rng.integers(2, 7)) if rng.random() < 0.2 else 2
    static_last = n == 2 and rng.random() < 0.5
    bodies = []
    for i, mass in enumerate(masses(rng, n)):
        base = log_uniform(rng, 0.01, 1.0)
        shape, size = ('sphere', (0.5 * base,)) if rng.random() < 0.35 else \
            ('box', box_size(rng, base))
        bodies.append(BodySpec(f'b{i}', shape, size, static=static_last and i == 1, mass=mass,
                               **material(rng)))
    s = BodyStates.zeros(n)
    s.position[:] = rng.uniform(-1.0, 1.0, (n, 3)) * (0.2 if n == 2 else 0.6)
    s.orientation[:] = normalize(np.c_[rng.uniform(-5, 5, (n, 3)), rng.uniform(0.1, 1.0, n)])
    twists(rng, s, np.ones(n))
    if static_last:
        s.linear[1] = s.angular[1] = 0.0
    pairs = [(i, j) for i in range(n) for j in range(i + 1, n)]
    if n > 2:   # a random connected set of touching pairs
        keep = int(rng.integers(n - 1, len(pairs) + 1))
        pairs = sorted(pairs[k] for k in rng.permutation(len(pairs))[:keep])
    a, b, point, normal, separation, kind = [], [], [], [], [], []
    for i, j in pairs:
        pts = patch(rng, 0.5 * (s.position[i] + s.position[j]), log_uniform(rng, 1e-4, 0.5))
        nrm = rng.normal(size=3)
        nrm /= max(np.linalg.norm(nrm), 1e-9)
        impact = ContactKind.IMPACT if rng.random() < 0.5 else ContactKind.PERSISTENT
        gap = float(rng.choice([0.0, 1e-4, 2e-3]))    # touching, or up to 0.1 or 2 mm
        for p in pts:
            a.append(i)
            b.append(j)
            point.append(p)
            normal.append(nrm)
            separation.append(rng.uniform(-1.0, 1.0) * gap)
            kind.append(int(impact))
    m = len(a)
    contacts = ContactSet(np.array(a, np.int64), np.array(b, np.int64), np.array(point),
                          np.array(normal), np.array(separation), np.zeros(m),
                          np.array(kind, np.int8), np.arange(m, dtype=np.int64),
                          pair_manifolds(np.array(a, np.int64), np.array(b, np.int64)))
    return (bodies, s, contacts, settings_of(rng), step_of(rng), rng.random() < 0.4,
            rng.random() < 0.3)


def cluster_case(rng: np.random.Generator):
    """(bodies, states, settings, dt, floor) of 2-6 shapes overlapping a bit (and a floor)."""
    n = int(rng.integers(2, 7))
    bodies, reach = [], np.zeros(n)
    for i, mass in enumerate(masses(rng, n)):
        base, form = log_uniform(rng, 0.03, 1.0), rng.random()
        if form < 0.3:
            shape, size = 'sphere', (0.5 * base,)
            reach[i] = 0.5 * base
        elif form < 0.45:
            shape, size = 'capsule', (0.25 * base, base * rng.uniform(0.5, 3.0))
            reach[i] = size[0] + 0.5 * size[1]
        elif form < 0.55:
            shape, size = 'cylinder', (0.5 * base, base * rng.uniform(0.05, 2.0))
            reach[i] = float(np.hypot(size[0], 0.5 * size[1]))
        else:
            shape, size = 'box', box_size(rng, base)
            reach[i] = 0.5 * float(np.linalg.norm(size))
        bodies.append(BodySpec(f'b{i}', shape, tuple(float(x) for x in size), mass=mass,
                               **material(rng)))
    s = BodyStates.zeros(n)
    for i in range(1, n):    # each one overlapping an earlier one's bounding sphere
        k = int(rng.integers(0, i))
        u = rng.normal(size=3)
        s.position[i] = s.position[k] + u / np.linalg.norm(u) * (reach[i] + reach[k]) \
            * rng.uniform(0.3, 0.9)
    s.orientation[:] = normalize(rng.normal(size=(n, 4)))
    twists(rng, s, reach)
    floor = rng.random() < 0.5
    if floor:   # its top through the lowest body, 30-100 % of its reach below its centre
        low = int(np.argmin(s.position[:, 2]))
        top = s.position[low, 2] - reach[low] * rng.uniform(0.3, 1.0)
        bodies.append(BodySpec('floor', 'box', (20.0, 20.0, 1.0), static=True,
                               **material(rng)))
        grown = BodyStates.zeros(n + 1)
        for name in ('position', 'orientation', 'linear', 'angular'):
            getattr(grown, name)[:n] = getattr(s, name)
        grown.position[n] = (s.position[low, 0], s.position[low, 1], top - 0.5)
        grown.orientation[n] = (0.0, 0.0, 0.0, 1.0)
        s = grown
    return bodies, s, settings_of(rng), float(rng.choice(STEPS)), floor


def kinetic(world: World, linear: np.ndarray, angular: np.ndarray,
            orientation: np.ndarray) -> float:
    energy = 0.0
    for i in np.flatnonzero(world.dynamic):
        rot = to_matrix(orientation[i])
        inertia = rot @ np.linalg.inv(world.inv_inertia_body[i]) @ rot.T
        energy += 0.5 / world.inv_mass[i] * linear[i] @ linear[i] \
            + 0.5 * angular[i] @ inertia @ angular[i]
    return float(energy)


def weighted(world: World, states: BodyStates, orientation: np.ndarray) -> np.ndarray:
    """The dynamic bodies' twists in the energy norm (sqrt(m) v, C^T w with C C^T the world
    inertia at ``orientation``): the squared length of the result is twice the energy."""
    parts = []
    for i in np.flatnonzero(world.dynamic):
        rot = to_matrix(orientation[i])
        root = np.linalg.cholesky(rot @ np.linalg.inv(world.inv_inertia_body[i]) @ rot.T)
        parts += [states.linear[i] / np.sqrt(world.inv_mass[i]), root.T @ states.angular[i]]
    return np.concatenate(parts)


def judge(world: World, before: BodyStates, change: np.ndarray, after: BodyStates
          ) -> tuple[bool, float]:
    """(broken, relative change beyond the bound) of one step: ``before`` the step's
    current state, ``change`` the external change of its linear twists (gravity),
    ``after`` its answer; energies at the solve's poses (``before``'s)."""
    finite = np.isfinite(after.linear).all() and np.isfinite(after.angular).all()
    k_in = kinetic(world, before.linear, before.angular, before.orientation)
    k_dv = kinetic(world, change, np.zeros_like(change), before.orientation)
    bound = (np.sqrt(k_in) + np.sqrt(k_dv)) ** 2
    k_out = kinetic(world, after.linear, after.angular, before.orientation) if finite else np.inf
    return (not finite or k_out > bound * (1 + 1e-9) + 1e-12,
            (k_out - bound) / max(bound, 1e-300))


def run_manifolds(case, iterations: int | None = None) -> tuple[bool, float, np.ndarray]:
    """One hand-made case: (broken, relative change, the answer's twists in the energy
    norm)."""
    bodies, s, contacts, settings, dt, gravity, twice = case
    if iterations is not None:
        settings = settings.with_values(velocity_iterations=iterations)
    world = World(bodies, settings, Fixed(contacts, settings))
    current = s.copy()
    change = np.zeros_like(s.linear)
    if gravity:
        change[world.dynamic] = GRAVITY * dt
        current.linear += change
    result = world.step(s, current.copy(), dt)
    if twice:   # the same step again, warm started from the first
        result = world.step(s, current.copy(), dt)
    broken, gain = judge(world, current, change, result.states)
    return broken, gain, weighted(world, result.states, current.orientation)


def run_cluster(case, steps: int, iterations: int | None = None
                ) -> tuple[bool, float, np.ndarray]:
    """One coal cluster over ``steps`` steps: (broken, worst relative change, the last
    answer's twists in the energy norm)."""
    bodies, s, settings, dt, floor = case
    if iterations is not None:
        settings = settings.with_values(velocity_iterations=iterations)
    world = World(bodies, settings)
    change = np.zeros_like(s.linear)
    if floor:
        change[world.dynamic] = GRAVITY * dt
    previous, current = s.copy(), s.copy()   # moving on its twist (and gravity) into s
    previous.linear = s.linear - change
    previous.position = s.position - s.linear * dt
    previous.orientation = integrate(s.orientation, s.angular, -dt)
    worst = -np.inf
    for _ in range(steps):
        answer = world.step(previous, current, dt).states
        broken, gain = judge(world, current, change, answer)
        worst = max(worst, gain)
        twist = weighted(world, answer, current.orientation)
        if broken:
            return True, gain, twist
        previous, current = answer.copy(), answer.copy()
        current.linear = answer.linear + change
        current.position = answer.position + current.linear * dt
        current.orientation = integrate(answer.orientation, answer.angular, dt)
    return False, worst, twist


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--cases', type=int, default=100_000, help='hand-made manifold cases')
    parser.add_argument('--clusters', type=int, default=5_000, help='coal cluster cases')
    parser.add_argument('--steps', type=int, default=3, help='steps of each cluster')
    parser.add_argument('--seed', type=int, default=0)
    parser.add_argument('--first', type=int, default=0, help='index of the first case')
    parser.add_argument('--only', choices=('manifolds', 'clusters'))
    parser.add_argument('--iterations', action='store_true',
                        help='also at velocity_iterations 1, 10, 100, 1000')
    args = parser.parse_args()
    kinds = [('manifolds', args.cases), ('clusters', args.clusters)]
    failures, worst, far = [], (-np.inf, None), []
    for kind, count in kinds:
        if args.only not in (None, kind) or count <= 0:
            continue
        started = time.perf_counter()
        broken = 0
        for index in range(args.first, args.first + count):
            rng = np.random.default_rng([args.seed, index, 0 if kind == 'manifolds' else 1])
            case = manifold_case(rng) if kind == 'manifolds' else cluster_case(rng)
            answers = {}
            for iterations in (ITERATIONS if args.iterations else (None,)):
                if kind == 'manifolds':
                    fail, gain, answer = run_manifolds(case, iterations)
                else:
                    fail, gain, answer = run_cluster(case, args.steps, iterations)
                answers[iterations] = answer
                if gain > worst[0]:
                    worst = (gain, (kind, index, iterations))
                if fail:
                    broken += 1
                    failures.append((kind, index, iterations, gain))
            if args.iterations:   # distance of each answer from the 1000-sweep one
                scale = max(max(np.linalg.norm(a) for a in answers.values()), 1e-300)
                far.append([np.linalg.norm(answers[k] - answers[1000]) / scale
                            for k in ITERATIONS[:-1]] + [kind == 'clusters', index])
        print(f'{count} {kind} (seed {args.seed}) in {time.perf_counter() - started:.1f} s: '
              f'{broken} failed')
    if worst[1] is None:
        return 0
    gain, (kind, index, iterations) = worst
    print(f'worst: {kind} case {index}' + (f' at {iterations} iterations' if iterations else '')
          + f', energy {gain:+.3g} of its bound (seed {args.seed}; rerun: --only {kind} '
          f'--first {index} --cases 1 --clusters 1)')
    if far:
        far = np.array(far)
        print('distance of the answer from the 1000-sweep one in the energy norm (of the '
              'largest answer), '
              'median / 99th percentile / largest: ' + ', '.join(
                  f'{k} sweeps {np.median(d):.2g} / {np.percentile(d, 99):.2g} / {d.max():.2g}'
                  for k, d in zip(ITERATIONS, far.T[:3])))
        farthest = far[np.argmax(far[:, 2])]
        print(f'  farthest at 100 sweeps: {("manifolds", "clusters")[int(farthest[3])]} case '
              f'{int(farthest[4])}')
    for kind, index, iterations, gain in failures[:20]:
        print(f'  {kind} case {index}' + (f' at {iterations} iterations' if iterations else '')
              + f': energy {gain:+.3g} of its bound')
    return 1 if failures else 0


if __name__ == '__main__':
    sys.exit(main())
