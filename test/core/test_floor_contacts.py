"""A box overlapping a floor plane is held at each of its corners in it, wherever it stands.

At 30 Hz a source integrates a resting box one period under gravity (10.9 mm down) before
each step, so a box whose lowest corner is 1.6 mm into the floor is more than a quarter of
its half extent deep at the step's end: detection then carries the contact of the previous
state (``deep_persistent``, taken where coal's depth at the step's end exceeds that; for
the tilted cube below at (-0.061, -0.065) it does, at the other places not), one point
per corner of the box that lies in the floor. Those corners were kept only where they lay
over the plane's "box", which a plane does not have (zero size at its origin): a box more
than the speculative margin from the plane's origin kept one corner or none. Held at one
corner, the box sank at the others by the slop each step (the hold-back's allowance): a
pile of 100 cubes dropped at 30 Hz rested 5.3 mm in its floor (3540a22,
bench/bench_rest.py, 4 s; 0.10 mm now).
"""

from __future__ import annotations

import numpy as np
import pytest

from collres_ros.core.config import SolverSettings
from collres_ros.core.detection import Detection
from collres_ros.core.rotation import to_matrix
from collres_ros.core.types import BodySpec, BodyStates

from contacts import box  # noqa: I100
from integrator import Simulation

SIZE = 0.1                      # m, cube edge
RATE = 30.0                     # Hz
FALL = 9.81 / RATE ** 2         # m, a period's fall from rest under gravity (v = g dt)
SLOP = SolverSettings().linear_slop
# tilted 1.4 deg about an axis in the floor, turned 6.6 deg about the vertical
TILT = np.array([7.2449e-04, -1.230631e-02, 5.796440e-02, 9.982425e-01])
TILT /= np.linalg.norm(TILT)


def floor() -> BodySpec:
    return BodySpec('floor', 'plane', (0.0, 0.0, 1.0, 0.0), static=True,
                    static_friction=0.6, kinetic_friction=0.4)


def cube() -> BodySpec:
    return box('cube', (SIZE,) * 3, 1.0, e=0.2, mu_s=0.6, mu_k=0.4)


def corner_heights(position: np.ndarray, orientation: np.ndarray = TILT) -> np.ndarray:
    """(8,) m, the heights of the cube's corners above the floor."""
    signs = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float)
    return position[2] + (signs * SIZE / 2) @ to_matrix(orientation)[2]


def resting(x: float, y: float, deepest: float) -> BodyStates:
    """The tilted cube at (x, y) with its lowest corner ``deepest`` m into the floor."""
    state = BodyStates.zeros(2)
    state.orientation[:] = [0.0, 0.0, 0.0, 1.0]
    state.orientation[1] = TILT
    state.position[1] = [x, y, 0.0]
    state.position[1, 2] = -deepest - corner_heights(state.position[1]).min()
    return state


@pytest.mark.parametrize('x, y', [(0.0, 0.0), (-0.061, -0.065), (2.0, -1.5)])
def test_a_box_deep_in_a_floor_at_the_steps_end_has_a_contact_at_each_corner_in_it(
        x: float, y: float) -> None:
    previous = resting(x, y, 3.17e-3)
    current = previous.copy()
    current.position[1, 2] -= FALL
    current.linear[1, 2] = -9.81 / RATE
    detection = Detection([floor(), cube()], SolverSettings(sleeping=False))
    seen = detection.detect(previous, current)
    heights = np.sort(corner_heights(current.position[1]))[:4]   # the four in the floor
    print(f'({x}, {y}): {seen.count} contacts, separations {np.round(seen.separation * 1e3, 2)}'
          f' mm; corners {np.round(heights * 1e3, 2)} mm')
    assert seen.count == 4
    assert np.allclose(np.sort(seen.separation), heights, atol=1e-6)


@pytest.mark.parametrize('x, y', [(-0.061, -0.065), (2.0, -1.5)])
def test_a_tilted_box_in_a_floor_is_pushed_out_at_30_hz(x: float, y: float) -> None:
    """Released at rest 3.17 mm deep at one corner: within 2 s the push-out lifts it to
    the slop (+ 0.1 mm) wherever it stands. On 3540a22 the first place (where detection
    took the deep path, with one corner) ended 9.16 mm in the floor."""
    sim = Simulation([floor(), cube()], resting(x, y, 3.17e-3), RATE,
                     SolverSettings(sleeping=False))
    for _ in range(int(2.0 * RATE)):
        sim.step()
    deepest = -corner_heights(sim.state.position[1], sim.state.orientation[1]).min()
    print(f'deepest corner {deepest * 1e3:.3f} mm into the floor after 2 s')
    assert deepest < SLOP + 1e-4
