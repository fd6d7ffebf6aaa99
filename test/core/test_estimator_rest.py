"""A settled pile that an estimator measures at rest, fed that state every period, sleeps.

An estimator publishes the pile as it sees it: the same poses every period, zero twists
(bench/bench_latency.py's estimator mode); each step's previous state is the node's last
answer. The answer to a pile at rest is that rest, so the pile falls asleep after
``time_to_sleep`` and stays asleep, and no answer carries a body faster than the sleep
speed.

The rest must then hold no hidden overlap: where two boxes' faces cross, tilted to one
another, their contact patch is a polygon of up to eight points at different depths, and
the reduction to four kept the area and could drop the deepest (where an edge of one box
crosses an edge of the other; test_collision_laws). The settling pile then sank that
corner into its neighbour unseen (1000 mixed bodies, 2 s at 120 Hz: box453 3.61 mm into
box597), and fed that rest, a step whose detection did see it pushed the box out every
period by turning it (the reference gap sees no turn between the answer and the input):
the answers drifted (0.1 rad in 16 steps) and every input woke the pile again one step
after it fell asleep (on 1c15e3e: asleep in 7 of 120 steps). Now the manifold keeps the
deepest point (within the slop): the settled pile's deepest overlap is 0.25 mm, and the
pile sleeps from step 15 on.

And an estimator's rest that does overlap (a box measured turned 0.05 rad into its
neighbour, 2.85 mm) is pushed out and stays out: the reference gap of a contact now takes
each body's turn from its poses, not from its twist (zero here), so the push-out sees what
it turned the last answer by. On 1c15e3e the push-out pushed again every step and the box
kept turning (0.0025 rad a step after 2 s) ever deeper into the box beside it (16.1 mm);
now it turns 0.045 rad back within 1 s and stops, 0.27 mm deep.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from collres_ros.core import rotation
from collres_ros.core.config import SolverSettings
from collres_ros.core.pipeline import Resolver
from collres_ros.core.shapes import bounding_radius
from collres_ros.core.types import BodyStates, InputBatch
from collres_ros.core.world import World

from overlap import deepest_into  # noqa: I100

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / 'bench'))
from pile import integrate, make_pile  # noqa: E402

SETTLE_DT = 1.0 / 120.0   # s, the pile is dropped and settled as bench_latency settles it
RATE = 30.0               # Hz, the estimator's rate


@pytest.mark.slow
def test_a_settled_pile_fed_its_rest_at_30_hz_falls_asleep_and_stays_asleep() -> None:
    bodies, state = make_pile(1000, seed=1, kind='mixed')
    world = World(bodies, SolverSettings(sleeping=False))
    for _ in range(int(round(2.0 / SETTLE_DT))):
        state = world.step(state, integrate(state, world.dynamic, SETTLE_DT), SETTLE_DT).states
    moving = np.flatnonzero(world.dynamic)
    names = [bodies[i].name for i in moving]
    rest = np.hstack([state.position[moving], state.orientation[moving],
                      np.zeros((len(moving), 6))])          # as measured: zero twists
    initial = BodyStates.zeros(len(bodies))
    initial.position[:], initial.orientation[:] = state.position, state.orientation
    settings = SolverSettings()
    resolver = Resolver(bodies, settings, initial=initial)
    reach = np.array([bounding_radius(bodies[i]) for i in moving])
    stamp, asleep, fastest = 10**12, [], 0.0
    for _ in range(int(4.0 * RATE)):
        stamp += int(round(1e9 / RATE))
        step = resolver.resolve(stamp, InputBatch(names, rest, 'world', 'world'))
        asleep.append(bool(step.sleeping.all()))
        speed = (np.linalg.norm(step.states.linear, axis=1)
                 + np.linalg.norm(step.states.angular, axis=1) * reach)
        fastest = max(fastest, float(speed.max()))
    first = asleep.index(True) if True in asleep else None
    print(f'asleep in {sum(asleep)} of {len(asleep)} steps, first at step {first}; '
          f'fastest point in an answer {fastest:.4f} m/s')
    assert first is not None and first < 2.0 * RATE
    assert all(asleep[first:]), 'an input woke the pile'
    assert fastest <= settings.sleep_threshold


def test_a_rest_measured_overlapping_is_pushed_out_and_stays_out() -> None:
    bodies, state = make_pile(100, seed=1, kind='mixed')
    world = World(bodies, SolverSettings(sleeping=False))
    for _ in range(int(round(2.0 / SETTLE_DT))):
        state = world.step(state, integrate(state, world.dynamic, SETTLE_DT), SETTLE_DT).states
    index = [b.name for b in bodies].index('box33')
    state.orientation[index] = rotation.multiply(
        rotation.from_rotation_vector(np.array([0.05, 0.0, 0.0])), state.orientation[index])
    given = deepest_into(bodies, state, index)
    moving = np.flatnonzero(world.dynamic)
    row = int(np.flatnonzero(moving == index)[0])
    measured = np.hstack([state.position[moving], state.orientation[moving],
                          np.zeros((len(moving), 6))])
    initial = BodyStates.zeros(len(bodies))
    initial.position[:], initial.orientation[:] = state.position, state.orientation
    resolver = Resolver(bodies, SolverSettings(sleeping=False), initial=initial)
    names = [bodies[i].name for i in moving]
    stamp, turns = 10**12, []
    for _ in range(int(2.0 * RATE)):
        stamp += int(round(1e9 / RATE))
        step = resolver.resolve(stamp, InputBatch(names, measured, 'world', 'world'))
        turns.append(step.states.orientation[row].copy())
    answered = state.copy()
    answered.position[moving] = step.states.position
    answered.orientation[moving] = step.states.orientation
    depth = deepest_into(bodies, answered, index)
    last = max(2.0 * np.arccos(min(1.0, abs(float(np.dot(q, p)))))
               for q, p in zip(turns[-10:], turns[-11:-1]))
    print(f'box33 {given * 1e3:.2f} mm deep as measured, {depth * 1e3:.2f} mm in the last '
          f'answer; the last answers turn {last:.1e} rad a step')
    assert depth < 0.25 * given
    assert last < 1e-4
