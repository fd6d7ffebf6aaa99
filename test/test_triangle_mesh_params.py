"""A triangle mesh as parameters: `body.<n>.shape: triangle_mesh` with a mesh file (its
triangles that have an area) or `points` (nine values a triangle, as a recorded scene
carries them); static only; every error is one line naming the parameter; contacts name
its triangles."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from collres_ros.core.shapes import piece_names
from collres_ros.core.types import TRIANGLE_MESH
from collres_ros.ros import params

BIN = Path(__file__).resolve().parent / 'data' / 'meshes' / 'bin.obj'


def values(**body) -> dict:
    return {'bodies': ['bin'], 'body.bin.shape': 'triangle_mesh', 'body.bin.static': True,
            **{f'body.bin.{k}': v for k, v in body.items()}}


def test_a_mesh_file_gives_its_triangles_and_a_recorded_scene_carries_them(
        tmp_path: Path) -> None:
    shutil.copy(BIN, tmp_path / 'bin.obj')
    scene = params.scene_from_values(values(mesh='bin.obj'), tmp_path)
    body = scene.bodies[0]
    assert body.shape == TRIANGLE_MESH
    corners = np.asarray(body.points).reshape(-1, 3, 3)
    assert len(corners) == 40                          # 32 floor triangles and 8 of walls
    normals = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    assert (normals[:32, 2] > 0).all()                 # the floor faces up (its front)
    assert piece_names(body)[:2] == ['triangle_0', 'triangle_1']
    again = params.load_recorded_scene(params.scene_to_yaml(scene), 'bag')
    assert again.bodies == scene.bodies


def test_a_sliver_in_a_mesh_file_is_left_out(tmp_path: Path) -> None:
    (tmp_path / 'two.obj').write_text('v 0 0 0\nv 1 0 0\nv 0 1 0\nv 2 0 0\nf 1 2 3\nf 1 2 4\n')
    scene = params.scene_from_values(values(mesh='two.obj'), tmp_path)
    assert len(scene.bodies[0].points) == 3


@pytest.mark.parametrize('body, message', [
    ({'mesh': 'bin.obj', 'static': False},
     r'^body\.bin\.static: a triangle_mesh must be static'),
    ({'points': [0.0, 0.0, 0.0, 1.0, 0.0, 0.0]},
     r'^body\.bin\.points: a triangle_mesh needs a mesh, or points: nine values'),
    ({'points': [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 2.0, 0.0, 0.0]},
     r'^body\.bin\.points: triangle 0: corners on one line'),
    ({'mesh': 'missing.obj'}, r'^body\.bin\.mesh: cannot read mesh .*missing\.obj'),
])
def test_a_bad_triangle_mesh_names_the_parameter(body, message) -> None:
    with pytest.raises(ValueError, match=message):
        params.scene_from_values(values(**body), BIN.parent)
