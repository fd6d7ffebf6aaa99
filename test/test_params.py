"""Params loading: the README's schema, every error form, defaults kept in step."""

from __future__ import annotations

from pathlib import Path

import pytest

from collres_ros.ros import params
from collres_ros.core.config import NODE_PARAMS, SIM_PARAMS, SOLVER_PARAMS, BODY_PARAMS

ROOT = Path(__file__).resolve().parents[1]
BASE = {'bodies': ['floor', 'ball'], 'body.floor.shape': 'box',
        'body.floor.size': [10.0, 10.0, 0.2], 'body.floor.static': True,
        'body.ball.size': [0.1]}


def error(**changes):
    values = dict(BASE)
    values.update({k.replace('__', '.'): v for k, v in changes.items()})
    with pytest.raises(ValueError) as info:
        params.scene_from_values(values)
    text = str(info.value)
    print(text)
    assert '\n' not in text
    return text


def test_default_config_loads_with_the_design_scene():
    scene = params.load_scene(ROOT / 'config' / 'collres.yaml')
    assert scene.names == ['floor', 'ball', 'box'] and scene.world_frame == 'world'
    ball = scene.bodies[1]
    assert (ball.shape, ball.size, ball.restitution) == ('sphere', (0.1,), 0.8)
    assert scene.bodies[0].static and scene.initial.position[1].tolist() == [0.0, 0.0, 1.1]
    assert scene.sim.gravity == (0.0, 0.0, -9.81)


def test_every_parameter_in_the_default_config_has_its_default():
    """config/collres.yaml lists every parameter; the solver/node/sim ones at their defaults."""
    values = params.read_params_file(ROOT / 'config' / 'collres.yaml')
    scene = params.load_scene(ROOT / 'config' / 'collres.yaml')
    for spec in params.all_specs(scene.names):
        assert spec.name in values, f'{spec.name} missing from config/collres.yaml'
    for spec in SOLVER_PARAMS:
        assert values[f'solver.{spec.name}'] == spec.default, spec.name
    for spec in NODE_PARAMS:
        assert values[spec.name] == spec.default, spec.name


def test_markdown_table_lists_every_parameter():
    table = params.markdown_table()
    for spec in BODY_PARAMS:
        assert f'`body.<name>.{spec.name}`' in table
    for spec in SOLVER_PARAMS:
        assert f'`solver.{spec.name}`' in table
    for spec in NODE_PARAMS + SIM_PARAMS:
        assert f'`{spec.name}`' in table
    readme = ROOT / 'README.md'
    if readme.is_file() and '`solver.toi_tolerance`' in readme.read_text():
        assert table in readme.read_text(), 'README table out of date: paste markdown_table()'


def test_descriptors_carry_the_config_ranges():
    pytest.importorskip('rcl_interfaces')
    for spec in params.node_specs(['ball']):
        d = params.descriptor(spec, read_only=False)
        assert d.name == spec.name and d.description
        if spec.type == 'double' and spec.minimum is not None:
            r = d.floating_point_range[0]
            assert (r.from_value, r.to_value) == (spec.minimum, spec.maximum)
        if spec.type == 'integer' and spec.minimum is not None:
            r = d.integer_range[0]
            assert (r.from_value, r.to_value) == (spec.minimum, spec.maximum)


