"""A pile at rest given one input after a gap longer than ``max_dt``, or one input twice,
stays at rest.

A source that integrates gravity sends, after a gap, the pile's rest state advanced by one
of its steps: every body g dt^2 into its supports and moving down at g dt, the change its
supports take away at every usual step. No timing of the inputs may launch a resting body:

* sleeping on, the pile asleep before the gap stays asleep, answered at its held rest
  (the step is the usual one of the stream's period from the held states);
* sleeping off, or a body moved during the gap: the bodies restart from their inputs, and
  the fresh step must not turn the input's g dt into motion: the supports carry it, the
  overlap goes as position (push-out), so the answer keeps a small fraction of the input's
  kinetic energy and no body leaves at a good part of g dt.

The pile is at rest before the gap (asleep, or every body slower than 0.02 g dt for a
second): a pile driven for a fixed 3 s with sleeping off could still be settling, a ball
rolling off a ledge at 0.40 g dt and gaining 0.1 g dt a step, which the fresh step answered
at 0.60 g dt (the usual step: 0.52 g dt); from rest the fresh step leaves the fastest
body at 0.17-0.18 g dt, 0.2 % of the input's kinetic energy.

An input delivered twice (the same stamp again) is refused and counted, and nothing else
happens: no time passed (on 7ed1f81 the repeat was a fresh world step of nothing, which woke
every island and dropped the warm start: the next steps shook the asleep pile up to
0.057 m/s at 30 Hz, 0.15 m/s at 100 Hz, still moving 1 s later).

On 8ac80a2 every body restarted, reading the input's g dt as its own velocity before a 1 ms
step: the asleep pile woke, and the bodies held by friction (spheres against the walls and
one another) slid down at up to 0.68 g dt (0.22 m/s; 4.9 % of the input's kinetic energy
kept, sleeping off; 0.67 g dt and 5.5 % with a body moved), which shook the pile. Now the
asleep pile stays asleep, and a restart keeps a body's last answer's twist as the one before
the step over the stream's period.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from collres_ros.core.config import SolverSettings
from collres_ros.core.pipeline import Resolver
from collres_ros.core.types import BodyStates, InputBatch

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / 'bench'))
from pile import GRAVITY, integrate, make_pile  # noqa: E402

RATE = 30.0          # Hz, the source's period
GAP = 1.0            # s, longer than max_dt (0.5 s)
REST = 0.02          # fraction of g dt: a pile whose bodies are all slower is at rest


def _g_dt() -> float:
    return float(np.linalg.norm(GRAVITY)) / RATE


def _values(states: BodyStates) -> np.ndarray:
    return np.hstack([states.position, states.orientation, states.linear, states.angular])


def _settled(sleeping: bool):
    """The mixed pile driven as its source drives it (the answer integrated one step) until
    at rest, 6 s at most: asleep (sleeping on) or, sleeping off, every body slower than
    REST g dt for a second: resolver, names, masses, last answer, stamp."""
    bodies, state = make_pile(100, seed=1, kind='mixed')
    resolver = Resolver(bodies, SolverSettings(sleeping=sleeping))
    moving = np.flatnonzero([not b.static for b in bodies])
    names = [bodies[i].name for i in moving]
    answer = BodyStates(state.position[moving], state.orientation[moving],
                        state.linear[moving], state.angular[moving])
    dynamic = np.ones(len(moving), bool)
    stamp = 10**12
    still = 0   # steps in a row with every body slower than REST g dt
    for _ in range(int(6.0 * RATE)):
        stamp += int(round(1e9 / RATE))
        step = resolver.resolve(stamp, InputBatch(
            names, _values(integrate(answer, dynamic, 1.0 / RATE)), 'world', 'world'))
        answer = step.states
        slow = np.linalg.norm(answer.linear, axis=1).max() < REST * _g_dt()
        still = still + 1 if slow else 0
        if step.sleeping.all() if sleeping else still >= RATE:
            break
    assert step.sleeping.all() if sleeping else still >= RATE
    mass = np.array([bodies[i].mass for i in moving])
    return resolver, names, mass, answer, stamp


def _after_gap(resolver, names, answer, stamp, moved=0.0):
    """The answer to the rest advanced one period, GAP later (body 0 moved ``moved`` m
    along x during the gap): (input, step)."""
    given = integrate(answer, np.ones(len(names), bool), 1.0 / RATE)
    given.position[0, 0] += moved
    stamp += int(round(1e9 * (GAP + 1.0 / RATE)))
    return given, resolver.resolve(stamp, InputBatch(names, _values(given), 'world', 'world'))


def _kinetic(mass: np.ndarray, states: BodyStates) -> float:
    return 0.5 * float((mass * (states.linear ** 2).sum(1)).sum())


def test_an_asleep_pile_given_its_rest_after_a_gap_stays_asleep_at_rest() -> None:
    resolver, names, mass, rest, stamp = _settled(sleeping=True)
    given, step = _after_gap(resolver, names, rest, stamp)
    assert {r.reason for r in step.resets} == {'large_gap'} and step.resumed_asleep
    assert step.sleeping.all()
    assert _kinetic(mass, step.states) == 0.0
    np.testing.assert_array_equal(step.states.position, rest.position)
    assert step.dt == pytest.approx(1.0 / RATE)


@pytest.mark.parametrize('sleeping,moved', [(False, 0.0), (True, 0.02)])
def test_a_restarted_pile_gains_no_motion_from_its_input_after_a_gap(sleeping: bool,
                                                                     moved: float) -> None:
    resolver, names, mass, rest, stamp = _settled(sleeping)
    given, step = _after_gap(resolver, names, rest, stamp, moved)
    assert {r.reason for r in step.resets} == {'large_gap'}
    assert not step.resumed_asleep   # a fresh start, reported so
    fastest = float(np.linalg.norm(step.states.linear, axis=1).max())
    g_dt = _g_dt()
    print(f'kinetic energy {_kinetic(mass, given):.3f} J in, '
          f'{_kinetic(mass, step.states):.2e} J out; fastest {fastest / g_dt:.2f} g dt')
    assert _kinetic(mass, step.states) < 0.01 * _kinetic(mass, given)
    assert fastest < 0.3 * g_dt


def test_an_asleep_pile_whose_input_arrives_twice_stays_asleep_at_rest() -> None:
    resolver, names, mass, rest, stamp = _settled(sleeping=True)
    answer = rest
    for k in range(int(RATE)):   # a second of the usual steps, the first input sent twice
        stamp += int(round(1e9 / RATE))
        batch = InputBatch(names, _values(integrate(answer, np.ones(len(names), bool),
                                                    1.0 / RATE)), 'world', 'world')
        step = resolver.resolve(stamp, batch)
        if k == 0:
            again = resolver.resolve(stamp, batch)
            assert {r.reason for r in again.rejected} == {'repeated_stamp'}
            assert again.names == [] and again.report.contacts.count == 0
        answer = step.states
        assert step.sleeping.all(), f'woke {1 + k} steps after the repeat'
        assert _kinetic(mass, step.states) == 0.0
    np.testing.assert_array_equal(answer.position, rest.position)
    assert resolver.totals['repeated_stamp'] == len(names)
