"""``StepResult.unchanged`` / ``ResolvedStep.unchanged``: a step says its contact report is the
last step's exactly when it is, array for array (what the node's encoder then only restamps).

Two boxes stacked on a floor at 100 Hz, inputs as a simulator sends them (the last answer plus
gravity dt), with lost inputs, a push that wakes them, a ball dropped beside them later: every
step flagged unchanged has the previous step's report bit for bit, and a resting pile's held
contacts are flagged (most steps once it sleeps); with sleeping off, no step is.
"""

from __future__ import annotations

import numpy as np
import pytest

from collres_ros.core.config import SolverSettings
from collres_ros.core.pipeline import Resolver
from collres_ros.core.types import BodySpec, BodyStates, InputBatch

RATE = 100.0
SIZE = 0.2


def report_arrays(step):
    r, c = step.report, step.report.contacts
    return [np.asarray(a) for a in (c.body_a, c.body_b, c.point, c.normal, c.separation,
                                    c.toi, c.kind, c.feature, r.normal_impulse,
                                    r.friction_impulse, r.state, *c.pieces())]


def same(a, b):
    return len(a) == len(b) and all(x.dtype == y.dtype and x.shape == y.shape
                                    and x.tobytes() == y.tobytes() for x, y in zip(a, b))


@pytest.mark.parametrize('sleeping', [True, False])
def test_unchanged_exactly_when_the_report_is_the_last_ones(sleeping: bool) -> None:
    bodies = [BodySpec('floor', 'plane', (0.0, 0.0, 1.0, 0.0), static=True),
              BodySpec('lower', 'box', (SIZE,) * 3, mass=1.0),
              BodySpec('upper', 'box', (SIZE,) * 3, mass=1.0),
              BodySpec('ball', 'sphere', (0.1,), mass=1.0)]
    state = BodyStates.zeros(4)
    state.position[1:, 2] = [SIZE / 2, 1.5 * SIZE, 0.1]
    state.position[3, 0] = 2.0
    resolver = Resolver(bodies, SolverSettings(sleeping=sleeping), initial=state)
    names = [b.name for b in bodies][1:]
    values = np.concatenate([state.position[1:], state.orientation[1:], state.linear[1:],
                             state.angular[1:]], axis=1)
    stamp, period = 5 * 10**9, int(1e9 / RATE)
    last, flagged = None, []
    for k in range(400):
        stamp += period
        values[:, 9] += -9.81 / RATE
        values[:, 0:3] += values[:, 7:10] / RATE
        if k == 200:
            values[1, 7] = 0.5          # the upper box pushed sideways
        if k == 300:
            values[2, 2] = 0.5          # the ball lifted: it falls beside the boxes
        if k in (150, 153, 156):
            continue                    # inputs lost on the way: not a step (dt 20 ms)
        step = resolver.resolve(stamp, InputBatch(names, values.copy(), 'world', 'world'))
        now = report_arrays(step)
        if step.unchanged:
            assert last is not None and same(now, last), f'step {k}: flagged, but it changed'
            flagged.append(k)
        last, values = now, np.concatenate(
            [step.states.position, step.states.orientation, step.states.linear,
             step.states.angular], axis=1)
    print('unchanged steps', len(flagged), flagged[:5], flagged[-5:])
    if sleeping:
        assert len(flagged) > 200 and 200 not in flagged and 201 not in flagged
    else:
        assert not flagged