def test_error_forms():
    assert error(body__ball__restitution=1.5) == \
        'body.ball.restitution: allowed range [0.0, 1.0] (got 1.5)'
    assert error(body__ball__mass=-1.0) == \
        'body.ball.mass: allowed range [1e-09, 1000000000.0] (got -1.0)'
    assert error(body__ball__kinetic_friction=0.6) == \
        'body.ball.kinetic_friction: must be <= static_friction 0.5 (got 0.6)'
    assert error(body__ball__shape='blob').startswith(
        "body.ball.shape: allowed values sphere, box, capsule, cylinder, cone, plane, convex")
    assert error(body__floor__size=[1.0, 2.0]) == \
        'body.floor.size: needs 3 values [x, y, z] (got [1.0, 2.0])'
    assert error(body__ball__size=[-0.1]) == \
        'body.ball.size: sphere needs 1 values [r] > 0 (got [-0.1])'
    assert error(body__ball__position=[0.0, 1.0]) == \
        'body.ball.position: needs 3 values [x, y, z] (got [0.0, 1.0])'
    assert error(body__ball__orientation=[0.0, 0.0, 0.0, 0.0]).startswith(
        'body.ball.orientation: quaternion must be non-zero')
    assert error(body__ball__static='yes') == \
        "body.ball.static: must be true or false (got 'yes')"
    assert error(solver__velocity_iterations=0) == \
        'solver.velocity_iterations: allowed range [1, 1000] (got 0)'
    assert error(solver__restitution_rule='sum').startswith(
        'solver.restitution_rule: allowed values average, min, max')
    assert error(solver__toi_tolerence=0.1) == 'solver.toi_tolerence: unknown parameter'
    assert error(body__cat__shape='box') == \
        "body.cat.shape: body 'cat' is not in bodies (got ['floor', 'ball'])"
    assert error(bodies=[]) == 'bodies: at least one body name required (got [])'
    assert error(bodies=['a', 'a']).startswith("bodies: duplicate name 'a'")
    assert error(bodies=['my ball']).startswith("bodies: name 'my ball' must match")
    assert error(stale_timeout=0.0) == 'stale_timeout: allowed range [0.001, 3600.0] (got 0.0)'
    assert error(body__floor__shape='plane', body__floor__size=[0.0, 0.0, 1.0, 0.0],
                 body__floor__static=False) == \
        'body.floor.static: a plane must be static (got false)'
    assert error(body__ball__shape='convex', body__ball__points=[0.0, 0.0, 0.0]).startswith(
        'body.ball.points: convex needs at least 4 points spanning a volume')


def test_file_sections_and_relative_mesh(tmp_path):
    (tmp_path / 'meshes').mkdir()
    (tmp_path / 'meshes' / 'tetra.obj').write_text(
        'v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\n')
    path = tmp_path / 'scene.yaml'
    path.write_text('''/**:
  ros__parameters:
    bodies: [floor, rock]
    body:
      floor: {shape: plane, size: [0, 0, 1, 0], static: true}
      rock: {shape: convex, mesh: meshes/tetra.obj, mass: 2}
collres_node:
  ros__parameters:
    solver: {velocity_iterations: 20}
    sync_slop: 0.001
collres_sim:
  ros__parameters:
    rate_hz: 100
other_node:
  ros__parameters:
    anything: 1
''')
    scene = params.load_scene(path)
    rock = scene.bodies[1]
    assert len(rock.points) == 4 and rock.mass == 2.0
    assert scene.solver.velocity_iterations == 20 and scene.node.sync_slop == 0.001
    assert scene.sim.rate_hz == 100.0


def test_file_errors(tmp_path):
    with pytest.raises(FileNotFoundError):
        params.load_scene(tmp_path / 'missing.yaml')
    bad = tmp_path / 'bad.yaml'
    bad.write_text('/**:\n  ros__parameters:\n    bodies: [a\n')
    with pytest.raises(ValueError, match='not valid YAML'):
        params.load_scene(bad)
    mesh = tmp_path / 'mesh.yaml'
    mesh.write_text('/**:\n  ros__parameters:\n    bodies: [r]\n    body:\n'
                    '      r: {shape: convex, mesh: nope.obj}\n')
    with pytest.raises(ValueError, match=r'^body\.r\.mesh: cannot read mesh'):
        params.load_scene(mesh)


def test_runtime_changes_are_revalidated():
    scene = params.scene_from_values(BASE)
    changed = params.with_changes(scene, {'body.ball.restitution': 0.1,
                                          'solver.velocity_iterations': 4})
    assert changed.bodies[1].restitution == 0.1 and changed.solver.velocity_iterations == 4
    with pytest.raises(ValueError, match='static_friction'):
        params.with_changes(scene, {'body.ball.static_friction': 0.1})
    assert params.is_runtime_changeable('body.ball.restitution')
    assert not params.is_runtime_changeable('body.ball.mass')
    assert params.is_runtime_changeable('solver.ccd')


