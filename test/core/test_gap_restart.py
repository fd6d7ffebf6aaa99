"""A pile at rest given one input after a gap longer than ``max_dt`` stays (nearly) at rest.

After a gap the resolver restarts every body (previous pose = its input's pose). A source
that integrates gravity sends the pile's rest state advanced by one of its steps: every
body g dt^2 into its supports and moving down at g dt, the change its supports take away
at every usual step. The fresh step must not turn that into motion: the supports carry it
and the overlap goes as position (push-out), so the answer's kinetic energy is a small
fraction of the input's and no body leaves at a good part of g dt. On 8ac80a2 the fresh
step read the input's g dt as each body's own velocity before the step, over a 1 ms step:
the bodies held by friction (spheres against the walls and one another) slid down at up
to 0.74 g dt (0.24 m/s; 4.2 % of the input's kinetic energy kept) and shook the pile awake.
Now a body resumed forward keeps its last answer's twist as the one before the step and
the step spans the stream's period: 0.05 g dt at most, 0.02 % of the energy.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from collres_ros.core.config import SolverSettings
from collres_ros.core.pipeline import Resolver
from collres_ros.core.types import BodyStates, InputBatch

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / 'bench'))
from pile import GRAVITY, integrate, make_pile  # noqa: E402

RATE = 30.0          # Hz, the source's period
GAP = 1.0            # s, longer than max_dt (0.5 s)


def _values(states: BodyStates) -> np.ndarray:
    return np.hstack([states.position, states.orientation, states.linear, states.angular])


def test_a_resting_pile_given_one_input_after_a_gap_stays_at_rest() -> None:
    bodies, state = make_pile(100, seed=1, kind='mixed')
    resolver = Resolver(bodies, SolverSettings())
    moving = np.flatnonzero([not b.static for b in bodies])
    names = [bodies[i].name for i in moving]
    mass = np.array([bodies[i].mass for i in moving])
    dt = 1.0 / RATE
    answer = BodyStates(state.position[moving], state.orientation[moving],
                        state.linear[moving], state.angular[moving])
    dynamic = np.ones(len(moving), bool)
    stamp = 10**12
    for _ in range(int(6.0 * RATE)):   # the source's drive until the pile is asleep
        stamp += int(round(1e9 * dt))
        step = resolver.resolve(stamp, InputBatch(
            names, _values(integrate(answer, dynamic, dt)), 'world', 'world'))
        answer = step.states
        if step.sleeping.all():
            break
    assert step.sleeping.all()
    stamp += int(round(1e9 * (GAP + dt)))
    given = integrate(answer, dynamic, dt)
    step = resolver.resolve(stamp, InputBatch(names, _values(given), 'world', 'world'))
    assert [r.reason for r in step.resets] == ['large_gap'] * len(names)
    kinetic_in = 0.5 * float((mass * (given.linear ** 2).sum(1)).sum())
    kinetic_out = 0.5 * float((mass * (step.states.linear ** 2).sum(1)).sum())
    fastest = float(np.linalg.norm(step.states.linear, axis=1).max())
    g_dt = float(np.linalg.norm(GRAVITY)) * dt
    print(f'kinetic energy {kinetic_in:.3f} J in, {kinetic_out:.2e} J out; '
          f'fastest {fastest:.4f} m/s = {fastest / g_dt:.2f} g dt')
    assert kinetic_out < 0.01 * kinetic_in
    assert fastest < 0.3 * g_dt
