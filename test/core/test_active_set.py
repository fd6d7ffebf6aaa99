"""The sweeps leave out contacts that carry nothing, and the answer is still every contact's.

A manifold whose points hold no impulse and separate faster than their speculative
allowance (by more than ``SOLVER_TUNING`` ``activation_margin``) is left out of the velocity
sweeps. After the sweeps every manifold left out is checked against the solved
velocities; one they drive beyond its allowance is let in and the sweeps go on. So the
answer satisfies every contact: a contact left out at the start that the other contacts'
impulses turn into a real one within the same substep still stops the body.

The law, with hand-made contacts and no gravity (e = 0, no friction), three balls on a
line, each spun up about the line by an external torque in the step (a load, so the
restitution threshold applies; a spin about the line moves no contact point): a 1 kg ball
at rest; 1 mm from it a second 1 kg ball moving away from it at 0.1 m/s; touching that one
from the other side a 100 kg ball approaching at 0.3 m/s (slower than the restitution
threshold: the resting solve's work, not an impact's). The heavy ball
pushes the middle one back into the first within the step's first substep: all three end
moving together at the velocity momentum gives them, (m v) summed over the total mass, and
the middle ball never goes into the first deeper than the slop. Sweeping only the contacts
in the set at the start of the substep (no check after the sweeps), it went 0.80 mm in at
30 Hz and 0.21 mm at 120 Hz (the next substep let the contact in; the position pass pushes
only a part of the depth out per step).
"""

from __future__ import annotations

import numpy as np
import pytest

from collres_ros.core.config import SolverSettings
from collres_ros.core.types import ContactKind, ContactSet
from collres_ros.core.world import World

from contacts import FixedContacts, sphere, states  # noqa: I100

RADIUS = 0.05              # m
GAP = 0.001                # m, between the first two balls at the step's start
MASS = np.array([1.0, 1.0, 100.0])    # kg
SPEED = np.array([0.0, 0.1, -0.3])    # m/s along +x


def contacts(x: np.ndarray) -> ContactSet:
    """The first two balls' contact (their gap) and the last two's (touching), at centres
    ``x`` (m, along x: the current state's)."""
    a = np.array([0, 1], np.int64)
    b = np.array([1, 2], np.int64)
    point = np.array([[x[0] + RADIUS, 0, 0], [x[1] + RADIUS, 0, 0]], float)
    normal = np.array([[1.0, 0, 0], [1.0, 0, 0]])
    separation = np.array([x[1] - x[0], x[2] - x[1]]) - 2 * RADIUS
    return ContactSet(a, b, point, normal, separation, np.zeros(2),
                      np.full(2, int(ContactKind.PERSISTENT), np.int8),
                      np.arange(2, dtype=np.int64), np.array([[0, 1, 0, 1], [1, 2, 1, 1]],
                                                             np.int64))


@pytest.mark.parametrize('rate', [30.0, 120.0])
def test_a_contact_left_out_that_the_push_closes_still_stops_the_body(rate):
    dt = 1.0 / rate
    bodies = [sphere(f'ball{i}', RADIUS, m, e=0.0) for i, m in enumerate(MASS)]
    previous = states([[0, 0, 0], [2 * RADIUS + GAP, 0, 0], [4 * RADIUS + GAP, 0, 0]],
                      [[s, 0, 0] for s in SPEED])
    current = previous.copy()
    current.angular[:, 0] += 1.0                       # rad/s: the torque's spin, a load
    current.position += current.linear * dt
    settings = SolverSettings(restitution_threshold=1.0)   # 0.4 m/s: a resting approach
    world = World(bodies, settings, FixedContacts(contacts(current.position[:, 0]), settings))
    result = world.step(previous, current, dt)
    x, v = result.states.position[:, 0], result.states.linear[:, 0]
    together = MASS @ SPEED / MASS.sum()            # m/s, the common velocity
    depth = 2 * RADIUS - (x[1] - x[0])              # m, the middle ball into the first
    print(f'{rate:.0f} Hz: velocities {v} m/s (together {together:.5f}), the middle ball '
          f'{depth * 1e3:.4f} mm into the first, impulses {result.report.normal_impulse} N s')
    assert result.report.normal_impulse[0] > 0.0          # the contact left out carried it
    assert v == pytest.approx(np.full(3, together), abs=1e-4 * abs(together))
    assert depth <= settings.linear_slop + 1e-9           # not into it beyond the slop
