"""Substeps (``solver.max_substep``, core/substeps.py): a 30 Hz step resolved as two of 1/60 s.

At 30 Hz the sequential-impulse sweeps do not converge a deep stack under one step's load
(g dt = 0.33 m/s): a column of 7 cubes of 0.1 m started touching topples within 1-2 s,
and a pile of mixed bodies never comes to rest, its bodies 5-6 cm into one another
(bench/pile.py's mixed pile of 200, seeds 1 and 2: awake after 8 s, 52 and 57 mm deep;
1000 bodies: awake after 12 s, 13-70 mm deep, the bottom boxes 12-16 mm into the floor).
Stepped at 60 or 120 Hz the same piles rest. In substeps of at most 1/60 s:

* a mixed pile of 200 bodies dropped at 30 Hz sleeps within 3 s (1.5 and 1.9 s), and no
  answer after the first second goes deeper into anything than the slop plus what the
  position pass leaves of one substep's fall: a resting contact whose load the sweeps left
  whole sinks g h^2 per substep of h s, and the pass removes ``position_correction`` of the
  depth beyond the slop per substep, so the depth stays below slop + g h^2 /
  position_correction (6.9 mm; measured 1.8 and 1.4 mm);
* a column of 7 cubes started touching stands at 30 Hz (0.3 mm in 10 s);
* a body no substep touches ends the step at its input, bit for bit, and the report's
  impulses are the step's: a column's floor contacts carry m g dt.

Each law fails with ``max_substep`` 0 (one solve per 30 Hz step), as the old core did.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from collres_ros.core.config import SolverSettings
from collres_ros.core.detection import Detection
from collres_ros.core.types import BodySpec
from collres_ros.core.world import World

from contacts import box, sphere, states  # noqa: I100
from integrator import Simulation

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / 'bench'))
from pile import integrate, make_pile  # noqa: E402

RATE = 30.0
SUBSTEP = 1.0 / 60.0
SETTINGS = SolverSettings(max_substep=SUBSTEP)
G = 9.81


@pytest.mark.parametrize('seed', [1, 2])
def test_a_mixed_pile_dropped_at_30_hz_comes_to_rest_in_substeps(seed: int) -> None:
    bodies, state = make_pile(200, seed=seed, kind='mixed')
    world = World(bodies, SETTINGS)
    probe = Detection(world.specs, SolverSettings(sleeping=False))
    dynamic = world.dynamic
    h = 1.0 / RATE / np.ceil(1.0 / RATE / SUBSTEP - 1e-9)
    bound = SETTINGS.linear_slop + G * h * h / SETTINGS.position_correction
    dt, deepest, asleep = 1.0 / RATE, 0.0, None
    for k in range(int(3.0 * RATE)):
        result = world.step(state, integrate(state, dynamic, dt), dt)
        state = result.states
        if (k + 1) * dt > 1.0:
            seen = probe.detect(state, state)
            deepest = max(deepest, float(-seen.separation.min()))
        if result.sleeping[dynamic].all():
            asleep = (k + 1) * dt
            break
    print(f'seed {seed}: asleep after {asleep} s, deepest {deepest * 1e3:.2f} mm '
          f'(bound {bound * 1e3:.2f} mm)')
    assert asleep is not None, 'awake after 3 s'
    assert deepest <= bound


def column(count: int, settings: SolverSettings) -> Simulation:
    """``count`` cubes of 0.1 m stacked touching on a floor, at rest, stepped at 30 Hz."""
    floor = BodySpec('floor', 'plane', (0.0, 0.0, 1.0, 0.0), static=True,
                     static_friction=0.6, kinetic_friction=0.4)
    cubes = [box(f'cube{k}', (0.1,) * 3, 1.0, e=0.2, mu_s=0.6, mu_k=0.4) for k in range(count)]
    start = [[0.0, 0.0, 0.0]] + [[0.0, 0.0, 0.05 + 0.1 * k] for k in range(count)]
    return Simulation([floor] + cubes, states(start, np.zeros((count + 1, 3))), RATE, settings)


def test_a_column_of_7_cubes_stands_at_30_hz_in_substeps() -> None:
    sim = column(7, SolverSettings(sleeping=False, max_substep=SUBSTEP))
    start = sim.state.position.copy()
    for _ in range(int(10 * RATE)):
        result = sim.step()
    drift = float(np.abs(sim.state.position - start)[1:].max())
    floor = result.report.contacts.body_a == 0
    carried = result.report.normal_impulse[floor].sum() / (7 * G / RATE)
    print(f'drift {drift * 1e3:.3f} mm in 10 s; floor impulse / (m g dt) {carried:.9f}')
    assert drift < 0.005
    assert carried == pytest.approx(1.0, abs=1e-6)


def test_a_body_no_substep_touches_ends_at_its_input_bit_for_bit() -> None:
    """A ball flying past a resting box (2 substeps): the box is resolved, the ball is
    answered with its input, every bit; a sleeping body likewise keeps its held pose."""
    floor = BodySpec('floor', 'plane', (0.0, 0.0, 1.0, 0.0), static=True)
    bodies = [floor, box('box', (0.2,) * 3, 1.0, mu_s=0.5, mu_k=0.5),
              sphere('ball', 0.1, 1.0)]
    world = World(bodies, SETTINGS)
    previous = states([[0, 0, 0], [0, 0, 0.1], [2.0, 0.0, 1.0]],
                      [[0, 0, 0], [0, 0, 0], [0.7, -0.3, 1.1]],
                      angular=[[0, 0, 0], [0, 0, 0], [3.0, -1.0, 0.5]])
    dt = 1.0 / RATE
    current = integrate(previous, world.dynamic, dt)
    result = world.step(previous, current, dt)
    assert world.timing['substeps'] == 2
    for name in ('position', 'orientation', 'linear', 'angular'):
        np.testing.assert_array_equal(getattr(result.states, name)[2], getattr(current, name)[2])
    assert result.states.position[1, 2] == pytest.approx(0.1, abs=1e-4)   # held by the floor
