"""Compound bodies through detection and the solver: laws a compound must obey.

* A table (a top on two legs) resting on a floor carries its weight, m g dt per step,
  on both legs, and does not turn or sink.
* A dumbbell (two spheres on a bar) set sliding without spin rolls off at
  v0 / (1 + I / (m r^2)), I its moment about the bar from the pieces.
* A box dropped into a bin built of static pieces rests on the bin's floor, between
  its walls, without sinking.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from collres_ros.core.config import SolverSettings
from collres_ros.core.detection import Detection
from collres_ros.core.shapes import centre_of_mass, inertia_tensor
from collres_ros.core.types import COMPOUND, BodySpec, BodyStates, Piece
from integrator import Simulation

FLOOR = BodySpec('floor', 'box', (4.0, 4.0, 0.2), static=True)
RATE = 240.0
G = 9.81


def centred(name: str, pieces: list[Piece], **values) -> tuple[BodySpec, np.ndarray]:
    """A compound whose pieces are shifted so that their centre of mass is the origin, and
    the shift (where the pieces' frame origin now sits in the body frame)."""
    body = BodySpec(name, COMPOUND, static=True, pieces=tuple(pieces))
    centre = centre_of_mass(body)
    moved = tuple(Piece(p.name, p.shape, p.size, p.points,
                        tuple(np.asarray(p.position) - centre), p.orientation) for p in pieces)
    return BodySpec(name, COMPOUND, pieces=moved, **values), -centre


def states(*rows: tuple) -> BodyStates:
    """States from (position, linear, angular) rows, identity orientations."""
    out = BodyStates.zeros(len(rows))
    for k, (position, linear, angular) in enumerate(rows):
        out.position[k], out.linear[k], out.angular[k] = position, linear, angular
    return out


def table() -> tuple[BodySpec, np.ndarray]:
    """A top 0.4 x 0.1 x 0.05 m on two legs 0.05 x 0.1 x 0.2 m at its ends (feet at z = 0 of
    the pieces' frame)."""
    return centred('table', [
        Piece('top', 'box', (0.4, 0.1, 0.05), position=(0.0, 0.0, 0.225)),
        Piece('left', 'box', (0.05, 0.1, 0.2), position=(-0.175, 0.0, 0.1)),
        Piece('right', 'box', (0.05, 0.1, 0.2), position=(0.175, 0.0, 0.1))], mass=2.0)


def test_detection_names_the_pieces_and_caps_a_pair_of_bodies() -> None:
    body, feet = table()
    start = states(((0, 0, -0.1), (0, 0, 0), (0, 0, 0)),
                   (-feet + (0, 0, -0.001), (0, 0, 0), (0, 0, 0)))   # 1 mm into the floor
    for cap, expected in ((8, 8), (3, 3)):
        detection = Detection([FLOOR, body], SolverSettings(max_contacts_per_pair=cap))
        rows = detection.detect(start, start)
        piece_a, piece_b = rows.pieces()
        assert rows.count == expected
        assert set(piece_a.tolist()) == {0} and set(piece_b.tolist()) <= {1, 2}
        if cap == 8:   # both feet, four corners each, with distinct feature ids
            assert sorted(piece_b.tolist()) == [1] * 4 + [2] * 4
            assert len(set(rows.feature.tolist())) == 8
        np.testing.assert_allclose(rows.separation, -0.001, atol=1e-8)


def test_a_table_rests_on_both_legs_with_its_weight() -> None:
    body, feet = table()
    sim = Simulation([FLOOR, body], states(((0, 0, -0.1), (0, 0, 0), (0, 0, 0)),
                                           (-feet, (0, 0, 0), (0, 0, 0))), RATE)
    m, dt = 2.0, 1.0 / RATE
    weights, legs = [], set()
    for step in range(240):
        result = sim.step()
        contacts = result.report.contacts
        if step >= 120:
            weights.append(result.report.normal_impulse.sum())
            legs |= set(contacts.pieces()[1][result.report.normal_impulse > 0].tolist())
    assert legs == {1, 2}
    assert np.mean(weights) == pytest.approx(m * G * dt, rel=1e-3)
    assert abs(sim.state.position[1, 2] + feet[2]) < 1e-3      # no sinking (< 1 mm)
    assert np.abs(sim.state.angular[1]).max() < 1e-3          # no turning
    assert np.abs(sim.state.position[1, :2]).max() < 1e-4     # nor sliding


def test_a_sliding_dumbbell_rolls_off_at_the_speed_its_inertia_gives() -> None:
    """Friction stops the slip: m (v0 - v) r = I w and v = w r give v = v0 / (1 + I/(m r^2))
    (I about the bar, from the pieces; no rolling resistance)."""
    r, a, d, m, v0 = 0.1, 0.02, 0.3, 2.0, 1.0
    turn = (0.0, math.sin(math.pi / 4), 0.0, math.cos(math.pi / 4))   # cylinder along x
    body = BodySpec('dumbbell', COMPOUND, mass=m, static_friction=0.6, kinetic_friction=0.5,
                    rolling_resistance=0.0, torsional_friction=0.0, pieces=(
                        Piece('left', 'sphere', (r,), position=(-d, 0.0, 0.0)),
                        Piece('bar', 'cylinder', (a, 2 * d), orientation=turn),
                        Piece('right', 'sphere', (r,), position=(d, 0.0, 0.0))))
    floor = BodySpec('floor', 'box', (4.0, 4.0, 0.2), static=True, static_friction=0.6,
                     kinetic_friction=0.5, rolling_resistance=0.0, torsional_friction=0.0)
    inertia = inertia_tensor(body)[0, 0]
    expected = v0 / (1.0 + inertia / (m * r * r))
    sim = Simulation([floor, body], states(((0, 0, -0.1), (0, 0, 0), (0, 0, 0)),
                                           ((0, 0, r), (0, v0, 0), (0, 0, 0))), RATE)
    for _ in range(240):   # the slip ends within 0.1 s (v0 / (mu g (1 + m r^2 / I)))
        sim.step()
    v, w = sim.state.linear[1], sim.state.angular[1]
    assert v[1] == pytest.approx(expected, rel=0.01)
    assert -w[0] * r == pytest.approx(v[1], rel=0.01)          # rolling: no slip left
    assert abs(sim.state.position[1, 2] - r) < 1e-3


def bin_of_pieces(wall: float = 0.02) -> BodySpec:
    """A static bin 0.4 m square inside: a floor ``wall`` thick with its top at z = 0 and
    four walls 0.2 m tall, five box pieces."""
    return BodySpec('bin', COMPOUND, static=True, pieces=(
        Piece('floor', 'box', (0.44, 0.44, wall), position=(0.0, 0.0, -wall / 2)),
        Piece('east', 'box', (wall, 0.44, 0.2), position=(0.21, 0.0, 0.1)),
        Piece('west', 'box', (wall, 0.44, 0.2), position=(-0.21, 0.0, 0.1)),
        Piece('north', 'box', (0.4, wall, 0.2), position=(0.0, 0.21, 0.1)),
        Piece('south', 'box', (0.4, wall, 0.2), position=(0.0, -0.21, 0.1))))


def test_a_box_rests_inside_a_bin_of_static_pieces() -> None:
    """A 0.1 m cube dropped into the bin from 0.1 m rests on the bin's floor."""
    cube = BodySpec('cube', 'box', (0.1, 0.1, 0.1), mass=1.0)
    start = states(((0, 0, 0), (0, 0, 0), (0, 0, 0)),
                   ((0.05, 0.0, 0.15), (0.3, 0.0, 0.0), (0, 0, 0)))
    sim = Simulation([bin_of_pieces(), cube], start, RATE)
    for _ in range(480):
        result = sim.step()
    position = sim.state.position[1]
    assert abs(position[2] - 0.05) < 1e-3                  # on the bin's floor, not in it
    assert abs(position[0]) <= 0.15 + 1e-3                 # between the walls
    assert np.linalg.norm(sim.state.linear[1]) < 1e-2
    assert result.report.normal_impulse.sum() == pytest.approx(G / RATE, rel=0.02)
