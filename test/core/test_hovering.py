"""Nothing hovers: a body that comes to rest on the floor rests on points that touch it.

Boxes dropped 5 cm onto a corner or an edge at several angles and rates (gravity
integrator, test/core/integrator.py), then left for 3 s: the box is at rest on one of
its faces, its four lowest corners (its support points) within the slop of the floor.
The manifold's points are each body's own surface points (a contact patch gathers points
within 1 cm of its plane; a tilted plate's far corners were given the patch's one depth,
and the plate came to rest on them up to 4.6 mm in the air).
"""

from __future__ import annotations

import numpy as np
import pytest

from collres_ros.core.rotation import to_matrix
from collres_ros.core.types import BodySpec

from contacts import box, states  # noqa: I100
from integrator import Simulation

SLOP = 1e-4   # m, solver.linear_slop


def corners(size) -> np.ndarray:
    half = np.asarray(size, float) / 2
    return np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)]) * half


def drop(size, axis, angle_deg: float, rate: float, mu: float,
         e: float = 0.0) -> tuple[np.ndarray, float]:
    """Heights of the four lowest corners (m) and the fastest corner's speed (m/s) of the
    box (restitution e) 3 s after the drop."""
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    half_angle = np.radians(angle_deg) / 2
    q = np.r_[axis * np.sin(half_angle), np.cos(half_angle)]
    local = corners(size)
    lowest = (local @ to_matrix(q).T)[:, 2].min()
    floor = BodySpec('floor', 'plane', (0.0, 0.0, 1.0, 0.0), static=True,
                     static_friction=mu, kinetic_friction=0.3)
    sim = Simulation([floor, box('box', size, 1.0, e=e, mu_s=mu, mu_k=0.3)],
                     states([[0, 0, 0], [0, 0, 0.05 - lowest]], np.zeros((2, 3)),
                            orientation=[[0, 0, 0, 1], q]), rate)
    sim.run(3.0)
    points = local @ to_matrix(sim.state.orientation[1]).T
    speed = np.linalg.norm(sim.state.linear[1] + np.cross(sim.state.angular[1], points),
                           axis=1).max()
    return np.sort(points[:, 2] + sim.state.position[1, 2])[:4], float(speed)


@pytest.mark.parametrize('size, axis, angle, rate, mu', [
    ((1.0, 1.0, 0.1), (1, 1, 0), 42, 240.0, 0.5),     # rested 4.6 mm up on stale points
    ((1.0, 1.0, 0.1), (1, 1, 0), 70, 240.0, 1.2),     # 0.59 mm
    ((1.0, 1.0, 0.1), (1, 1, 0), 35, 120.0, 0.5),     # 4.3 mm
    ((1.0, 1.0, 0.1), (0.3, 1, 0.2), 49, 120.0, 0.5),  # 4.4 mm
    ((0.2, 0.2, 0.2), (1, 0, 0), 40, 240.0, 0.5),     # an edge
    ((0.2, 0.2, 0.2), (1, 1, 1), 50, 60.0, 0.5),      # a corner
    ((0.4, 0.1, 0.05), (1, 0.3, 0), 30, 120.0, 1.2),  # a bar
    # small boxes: their far face lay within the patch's 1 cm of the floor and one of its
    # points was kept for a touching corner (49bb690: rested 1.2 deg tilted, a corner
    # 0.14 mm deep, one 0.08 mm up; the plate 0.16 mm deep)
    ((0.01, 0.01, 0.01), (1, 0, 0), 40, 100.0, 0.5),
    ((0.02, 0.02, 0.002), (1, 0, 0), 40, 1000.0, 0.5),
])
def test_a_box_dropped_on_an_edge_or_corner_rests_on_the_floor(size, axis, angle, rate, mu):
    support, speed = drop(size, axis, angle, rate, mu)
    print(f'{size} about {axis} at {angle} deg, {rate:.0f} Hz: four lowest corners '
          f'{np.round(support * 1000, 4)} mm, fastest corner {speed:.2e} m/s')
    assert speed < 1e-3, 'not at rest'
    assert np.all(np.abs(support) <= SLOP + 1e-6)


@pytest.mark.parametrize('rate', [30.0, 60.0, 120.0, 240.0])
@pytest.mark.parametrize('size, axis, angle', [((0.2, 0.2, 0.2), (1, 0, 0), 40),
                                               ((0.05, 0.05, 0.05), (1, 0, 0), 30),
                                               ((1.0, 1.0, 0.1), (1, 1, 0), 42)])
def test_a_box_of_default_material_dropped_on_an_edge_rests_on_the_floor(
        size, axis, angle, rate):
    """The law in a user's words: a box of the default material (e 0.5, friction 0.5 /
    0.3) dropped on its edge at 30 to 240 Hz bounces and comes to rest with its lowest
    corners within the slop of the floor."""
    support, speed = drop(size, axis, angle, rate, 0.5, e=0.5)
    print(f'{size} about {axis} at {angle} deg, {rate:.0f} Hz: four lowest corners '
          f'{np.round(support * 1000, 4)} mm, fastest corner {speed:.2e} m/s')
    assert speed < 1e-3, 'not at rest'
    assert np.all(np.abs(support) <= SLOP + 1e-6)
