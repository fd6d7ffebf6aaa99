"""A contact without a solver row that the answer drives into approach still stops the body.

``prepare`` gives no row to a speculative contact that separates faster than
``SOLVER_TUNING`` ``row_bound`` (1 + e) times the step's fastest approach before the solve:
most impulses cannot turn it around. A chain of impacts can: each e = 1 hit of a ball on
one ten times lighter sends it on at 2 / 1.1 times the speed, so the third ball of a chain
leaves at 6 v0. The net: after each substep and after the landing every contact without a
row is checked at the solved velocities; one that approaches beyond its allowance gets a
row and the step is solved again. So the last ball of the chain, headed for a wall it
reaches within the step, stops short of the wall (and the step gains no energy).

Hand-made contacts, no gravity, 30 Hz: a 1 kg ball at v0 = 1 m/s hits a line of touching
balls of 0.1, 0.01 and 0.001 kg; 150 mm beyond the last ball a fixed wall (a speculative
contact that separates, with its allowance of 4.5 m/s, faster than 2 (1 + e) v0 = 4 m/s:
no row on the old bound either). The chain sends the last ball at about 6 m/s: 200 mm
over the step. Without the net it went 50 mm into the wall.
"""

from __future__ import annotations

import numpy as np

from collres_ros.core.config import SolverSettings
from collres_ros.core.types import ContactKind, ContactSet
from collres_ros.core.world import World

from contacts import FixedContacts, sphere, states  # noqa: I100

R = 0.05                                    # m, ball radius
WALL = 0.5                                  # m, the wall: a fixed sphere this large
GAP = 0.15                                  # m, from the last ball to the wall
MASS = [1.0, 0.1, 0.01, 0.001]              # kg
V0 = 1.0                                    # m/s


def chain_contacts(x: np.ndarray) -> ContactSet:
    """The first ball's impact on the second (at its time of impact, the step's start),
    the touching pairs, and the last ball's gap to the wall; centres ``x`` (m, along x)."""
    a = np.array([0, 1, 2, 3], np.int64)
    b = np.array([1, 2, 3, 4], np.int64)
    point = np.array([[x[1] - R, 0, 0], [x[1] + R, 0, 0], [x[2] + R, 0, 0],
                      [x[3] + R, 0, 0]], float)
    normal = np.tile([1.0, 0.0, 0.0], (4, 1))
    kind = np.array([ContactKind.IMPACT] + [ContactKind.PERSISTENT] * 3, np.int8)
    return ContactSet(a, b, point, normal, np.array([0.0, 0.0, 0.0, GAP]), np.zeros(4),
                      kind, np.zeros(4, np.int64),
                      np.array([[i, i + 1, i, 1] for i in range(4)], np.int64))


def test_the_last_ball_of_a_chain_stops_short_of_a_wall_it_had_no_row_for():
    dt = 1.0 / 30.0
    bodies = [sphere(f'ball{i}', R, m, e=1.0) for i, m in enumerate(MASS)]
    bodies.append(sphere('wall', WALL, 1.0, e=1.0, static=True))
    x = np.array([-2 * R, 0.0, 2 * R, 4 * R, 5 * R + GAP + WALL])
    previous = states([[xi, 0, 0] for xi in x], [[V0, 0, 0]] + [[0, 0, 0]] * 4)
    current = previous.copy()
    current.position += current.linear * dt
    settings = SolverSettings(sleeping=False)
    world = World(bodies, settings, FixedContacts(chain_contacts(x), settings))
    result = world.step(previous, current, dt)
    end, v = result.states.position[:, 0], result.states.linear[:, 0]
    into = (end[3] + R) - (x[4] - WALL)               # m, the last ball into the wall
    m = np.array(MASS)
    before, after = 0.5 * m[0] * V0 ** 2, 0.5 * m @ v[:4] ** 2
    print(f'velocities {v} m/s, the last ball {into * 1e3:.3f} mm into the wall, '
          f'kinetic energy {before:.6f} -> {after:.6f} J, impulses '
          f'{result.report.normal_impulse} N s')
    assert into <= settings.linear_slop + 1e-9       # it stops short of the wall
    assert result.report.normal_impulse[3] > 0.0    # the wall stopped it
    assert after <= before * (1.0 + 1e-9)          # no energy gained
