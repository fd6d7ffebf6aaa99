"""A static triangle mesh (``shape: triangle_mesh``) is scenery that stays concave:

* a ball released inside a bowl rolls inside it and settles at its lowest point; on the
  bowl's convex hull it rests on top, at the rim;
* a box dropped into a bin rests on its floor of 32 triangles without sinking, on one
  manifold of four rows along the floor's normal, and slides across the edges between the
  floor's triangles decelerating at mu_k g without catching on them;
* the decomposed (dynamic) U channel dropped into the bin rests on its floor;
* contacts take the triangle's face normal (the side a shape pressed through a triangle is
  pushed back to is its front), except at an active edge (the mesh's boundary), over which
  a ball rolls on the edge's normal.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from integrator import Simulation
from test_decomposed_laws import UNDERSIDE, channel, hulls  # noqa: F401 (hulls: a fixture)

from collres_ros.core.config import SolverSettings
from collres_ros.core.detection import Detection
from collres_ros.core.rotation import to_matrix
from collres_ros.core.shapes import hull_vertices, mesh_surface
from collres_ros.core.types import TRIANGLE_MESH, BodySpec, BodyStates

MESHES = Path(__file__).resolve().parents[1] / 'data' / 'meshes'
BOWL_RIM = 0.08930309758   # m, z of the bowl's rim (bowl.obj's header); its bottom at 0
RIM_RADIUS = 0.191511      # m
RATE = 240.0
G = 9.81
SLOP = SolverSettings().linear_slop


def mesh(name: str) -> BodySpec:
    path = MESHES / f'{name}.obj'
    corners = mesh_surface(path.read_bytes(), path.suffix, str(path))
    return BodySpec(name, TRIANGLE_MESH, static=True,
                    points=tuple(map(tuple, corners.reshape(-1, 3))))


def start(*positions, linear=None) -> BodyStates:
    out = BodyStates.zeros(len(positions))
    out.position[:] = positions
    if linear is not None:
        out.linear[:] = linear
    return out


def test_a_ball_released_in_a_bowl_settles_at_its_bottom_where_the_hull_holds_it_on_top() -> None:
    r = 0.03
    ball = BodySpec('ball', 'sphere', (r,), mass=0.1, restitution=0.2, rolling_resistance=0.05)
    released = start((0, 0, 0), (0.1, 0.05, BOWL_RIM + r + 1e-3))
    sim = Simulation([mesh('bowl'), ball], released, RATE)
    reach = 0.0
    for _ in range(int(6.0 * RATE)):
        sim.step()
        reach = max(reach, float(np.linalg.norm(sim.state.position[1, :2])))
    assert reach < RIM_RADIUS - r                                    # it rolled inside it
    assert np.linalg.norm(sim.state.position[1, :2]) < 2e-3          # at the bottom ...
    assert sim.state.position[1, 2] == pytest.approx(r, abs=1e-3)    # ... on it, not in it
    assert np.linalg.norm(sim.state.linear[1]) < 1e-2
    bowl = mesh('bowl')
    hull = BodySpec('bowl', 'convex', static=True,
                    points=tuple(map(tuple, hull_vertices(np.asarray(bowl.points)))))
    sim = Simulation([hull, ball], released, RATE)
    for _ in range(int(1.0 * RATE)):
        sim.step()
    assert sim.state.position[1, 2] == pytest.approx(BOWL_RIM + r, abs=2e-3)   # on the top


def test_a_box_rests_on_a_floor_of_triangles_without_sinking() -> None:
    m = 1.0
    box = BodySpec('box', 'box', (0.1, 0.1, 0.1), mass=m)
    sim = Simulation([mesh('bin'), box], start((0, 0, 0), (0.03, 0.02, 0.1)), RATE)
    lowest = np.inf
    for _ in range(int(2.0 * RATE)):
        result = sim.step()
        lowest = min(lowest, sim.state.position[1, 2])
    assert lowest > 0.05 - SLOP                                      # never sank in
    assert sim.state.position[1] == pytest.approx((0.03, 0.02, 0.05), abs=SLOP)
    contacts = result.report.contacts
    assert contacts.count == 4 and len(contacts.manifolds) == 1      # one face, four rows
    assert np.abs(contacts.normal - (0.0, 0.0, 1.0)).max() < 1e-9   # the floor's normal
    assert result.report.normal_impulse.sum() == pytest.approx(m * G / RATE, rel=1e-3)


def test_a_box_slides_across_the_edges_between_triangles_without_catching() -> None:
    """Set sliding at 0.6 m/s along the floor's diagonal (over the triangles' shared edges),
    it stops after v^2 / (2 mu_k g) and stays level."""
    mu, v = 0.3, 0.6
    box = BodySpec('box', 'box', (0.1, 0.1, 0.1), mass=1.0, static_friction=mu,
                   kinetic_friction=mu)
    direction = np.array([1.0, 1.0, 0.0]) / np.sqrt(2.0)
    sliding = start((0, 0, 0), (-0.1, -0.1, 0.05), linear=((0, 0, 0), v * direction))
    sim = Simulation([mesh('bin'), box], sliding, RATE)
    tilt = 0.0
    for _ in range(int(1.0 * RATE)):
        sim.step()
        up = to_matrix(sim.state.orientation[1])[2, 2]   # cosine of the box's tilt
        tilt = max(tilt, float(np.arccos(np.clip(up, -1.0, 1.0))))
    travelled = (sim.state.position[1] - (-0.1, -0.1, 0.05)) @ direction
    assert travelled == pytest.approx(v * v / (2.0 * mu * G), rel=0.03)
    assert tilt < 1e-3
    assert abs(sim.state.position[1, 2] - 0.05) < SLOP
    assert np.linalg.norm(sim.state.linear[1]) < 1e-3


def test_the_decomposed_channel_rests_in_a_triangle_mesh_bin(hulls) -> None:  # noqa: F811
    sim = Simulation([mesh('bin'), channel(hulls, False)],
                     start((0, 0, 0), (0.05, 0.0, -UNDERSIDE + 0.05)), RATE)
    for _ in range(int(2.0 * RATE)):
        result = sim.step()
    assert sim.state.position[1, 2] == pytest.approx(-UNDERSIDE, abs=1.5e-3)   # on the floor
    assert np.linalg.norm(sim.state.linear[1]) < 1e-2
    assert result.report.normal_impulse.sum() == pytest.approx(0.5 * G / RATE, rel=0.02)


def test_contacts_take_the_face_normal_except_at_an_active_edge() -> None:
    r = 0.05
    ball = BodySpec('ball', 'sphere', (r,), mass=1.0)
    detection = Detection([mesh('bin'), ball], SolverSettings())

    def contact(position) -> tuple[np.ndarray, float]:
        detection.reset()
        now = start((0, 0, 0), position)
        found = detection.detect(now, now)
        deepest = int(np.argmin(found.separation))
        return found.normal[deepest], float(found.separation[deepest])

    # pressed through the floor (centre 2 cm below it): pushed back up to the front
    normal, separation = contact((0.05, 0.03, -0.02))
    assert normal == pytest.approx((0.0, 0.0, 1.0), abs=1e-9)
    assert separation == pytest.approx(-(r + 0.02), abs=1e-9)
    # over the east wall's free top edge (x = 0.2, z = 0.2), from inside: its edge's normal
    # (from the edge to the centre), not the wall's (-1, 0, 0)
    normal, separation = contact((0.17, 0.01, 0.23))
    assert normal == pytest.approx(np.array([-1.0, 0.0, 1.0]) / np.sqrt(2.0), abs=1e-6)
    assert separation == pytest.approx(0.03 * np.sqrt(2.0) - r, abs=1e-6)
