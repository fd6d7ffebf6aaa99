"""Convex decomposition (CoACD) of a concave mesh: hulls that keep its concavity, the cache
beside the mesh keyed by its bytes and the settings, bodies with decompose: true, and the
collres_decompose executable."""

from __future__ import annotations

import logging
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from collres_ros.core import decomposition
from collres_ros.core.shapes import convex_hull, mass_properties
from collres_ros.core.types import COMPOUND
from collres_ros.ros import params, processes

MESH = Path(__file__).resolve().parent / 'data' / 'meshes' / 'u_channel.obj'
BASE_Z = -0.0355882353                           # the channel's underside (its file's header)
NOTCH = np.array([0.0, 0.0, BASE_Z + 0.065])     # middle of the notch, between the walls
VOLUME = (0.2 * 0.03 + 2 * 0.03 * 0.07) * 0.1    # m^3


def inside(points: np.ndarray, point: np.ndarray, margin: float = 1e-9) -> bool:
    """Whether ``point`` lies in the convex hull of ``points`` (every face's plane)."""
    hull = convex_hull(points)
    vertices = np.asarray(hull.points(), float).reshape(-1, 3)
    centre = vertices.mean(axis=0)
    for k in range(hull.num_polygons):
        a, b, c = (vertices[int(hull.polygons(k)[j])] for j in range(3))
        normal = np.cross(b - a, c - a)
        if normal @ (centre - a) > 0.0:
            normal = -normal
        if normal @ (point - a) > margin * np.linalg.norm(normal):
            return False
    return True


@pytest.fixture
def mesh(tmp_path: Path) -> Path:
    copy = tmp_path / MESH.name
    shutil.copy(MESH, copy)
    return copy


def test_the_hulls_keep_the_notch_the_convex_hull_fills() -> None:
    """The channel's hull holds the notch's middle; none of CoACD's hulls does, and together
    they hold the channel's volume (within CoACD's concavity threshold)."""
    data = MESH.read_bytes()
    everything = params._read_mesh(MESH)
    assert inside(everything, NOTCH)
    hulls = decomposition.decompose(data, '.obj')
    assert 2 <= len(hulls) <= 16
    assert not any(inside(h, NOTCH) for h in hulls)
    total = sum(float(convex_hull(h).computeVolume()) for h in hulls)
    assert total == pytest.approx(VOLUME, rel=0.1)
    assert float(convex_hull(everything).computeVolume()) > 1.5 * VOLUME


def test_the_cache_is_keyed_by_the_mesh_and_the_settings(mesh, monkeypatch) -> None:
    data = mesh.read_bytes()
    made = decomposition.hulls(mesh, data, log=lambda line: None)
    path = decomposition.cache_path(mesh, data)
    assert path.parent == mesh.parent and path.name.startswith('u_channel.obj.')
    runs = []
    real = decomposition.decompose
    monkeypatch.setattr(decomposition, 'decompose',
                        lambda *a, **k: runs.append(a) or real(*a, **k))
    again = decomposition.hulls(mesh, data, log=lambda line: None)
    assert not runs   # read from the cache
    assert len(again) == len(made) and all(np.array_equal(a, b) for a, b in zip(again, made))
    assert decomposition.cache_path(mesh, data, threshold=0.1) != path
    assert decomposition.cache_path(mesh, data, max_hulls=4) != path
    assert decomposition.cache_path(mesh, data + b'\n') != path
    path.write_text('{"version": 1, "key": "x", "hulls": [[0, 0, 0]]}')   # damaged
    decomposition.hulls(mesh, data, log=lambda line: None)
    assert len(runs) == 1 and decomposition.read_cache(path, decomposition.cache_key(
        data, 0.05, 16)) is not None


def scene_text(mesh: Path, static: bool = False) -> str:
    return f"""/**:
  ros__parameters:
    bodies: [floor, part]
    body:
      floor: {{shape: box, size: [2.0, 2.0, 0.2], static: true, position: [0.0, 0.0, -0.1]}}
      part:
        shape: convex
        mesh: {mesh.name}
        decompose: true
        static: {str(static).lower()}
        mass: 0.5
        position: [0.0, 0.0, 0.2]
"""


def test_a_decompose_body_is_its_hulls_and_makes_them_once(mesh, caplog) -> None:
    scene_file = mesh.parent / 'scene.yaml'
    scene_file.write_text(scene_text(mesh))
    with caplog.at_level(logging.WARNING, logger='collres_ros.decomposition'):
        part = params.load_scene(scene_file).bodies[1]
    assert any('decomposing' in r.message and mesh.name in r.message for r in caplog.records)
    assert part.shape == COMPOUND and len(part.pieces) >= 2
    assert [p.name for p in part.pieces] == [f'hull_{k}' for k in range(len(part.pieces))]
    assert 1.0 / mass_properties(part)[0] == pytest.approx(0.5)
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger='collres_ros.decomposition'):
        assert params.load_scene(scene_file).bodies[1] == part
    assert not caplog.records   # from the cache
    # a bag's recorded params carry the hulls as pieces, with no file to read
    recorded = params.load_recorded_scene(params.scene_to_yaml(params.load_scene(scene_file)),
                                          'bag')
    assert recorded.bodies[1].pieces == part.pieces


def test_decompose_needs_a_convex_mesh_and_a_recorded_scene_reads_no_file(mesh) -> None:
    base = {'bodies': ['part'], 'body.part.decompose': True}
    with pytest.raises(ValueError, match=r'^body\.part\.decompose: needs shape convex'):
        params.scene_from_values(base, mesh.parent)
    values = {**base, 'body.part.shape': 'convex', 'body.part.mesh': mesh.name}
    with pytest.raises(ValueError, match=r'^body\.part\.decompose: a recorded scene'):
        params.scene_from_values(values, mesh.parent, files=False)
    with pytest.raises(ValueError, match=r'^body\.part\.mesh: cannot decompose mesh'):
        params.scene_from_values({**values, 'body.part.mesh': 'missing.obj'}, mesh.parent)


def run(args: list[str], cwd: Path) -> subprocess.CompletedProcess:
    result = subprocess.run(processes.command('collres_decompose') + args, capture_output=True,
                            text=True, timeout=300, cwd=cwd)
    print(result.returncode, repr(result.stdout), repr(result.stderr))
    return result


def test_collres_decompose_writes_the_cache_the_params_read(mesh) -> None:
    result = run([mesh.name, '--max-hulls', '8'], mesh.parent)
    data = mesh.read_bytes()
    path = decomposition.cache_path(mesh, data, max_hulls=8)
    assert result.returncode == 0 and path.is_file()
    count = len(decomposition.read_cache(path, decomposition.cache_key(data, 0.05, 8)))
    assert result.stdout == f'{path.name} ({count} hulls)\n'
    assert run([mesh.name, '--max-hulls', '0'], mesh.parent).returncode == 2
    missing = run(['nothing.obj'], mesh.parent)
    assert missing.returncode == 1 and missing.stderr.startswith('error: ')
