"""The resting solve in substeps (``solver.max_substep``, ``StepSolver::soft_step``).

At 30 Hz one sequential-impulse solve per step does not converge a deep stack under one
step's load (g dt = 0.33 m/s): a column of 7 cubes of 0.1 m started touching toppled
within 1-2 s, and a pile of mixed bodies never came to rest, its bodies 5-6 cm into one
another (bench/pile.py's mixed pile of 200, seeds 1 and 2: awake after 8 s, 52 and 57 mm
deep). After its one detection a step's resting solve now runs in ceil(dt / max_substep)
substeps (5 of 1/150 s at 30 Hz), each adding its share of gravity, letting each contact
close by its separation as the substeps so far moved its bodies, and moving the poses.
With the default settings:

* a column of 7 cubes started touching stands at 30 Hz, and the floor carries m g dt
  (the old core, one solve per step: the column fell 678 mm);
* a body the solve does not touch ends the step at its input, bit for bit.

(The mixed pile at 30 Hz still does not rest: most of its depth grows at impacts, the
pair's own or a third body's, and 1 % of it (200 bodies; 14 % at 1000) in pairs
detection gave no contact (``bench/bench_rest.py --why``; test_fast_approach.py);
towers: test_stacks.py.)
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from collres_ros.core.config import SolverSettings
from collres_ros.core.types import BodySpec
from collres_ros.core.world import World

from contacts import box, sphere, states  # noqa: I100
from integrator import Simulation

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / 'bench'))
from pile import integrate  # noqa: E402

RATE = 30.0
G = 9.81


def column(count: int, settings: SolverSettings) -> Simulation:
    """``count`` cubes of 0.1 m stacked touching on a floor, at rest, stepped at 30 Hz."""
    floor = BodySpec('floor', 'plane', (0.0, 0.0, 1.0, 0.0), static=True,
                     static_friction=0.6, kinetic_friction=0.4)
    cubes = [box(f'cube{k}', (0.1,) * 3, 1.0, e=0.2, mu_s=0.6, mu_k=0.4) for k in range(count)]
    start = [[0.0, 0.0, 0.0]] + [[0.0, 0.0, 0.05 + 0.1 * k] for k in range(count)]
    return Simulation([floor] + cubes, states(start, np.zeros((count + 1, 3))), RATE, settings)


def test_a_column_of_7_cubes_stands_at_30_hz() -> None:
    sim = column(7, SolverSettings(sleeping=False))
    start = sim.state.position.copy()
    for _ in range(int(10 * RATE)):
        result = sim.step()
    assert sim.world.timing['substeps'] == 5
    drift = float(np.abs(sim.state.position - start)[1:].max())
    floor = result.report.contacts.body_a == 0
    carried = result.report.normal_impulse[floor].sum() / (7 * G / RATE)
    print(f'drift {drift * 1e3:.3f} mm in 10 s; floor impulse / (m g dt) {carried:.9f}')
    assert drift < 0.005
    assert carried == pytest.approx(1.0, abs=1e-5)


def test_a_body_the_solve_does_not_touch_ends_at_its_input_bit_for_bit() -> None:
    """A ball flying past a resting box (5 substeps): the box is resolved, the ball is
    answered with its input, every bit."""
    floor = BodySpec('floor', 'plane', (0.0, 0.0, 1.0, 0.0), static=True)
    bodies = [floor, box('box', (0.2,) * 3, 1.0, mu_s=0.5, mu_k=0.5),
              sphere('ball', 0.1, 1.0)]
    world = World(bodies, SolverSettings())
    previous = states([[0, 0, 0], [0, 0, 0.1], [2.0, 0.0, 1.0]],
                      [[0, 0, 0], [0, 0, 0], [0.7, -0.3, 1.1]],
                      angular=[[0, 0, 0], [0, 0, 0], [3.0, -1.0, 0.5]])
    dt = 1.0 / RATE
    current = integrate(previous, world.dynamic, dt)
    result = world.step(previous, current, dt)
    assert world.timing['substeps'] == 5
    for name in ('position', 'orientation', 'linear', 'angular'):
        np.testing.assert_array_equal(getattr(result.states, name)[2], getattr(current, name)[2])
    assert result.states.position[1, 2] == pytest.approx(0.1, abs=1e-4)   # held by the floor
