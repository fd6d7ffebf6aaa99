"""A concave mesh decomposed by CoACD behaves as the concave solid its hull is not:

* a ball dropped into the notch of a (static) U channel settles on the notch's floor and
  rolls inside it between the walls; on the channel's convex hull it rests on top;
* the (dynamic) decomposed channel dropped into a bin built of static pieces rests on the
  bin's floor without sinking.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest
from integrator import Simulation
from test_compound_laws import bin_of_pieces

from collres_ros.core import decomposition
from collres_ros.core.shapes import load_mesh_points
from collres_ros.core.types import COMPOUND, BodySpec, BodyStates, Piece

MESH = Path(__file__).resolve().parents[1] / 'data' / 'meshes' / 'u_channel.obj'
UNDERSIDE = -0.0355882353       # z of the channel's underside in its frame (file header)
NOTCH_FLOOR = UNDERSIDE + 0.03  # z of the notch's floor
TOP = UNDERSIDE + 0.1           # z of the walls' tops
RATE = 240.0


@pytest.fixture(scope='module')
def hulls(tmp_path_factory) -> list[np.ndarray]:
    copy = tmp_path_factory.mktemp('mesh') / MESH.name
    shutil.copy(MESH, copy)
    return decomposition.hulls(copy, copy.read_bytes(), log=lambda line: None)


def channel(hulls: list[np.ndarray], static: bool) -> BodySpec:
    return BodySpec('channel', COMPOUND, static=static, mass=0.5, pieces=tuple(
        Piece(f'hull_{k}', 'convex', points=tuple(map(tuple, h))) for k, h in enumerate(hulls)))


def start(*positions, linear=((0, 0, 0),) * 2) -> BodyStates:
    out = BodyStates.zeros(len(positions))
    out.position[:] = positions
    out.linear[:] = linear
    return out


def test_a_ball_rolls_inside_the_notch_the_hull_fills(hulls) -> None:
    """Set rolling at 0.2 m/s on the notch's floor, the ball rolls along it (on it, no slip)
    and stays between the walls; dropped onto the channel's convex hull it rests on top."""
    r, v = 0.015, 0.2
    ball = BodySpec('ball', 'sphere', (r,), mass=0.1, restitution=0.2)
    rolling = start((0, 0, 0), (-0.04, 0.0, NOTCH_FLOOR + r), linear=((0, 0, 0), (v, 0, 0)))
    rolling.angular[1] = (0.0, v / r, 0.0)
    sim = Simulation([channel(hulls, True), ball], rolling, RATE)
    heights, xs = [], []
    for _ in range(int(1.5 * RATE)):
        sim.step()
        heights.append(sim.state.position[1, 2])
        xs.append(sim.state.position[1, 0])
    heights, xs = np.array(heights), np.array(xs)
    early = int(0.15 * RATE)   # before it reaches the far wall
    assert xs[early] - xs[0] == pytest.approx(v * (early / RATE), rel=0.05)   # rolling on
    assert np.abs(heights - (NOTCH_FLOOR + r)).max() < 2e-3       # on the notch's floor
    assert np.abs(xs).max() < 0.07 - r + 2e-3                     # between the walls
    hull = BodySpec('channel', 'convex', static=True,
                    points=tuple(map(tuple, load_mesh_points(str(MESH)))))
    sim = Simulation([hull, ball], start((0, 0, 0), (0.0, 0.0, TOP + 0.05)), RATE)
    for _ in range(int(1.0 * RATE)):
        sim.step()
    assert sim.state.position[1, 2] == pytest.approx(TOP + r, abs=2e-3)   # on the hull's top


def test_the_decomposed_channel_rests_in_a_bin_of_static_pieces(hulls) -> None:
    sim = Simulation([bin_of_pieces(), channel(hulls, False)],
                     start((0, 0, 0), (0.05, 0.0, -UNDERSIDE + 0.05)), RATE)
    for _ in range(int(2.0 * RATE)):
        result = sim.step()
    position = sim.state.position[1]
    assert position[2] == pytest.approx(-UNDERSIDE, abs=1.5e-3)   # on the floor, not in it
    assert np.linalg.norm(sim.state.linear[1]) < 1e-2
    assert result.report.normal_impulse.sum() == pytest.approx(0.5 * 9.81 / RATE, rel=0.02)
