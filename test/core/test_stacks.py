"""Stacks that stand with the default settings at the default rate (240 Hz), and at 30
and 60 Hz.

A tower of 20 equal cubes of any size, a 1000 kg box on a 1 kg box and a pyramid of
55 cubes, started touching at rest on a floor, integrated with gravity for 10 s
(test/core/integrator.py): every body stays within a few millimetres of where it
started (the law of a rigid stack at rest: it does not move), and the stack never
gains energy. At 30 and 60 Hz the towers of 20 cubes fell with one solve per step; the
resting solve's substeps (``solver.max_substep``) hold them.
"""

from __future__ import annotations

import numpy as np
import pytest

from collres_ros.core.config import SimSettings
from collres_ros.core.types import BodySpec

from contacts import box, states  # noqa: I100
from integrator import Simulation

RATE = SimSettings().rate_hz     # the default rate (collres_sim): 240 Hz


def floor() -> BodySpec:
    return BodySpec('floor', 'plane', (0.0, 0.0, 1.0, 0.0), static=True,
                    static_friction=0.5, kinetic_friction=0.3)


def cube(name: str, size: float, mass: float = 1.0) -> BodySpec:
    return box(name, (size,) * 3, mass, mu_s=0.5, mu_k=0.3)


def stand(bodies: list[BodySpec], start: np.ndarray, duration: float = 10.0,
          rate: float = RATE) -> tuple[float, float, float]:
    """Largest displacement of any body (m), start and largest energy (J) over the run."""
    sim = Simulation(bodies, states(start, np.zeros_like(start)), rate)
    e0, highest, moved = sim.energy(), -np.inf, 0.0
    for _ in range(int(round(duration * rate))):
        sim.step()
        moved = max(moved, float(np.linalg.norm(sim.state.position[1:] - start[1:],
                                                axis=1).max()))
        highest = max(highest, sim.energy())
    return moved, e0, highest


@pytest.mark.parametrize('size', [0.05, 0.2, 1.0])
def test_tower_of_20_cubes_stands_10s(size):
    count = 20
    bodies = [floor()] + [cube(f'c{i}', size) for i in range(count)]
    start = np.array([[0.0, 0.0, 0.0]] + [[0.0, 0.0, size * (i + 0.5)] for i in range(count)])
    moved, e0, highest = stand(bodies, start)
    print(f'{count} cubes of {size} m: largest displacement {moved * 1000:.3f} mm; '
          f'energy {e0:.4f} J, highest {highest:.4f} J')
    assert moved < 0.005
    assert highest <= e0 + 1e-9 * abs(e0)


@pytest.mark.parametrize('rate', [30.0, 60.0])
@pytest.mark.parametrize('size', [0.05, 0.2])
def test_tower_of_20_cubes_stands_10s_at_low_rates(size, rate):
    count = 20
    bodies = [floor()] + [cube(f'c{i}', size) for i in range(count)]
    start = np.array([[0.0, 0.0, 0.0]] + [[0.0, 0.0, size * (i + 0.5)] for i in range(count)])
    moved, e0, highest = stand(bodies, start, rate=rate)
    print(f'{count} cubes of {size} m at {rate:g} Hz: largest displacement '
          f'{moved * 1000:.3f} mm; energy {e0:.4f} J, highest {highest:.4f} J')
    assert moved < 0.005
    assert highest <= e0 + 1e-9 * abs(e0)


@pytest.mark.parametrize('rate', [RATE, 30.0])
def test_1000_kg_box_on_1_kg_box_stands_10s(rate):
    size = 0.2
    bodies = [floor(), cube('light', size, 1.0), cube('heavy', size, 1000.0)]
    start = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, size / 2], [0.0, 0.0, 1.5 * size]])
    moved, e0, highest = stand(bodies, start, rate=rate)
    print(f'1000:1 stack at {rate:g} Hz: largest displacement {moved * 1000:.4f} mm')
    assert moved < 1e-4
    assert highest <= e0 + 1e-9 * abs(e0)


@pytest.mark.parametrize('rate', [RATE, 30.0])
def test_pyramid_of_55_cubes_stands_10s(rate):
    size, base = 0.2, 10
    bodies, start = [floor()], [[0.0, 0.0, 0.0]]
    for row in range(base):
        for j in range(base - row):
            bodies.append(cube(f'c{row}_{j}', size))
            start.append([(j - (base - row - 1) / 2) * 1.05 * size, 0.0, size * (row + 0.5)])
    moved, e0, highest = stand(bodies, np.array(start), rate=rate)
    print(f'pyramid of {len(bodies) - 1} cubes at {rate:g} Hz: largest displacement '
          f'{moved * 1000:.3f} mm')
    assert moved < 0.001
    assert highest <= e0 + 1e-9 * abs(e0)
