"""Hostile params files: every one refused at start with one line naming the parameter.

Covered: mesh paths (only regular .obj/.stl files below a size
limit), topic-name rules for body names, integers given a fraction, NaN mesh
vertices, binary STL files whose header starts with ``solid``, and sizes,
positions and velocities inside documented ranges (no overflow on stderr).
"""

from __future__ import annotations

import os
import struct
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from collres_ros.core.config import MESH_MAX_BYTES
from collres_ros.core.pipeline import Resolver
from collres_ros.core.types import BodyInput
from collres_ros.ros import params

BASE = {'bodies': ['floor', 'ball'], 'body.floor.shape': 'box',
        'body.floor.size': [10.0, 10.0, 0.2], 'body.floor.static': True,
        'body.ball.size': [0.1]}


def refused(values, base_dir=None):
    with pytest.raises(ValueError) as info:
        params.scene_from_values({**BASE, **values}, base_dir)
    text = str(info.value)
    print(text)
    assert '\n' not in text and len(text) < 400
    return text


def convex(mesh):
    return {'body.ball.shape': 'convex', 'body.ball.mesh': str(mesh), 'body.ball.size': None}


def test_mesh_only_regular_obj_or_stl_files(tmp_path):
    assert refused(convex('/etc/passwd')).startswith('body.ball.mesh: cannot read mesh')
    assert 'unsupported mesh format' in refused(convex('/etc/passwd'))
    os.symlink('/dev/zero', tmp_path / 'zero.stl')
    assert 'not a regular file' in refused(convex(tmp_path / 'zero.stl'))
    os.mkfifo(tmp_path / 'fifo.obj')       # would block a plain open() for ever
    assert 'not a regular file' in refused(convex(tmp_path / 'fifo.obj'))
    big = tmp_path / 'big.obj'
    with open(big, 'wb') as f:
        f.truncate(MESH_MAX_BYTES + 1)
    assert 'more than the limit' in refused(convex(big))
    assert refused(convex(tmp_path / 'missing.obj')).endswith(
        '(No such file or directory) (got \'' + str(tmp_path / 'missing.obj') + '\')')


def test_body_names_follow_the_topic_name_rules_length_included():
    long = 'a' * 300
    text = refused({'bodies': ['floor', long]})
    assert text.startswith('bodies: name ') and 'at most 223' in text and long not in text
    assert refused({'bodies': ['floor', '1ball']}).startswith('bodies: name ')
    longest = 'b' * params.NAME_MAX_LENGTH
    values = {k: v for k, v in BASE.items() if not k.startswith('body.ball.')}
    scene = params.scene_from_values({**values, 'bodies': ['floor', longest]})
    from rclpy.validate_full_topic_name import validate_full_topic_name
    validate_full_topic_name(params.LONGEST_BODY_TOPIC.format(scene.names[1]))   # no raise


def test_integer_parameters_refuse_a_fraction_as_at_runtime():
    assert refused({'solver.velocity_iterations': 2.5}) == \
        'solver.velocity_iterations: must be an integer (got 2.5)'
    assert refused({'queue_depth': 10.0}) == \
        'queue_depth: must be an integer, write 10 (got 10.0)'
    assert params.scene_from_values({**BASE, 'queue_depth': 10}).node.queue_depth == 10


def test_a_nan_mesh_vertex_names_the_parameter(tmp_path):
    (tmp_path / 'n.obj').write_text('v nan 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nv 1 1 1\n')
    text = refused(convex(tmp_path / 'n.obj'))
    assert text.startswith('body.ball.mesh: vertex') and 'not finite' in text


def _binary_stl(path, header):
    triangles = [((0, 0, 0), (1, 0, 0), (0, 1, 0)), ((0, 0, 0), (0, 1, 0), (0, 0, 1)),
                 ((0, 0, 0), (0, 0, 1), (1, 0, 0)), ((1, 0, 0), (0, 1, 0), (0, 0, 1))]
    data = header.ljust(80, b' ') + struct.pack('<I', len(triangles))
    for t in triangles:
        data += struct.pack('<12fH', 0, 0, 0, *(c for v in t for c in v), 0)
    path.write_bytes(data)
    return path


def test_a_binary_stl_with_a_solid_header_is_read_as_binary(tmp_path):
    path = _binary_stl(tmp_path / 'cad.stl', b'solid exported by a CAD tool')
    scene = params.scene_from_values({**BASE, **convex(path)})
    points = np.array(scene.bodies[1].points)
    assert sorted(map(tuple, points.tolist())) == [(0, 0, 0), (0, 0, 1), (0, 1, 0), (1, 0, 0)]