def test_collision_filter_parameters_and_their_errors():
    scene = params.scene_from_values(BASE)
    assert scene.collision_filter.group == (1, 1)
    assert scene.collision_filter.mask == (0xFFFF, 0xFFFF) and scene.collision_filter.ignored == ()
    three = {**BASE, 'bodies': ['floor', 'ball', 'box'], 'body.box.shape': 'box',
             'body.box.size': [0.2, 0.2, 0.2], 'body.ball.collision_group': 6,
             'body.box.collision_mask': 1, 'ignore_pairs': ['box : floor', 'ball:box']}
    f = params.scene_from_values(three).collision_filter
    print(f)
    assert f.group == (1, 6, 1) and f.mask == (0xFFFF, 0xFFFF, 1)
    assert f.ignored == ((0, 2), (1, 2))
    assert f.collides(0, 1) and not f.collides(0, 2) and not f.collides(1, 2)
    assert error(ignore_pairs=['ball:flor']) == \
        "ignore_pairs: body 'flor' is not in bodies (got 'ball:flor')"
    assert error(ignore_pairs=['ballfloor']) == \
        'ignore_pairs: each entry must be "a:b", two body names (got \'ballfloor\')'
    assert error(ignore_pairs=['ball:floor:ball']).startswith('ignore_pairs: each entry must')
    assert error(ignore_pairs=['ball:ball']) == \
        "ignore_pairs: an entry names one body twice (got 'ball:ball')"
    assert error(ignore_pairs='ball:floor').startswith('ignore_pairs: must be a list')
    assert error(body__ball__collision_mask=0x10000) == \
        'body.ball.collision_mask: allowed range [0, 65535] (got 65536)'
    assert error(body__ball__collision_group=-1) == \
        'body.ball.collision_group: allowed range [0, 65535] (got -1)'
    assert error(body__ball__collision_group=2.0).startswith(
        'body.ball.collision_group: must be an integer')
    for name in ('ignore_pairs', 'body.ball.collision_group', 'body.ball.collision_mask'):
        assert params.is_runtime_changeable(name), name
    changed = params.with_changes(scene, {'ignore_pairs': ['floor:ball']})
    assert changed.collision_filter.ignored == ((0, 1),)
    with pytest.raises(ValueError, match=r"^ignore_pairs: body 'cat' is not in bodies"):
        params.with_changes(scene, {'ignore_pairs': ['floor:cat']})


def test_a_runtime_change_validates_what_changed_and_keeps_the_shapes(tmp_path):
    mesh = tmp_path / 'rock.obj'
    mesh.write_text('v 0 0 0\nv 0.1 0 0\nv 0 0.1 0\nv 0 0 0.1\nv 0.05 0.05 0.05\n')
    scene = params.scene_from_values({**BASE, 'body.ball.shape': 'convex',
                                      'body.ball.mesh': str(mesh), 'body.ball.size': None})
    mesh.unlink()   # a runtime change reads no mesh file again
    changed = params.with_changes(scene, {'solver.velocity_iterations': 5,
                                          'body.ball.restitution': 0.2})
    assert changed.solver.velocity_iterations == 5 and changed.bodies[1].restitution == 0.2
    assert changed.bodies[1].points == scene.bodies[1].points
    assert changed.values['body.ball.mesh'] == str(mesh)
    with pytest.raises(ValueError, match=r'^solver.velocity_iterations: allowed range'):
        params.with_changes(scene, {'solver.velocity_iterations': 0})
    with pytest.raises(ValueError, match=r'^body.ball.mass: read-only'):
        params.with_changes(scene, {'body.ball.mass': 2.0})
    with pytest.raises(ValueError, match=r'^ignore_pairs: '):
        params.with_changes(scene, {'ignore_pairs': ['ball:nope']})
