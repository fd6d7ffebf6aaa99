"""Compound bodies as parameters: `body.<n>.shapes` names the pieces, each described by
`body.<n>.piece.<p>.*`, the same in a params file and as flat ROS parameters; every error
is one line naming the parameter."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from collres_ros.core.shapes import inertia_tensor
from collres_ros.core.types import COMPOUND, Piece
from collres_ros.ros import params

S = math.sin(math.pi / 4)
DUMBBELL = """/**:
  ros__parameters:
    bodies: [floor, dumbbell]
    body:
      floor: {shape: box, size: [2.0, 2.0, 0.2], static: true, position: [0.0, 0.0, -0.1]}
      dumbbell:
        shapes: [left, bar, right]
        mass: 2.0
        position: [0.0, 0.0, 0.1]
        piece:
          left: {shape: sphere, size: [0.1], position: [-0.3, 0.0, 0.0]}
          bar: {shape: cylinder, size: [0.02, 0.6], orientation: [0.0, %r, 0.0, %r]}
          right: {shape: sphere, size: [0.1], position: [0.3, 0.0, 0.0]}
""" % (S, S)

FLAT = {'bodies': ['floor', 'dumbbell'], 'body.floor.shape': 'box',
        'body.floor.size': [2.0, 2.0, 0.2], 'body.floor.static': True,
        'body.floor.position': [0.0, 0.0, -0.1],
        'body.dumbbell.shapes': ['left', 'bar', 'right'], 'body.dumbbell.mass': 2.0,
        'body.dumbbell.position': [0.0, 0.0, 0.1],
        'body.dumbbell.piece.left.shape': 'sphere', 'body.dumbbell.piece.left.size': [0.1],
        'body.dumbbell.piece.left.position': [-0.3, 0.0, 0.0],
        'body.dumbbell.piece.bar.shape': 'cylinder',
        'body.dumbbell.piece.bar.size': [0.02, 0.6],
        'body.dumbbell.piece.bar.orientation': [0.0, S, 0.0, S],
        'body.dumbbell.piece.right.shape': 'sphere', 'body.dumbbell.piece.right.size': [0.1],
        'body.dumbbell.piece.right.position': [0.3, 0.0, 0.0]}


def test_a_params_file_and_flat_ros_parameters_give_the_same_compound(tmp_path: Path) -> None:
    path = tmp_path / 'dumbbell.yaml'
    path.write_text(DUMBBELL)
    from_file = params.load_scene(path)
    body = from_file.bodies[1]
    assert body.shape == COMPOUND
    bar = body.pieces[1]
    assert bar.orientation == pytest.approx((0.0, S, 0.0, S), abs=1e-15)
    assert body.pieces == (
        Piece('left', 'sphere', (0.1,), (), (-0.3, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0)),
        Piece('bar', 'cylinder', (0.02, 0.6), (), (0.0, 0.0, 0.0), bar.orientation),
        Piece('right', 'sphere', (0.1,), (), (0.3, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0)))
    assert params.scene_from_values(FLAT).bodies == from_file.bodies
    assert from_file.pieces == {'dumbbell': ['left', 'bar', 'right']}
    declared = {s.name for s in params.node_specs(from_file.names, from_file.pieces)}
    assert 'body.dumbbell.piece.bar.orientation' in declared
    # symmetric about its centre: principal axes along the bar and across it
    inertia = inertia_tensor(body)
    np.testing.assert_allclose(inertia - np.diag(np.diag(inertia)), 0.0, atol=1e-15)
    assert inertia[1, 1] == pytest.approx(inertia[2, 2]) and inertia[0, 0] < inertia[1, 1]
    # the recorder's text gives the same bodies, with no file to read
    again = params.load_recorded_scene(params.scene_to_yaml(from_file), 'bag')
    assert again.bodies == from_file.bodies


def test_a_convex_piece_from_a_mesh_is_inlined_when_recorded(tmp_path: Path) -> None:
    (tmp_path / 'tetra.obj').write_text('v 0 0 0\nv 0.1 0 0\nv 0 0.1 0\nv 0 0 0.1\n')
    values = {'bodies': ['thing'], 'body.thing.static': True, 'body.thing.shapes': ['tip'],
              'body.thing.piece.tip.shape': 'convex', 'body.thing.piece.tip.mesh': 'tetra.obj'}
    scene = params.scene_from_values(values, tmp_path)
    assert len(scene.bodies[0].pieces[0].points) == 4
    again = params.load_recorded_scene(params.scene_to_yaml(scene), 'bag')
    assert again.bodies == scene.bodies


@pytest.mark.parametrize('change, message', [
    ({'body.dumbbell.piece.stray.shape': 'box'},
     r"^body\.dumbbell\.piece\.stray\.shape: piece 'stray' is not in body\.dumbbell\.shapes"),
    ({'body.dumbbell.shape': 'box'},
     r'^body\.dumbbell\.shape: a compound body \(body\.dumbbell\.shapes\) takes its shape'),
    ({'body.dumbbell.shapes': ['left', 'left']}, r'^body\.dumbbell\.shapes: duplicate piece'),
    ({'body.dumbbell.shapes': ['left', 'no-dash']},
     r"^body\.dumbbell\.shapes: piece name 'no-dash' must match"),
    ({'body.dumbbell.piece.bar.size': [0.02]},
     r'^body\.dumbbell\.piece\.bar\.size: needs 2 values \[r, length\]'),
    ({'body.dumbbell.piece.bar.shape': 'plane'},
     r'^body\.dumbbell\.piece\.bar\.shape: allowed values sphere, box'),
    ({'body.dumbbell.piece.bar.orientation': [0.0, 0.0, 0.0, 0.0]},
     r'^body\.dumbbell\.piece\.bar\.orientation: quaternion must be non-zero'),
    ({'body.dumbbell.piece.right.position': [0.5, 0.0, 0.0]},
     r'^body\.dumbbell\.shapes: the pieces\' centre of mass \(0\.0\d+, 0, 0\) m must be the '
     r'body origin'),
])
def test_a_bad_compound_names_the_parameter(change, message) -> None:
    with pytest.raises(ValueError, match=message):
        params.scene_from_values({**FLAT, **change})


def test_a_static_compound_may_be_off_centre_and_piece_parameters_are_read_only() -> None:
    scene = params.scene_from_values({**FLAT, 'body.dumbbell.static': True,
                                      'body.dumbbell.piece.right.position': [0.5, 0.0, 0.0]})
    assert scene.bodies[1].pieces[2].position == (0.5, 0.0, 0.0)
    with pytest.raises(ValueError, match=r'^body\.dumbbell\.piece\.bar\.size: read-only'):
        params.with_changes(scene, {'body.dumbbell.piece.bar.size': [0.03, 0.6]})