@pytest.mark.parametrize('values, text', [
    ({'body.ball.size': [1e-300]}, 'body.ball.size: sphere sizes must be in [1e-06, 1e+06] m'),
    ({'body.ball.size': [1e300]}, 'body.ball.size: sphere sizes must be in [1e-06, 1e+06] m'),
    ({'body.ball.position': [1e308, 0.0, 0.0]}, 'body.ball.position: values must be in'),
    ({'body.ball.linear_velocity': [0.0, 0.0, -1e300]}, 'body.ball.linear_velocity: values'),
    ({'body.ball.inertia': [1e-300, 1.0, 1.0]}, 'body.ball.inertia: values must be in'),
    ({'body.floor.shape': 'plane', 'body.floor.size': [0.0, 0.0, 1.0, 1e300]},
     'body.floor.size: plane needs'),
    ({'body.ball.shape': 'convex', 'body.ball.points': [0, 0, 0, 1e300, 0, 0, 0, 1, 0, 0, 0, 1]},
     'body.ball.points: values must be in'),
])
def test_absurd_sizes_and_positions_are_refused(values, text):
    assert refused(values).startswith(text)


def test_absurd_inputs_are_refused_and_no_overflow_reaches_stderr():
    code = '''
import numpy as np
from collres_ros.core.pipeline import Resolver
from collres_ros.core.types import BodyInput
from collres_ros.ros.params import scene_from_values
scene = scene_from_values({'bodies': ['floor', 'ball', 'box'], 'body.floor.shape': 'box',
    'body.floor.size': [10.0, 10.0, 0.2], 'body.floor.static': True,
    'body.box.shape': 'box', 'body.box.size': [0.2, 0.2, 0.2]})
resolver = Resolver.for_scene(scene)
for k, (x, v) in enumerate([(0.0, 0.0), (1e308, 0.0), (0.0, 1e308), (-1e308, -1e308),
                            (1e8, 1e8), (0.0, 0.0)]):
    out = resolver.resolve(10**9 + k * 10**7, [
        BodyInput('ball', (x, 0.0, 0.05), (0.0, 0.0, 0.0, 1.0), (v, 0.0, -v), (v, 0.0, 0.0),
                  'world', 'world'),
        BodyInput('box', (x, 0.0, 0.1), (0.0, 0.0, 0.0, 1.0), (-v, 0.0, 0.0), (0.0, 0.0, 0.0),
                  'world', 'world')])
    assert np.isfinite(out.states.position).all()
print(dict(resolver.totals))
'''
    result = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                            timeout=120, cwd=Path(__file__).resolve().parents[1])
    print(result.stdout, result.stderr)
    assert result.returncode == 0 and result.stderr == ''
    assert "'out_of_range': 6" in result.stdout


def test_inputs_within_the_limits_are_served():
    scene = params.scene_from_values(BASE)
    out = Resolver.for_scene(scene).resolve(10**9, [BodyInput(
        'ball', (1e8, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0), (1e8, 0.0, 0.0), (0.0, 0.0, 0.0),
        'world', 'world')])
    assert out.names == ['ball'] and not out.rejected


def test_a_hull_of_many_vertices_is_simplified_to_the_vertex_budget(tmp_path):
    from collres_ros.core.config import HULL_MAX_VERTICES
    from collres_ros.core.shapes import convex_hull
    rng = np.random.default_rng(11)
    sphere = rng.normal(size=(100_000, 3))
    sphere = 0.5 * sphere / np.linalg.norm(sphere, axis=1, keepdims=True)
    mesh = tmp_path / 'scan.obj'
    mesh.write_text(''.join(f'v {x!r} {y!r} {z!r}\n' for x, y, z in sphere.tolist()))
    scene = params.scene_from_values({**BASE, **convex(mesh)})
    points = np.array(scene.bodies[1].points)
    print(len(points), 'of', len(sphere), 'vertices kept')
    assert 4 <= len(points) <= HULL_MAX_VERTICES
    given = set(map(tuple, sphere.tolist()))
    assert all(tuple(p) in given for p in points.tolist())   # vertices of the input
    volume = convex_hull(points).computeVolume()
    assert volume >= 0.95 * 4.0 / 3.0 * np.pi * 0.5 ** 3       # approximates it from inside
    assert volume <= 4.0 / 3.0 * np.pi * 0.5 ** 3
    inline = params.scene_from_values({**BASE, 'body.ball.shape': 'convex',
                                       'body.ball.points': sphere[:1000].ravel().tolist()})
    assert len(inline.bodies[1].points) <= HULL_MAX_VERTICES
    yaml_text = params.scene_to_yaml(scene)   # what a bag records stays small
    assert len(yaml_text) < 40_000
