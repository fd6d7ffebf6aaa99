"""A rocking column of cubes loses energy in every step and comes to rest.

Seven cubes of 0.1 m and 1 kg stand in a column on a plane (restitution 0.2, friction 0.6
static / 0.4 kinetic, the floor's and the cubes'), set rocking about a base edge at 0.3
rad/s as one rigid body (kinetic energy 52 mJ, far from the 0.24 J that would tip it
over). Its mechanical energy (kinetic + m g z of the seven cubes) can only fall: gravity is
conservative, the contacts are inelastic with friction, and nothing drives the column. A
rigid block so rocking (Housner) keeps (1 - 3/2 sin^2 a)^2 = 0.94 of its kinetic energy at
each change of edge (a = atan(0.1 / 0.7)), over ever shorter swings: its swings add up to
0.8 s; with 80 sweeps a substep the column is below 0.01 m/s after 0.83 s (30 Hz) and
1.00 s (120 Hz).

The energy law is checked with position_correction 0, so that it reads the velocity solve
alone: then a step's energy may rise by rounding only, 1e-6 J of 24 J (the push-out's
potential energy, by design not bounded by the velocity solve's law, is left out). That is
the law of the contact solve, not of the integrator: symplectic Euler about a fixed edge
under gravity's torque I k (constant on either side of the edge) loses I (k h)^2 / 2 in
each substep h, and the sweeps run to convergence (1000 a substep, no early stop) gain at
most 1e-7 J in a step at 30 and 120 Hz; a single 0.1 x 0.1 x 0.7 m block of 7 kg so
rocking gains nothing, with the defaults too. The rest is checked with the defaults.

What meets it: the sweeps alone, warm started from the impulses that held the column while
it leaned the other way, give it up to 4.7 mJ in a substep where it changes the edge it
rocks on (17 mJ a step at 30 Hz); the column (one island of 7 movable cubes, 28 rows) is
then solved exactly (StepSolver::exact_islands: its rows' rules as equalities of one dense
system from the substep's start velocities, each from the set the one before found) in
every substep until 0.2 s have passed without such a gain (its edges change at most 0.15 s
apart): it gains at most 2.2e-8 / 5.0e-9 J a step and rests after 0.67 / 0.83 s at 30 /
120 Hz.
"""

from __future__ import annotations

import numpy as np
import pytest

from collres_ros.core.config import SolverSettings
from collres_ros.core.rotation import to_matrix
from collres_ros.core.types import BodySpec

from contacts import states  # noqa: I100
from integrator import Simulation

CUBES = 7
SIDE = 0.1        # m
SPIN = 0.3        # rad/s about y, tilting towards +x about the base edge at x = +SIDE / 2
GAIN = 1e-6       # J, the most a step may add to the column's mechanical energy (rounding)
REST_BY = 1.5     # s, from then on every cube's fastest point is below STILL
STILL = 0.01      # m/s


def column(rate: float, settings: SolverSettings) -> Simulation:
    """The column on its floor, rocking as one body about the base edge at x = +SIDE / 2."""
    material = dict(restitution=0.2, static_friction=0.6, kinetic_friction=0.4)
    floor = BodySpec('floor', 'plane', (0.0, 0.0, 1.0, 0.0), static=True, **material)
    cubes = [BodySpec(f'box{k}', 'box', (SIDE, SIDE, SIDE), mass=1.0, **material)
             for k in range(CUBES)]
    edge = np.array([SIDE / 2, 0.0, 0.0])
    spin = np.array([0.0, SPIN, 0.0])
    position = [np.zeros(3)] + [np.array([0.0, 0.0, SIDE * (k + 0.5)]) for k in range(CUBES)]
    linear = [np.zeros(3)] + [np.cross(spin, p - edge) for p in position[1:]]
    angular = [np.zeros(3)] + [spin] * CUBES
    return Simulation([floor] + cubes, states(position, linear, angular), rate, settings)


def mechanical_energy(sim: Simulation) -> float:
    """J: kinetic energy + m g z of the cubes (the floor is static)."""
    s = sim.state
    w_body = np.einsum('nji,nj->ni', to_matrix(s.orientation), s.angular)
    kinetic = 0.5 * sim.mass * np.sum(s.linear ** 2, axis=1) \
        + 0.5 * np.sum(sim.inertia_body * w_body ** 2, axis=1)
    return float(np.sum((kinetic + sim.mass * -sim.gravity[2] * s.position[:, 2])[1:]))


@pytest.mark.parametrize('rate', [30.0, 120.0])
def test_rocking_column_never_gains_energy(rate):
    sim = column(rate, SolverSettings(position_correction=0.0))
    energy = mechanical_energy(sim)
    rises = []
    while sim.time < 3.0:
        sim.step()
        now = mechanical_energy(sim)
        rises.append(now - energy)
        energy = now
    assert np.abs(sim.state.position[1:, :2]).max() < SIDE / 10   # standing where it stood
    assert max(rises) <= GAIN, f'a step gained {max(rises) * 1e3:.3f} mJ'


@pytest.mark.parametrize('rate', [30.0, 120.0])
def test_rocking_column_comes_to_rest(rate):
    sim = column(rate, SolverSettings())
    fastest = 0.0   # m/s, of a cube's point from REST_BY on
    while sim.time < REST_BY + 1.5:
        sim.step()
        if sim.time < REST_BY - 1e-9:
            continue
        s = sim.state
        speed = np.linalg.norm(s.linear[1:], axis=1) \
            + np.linalg.norm(s.angular[1:], axis=1) * np.sqrt(3.0) * SIDE / 2
        fastest = max(fastest, float(speed.max()))
    assert fastest < STILL, f'a cube moves at {fastest:.4f} m/s after {REST_BY} s'
    assert np.abs(sim.state.position[1:, :2]).max() < SIDE / 10   # standing where it stood
