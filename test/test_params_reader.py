"""One reading of a params file, rcl's: what collres_sim and collres_replay take is what the
node's rcl takes.

rcl reads no aliases (a kilobyte of nested aliases expands to millions of
values), no tags but ``!!str``, and types a plain scalar as a bool, a C
``strtol`` integer, a ``strtod`` double or else a string: ``1e-05`` is a
double. The oracle is rcl itself (the overrides rclpy hands a node started
with ``--params-file``). A bag's recorded params are read the same way, and
are untrusted: they name no file (a ``mesh`` path is refused), and what is not
a string is one error line.
"""

from __future__ import annotations

import math
import shutil
from pathlib import Path

import pytest
import yaml

pytest.importorskip('rclpy')

from collres_ros.core.config import PARAMS_FILE_MAX_DEPTH  # noqa: E402
from collres_ros.replay import main as replay_main  # noqa: E402
from collres_ros.ros import params  # noqa: E402
from collres_ros.ros.simulation import load_sim_scene  # noqa: E402
from collres_ros.sim import main as sim_main  # noqa: E402
from test_params_namespaces import rcl_overrides  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
BALL = ROOT / 'config' / 'scenes' / 'bouncing_ball.yaml'
SCALARS = ['1e-05', '0.00001', '1E5', '010', '0x1F', '+5', '-0', '.5', '1.', 'yes', 'No',
           'on', 'OFF', 'y', 'N', '~', 'null', '.inf', '-.Inf', 'inf', '1e999', '1_000',
           '0o17', "'1.5'", '"2"', '!!str 3', '9223372036854775808', '0b101', '1:30',
           '2026-12-01', '[1e-05, 2.5]', '[yes, no]', '0x1p3', '-infinity', '1e-320', '0e0',
           '09', 'TRUE', 'tRUE', '12abc', '.nan', 'NaN', "''"]


def test_scalars_are_typed_as_rcl_types_them(tmp_path: Path) -> None:
    path = tmp_path / 'scalars.yaml'
    path.write_text('/**:\n  ros__parameters:\n' + ''.join(
        f'    p{k:02d}: {text}\n' for k, text in enumerate(SCALARS)))
    expected = rcl_overrides(path, 'collres_node', '/')
    got = params.read_params_file(path)
    assert sorted(got) == sorted(expected)
    for name, value in expected.items():
        ours = got[name]
        print(f'{SCALARS[int(name[1:])]!r:>24}: rcl {value!r}, ours {ours!r}')
        if isinstance(value, float) and math.isnan(value):
            assert isinstance(ours, float) and math.isnan(ours)
        else:
            assert (type(ours), ours) == (type(value), value)


def scene_file(tmp_path: Path, extra: str) -> Path:
    path = tmp_path / 'scene.yaml'
    path.write_text(BALL.read_text() + extra)
    return path


def test_sim_and_replay_take_small_numbers_as_the_node_does(tmp_path: Path) -> None:
    path = tmp_path / 'small.yaml'
    path.write_text('/**:\n  ros__parameters:\n    bodies: [ball]\n'
                    '    body: {ball: {size: [0.00001], position: [0.0, 0.0, 1e-05]}}\n'
                    'collres_node:\n  ros__parameters:\n    solver: {toi_tolerance: 0.00001}\n')
    assert rcl_overrides(path, 'collres_node', '/')['solver.toi_tolerance'] == 1e-05
    scene = load_sim_scene(path).scene
    assert scene.solver.toi_tolerance == 1e-05
    assert scene.bodies[0].size == (1e-05,) and scene.initial.position[0, 2] == 1e-05


def alias_bomb(levels: int = 6, fan: int = 10) -> str:
    """About a kilobyte of YAML whose aliases expand to fan**levels leaves."""
    lines = ['x0: &a0 [1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0]']
    for k in range(1, levels):
        lines.append(f'x{k}: &a{k} [' + ', '.join([f'*a{k - 1}'] * fan) + ']')
    return '/**:\n  ros__parameters:\n' + ''.join(f'    {line}\n' for line in lines)


def test_aliases_are_refused_at_once(tmp_path: Path) -> None:
    path = tmp_path / 'bomb.yaml'
    path.write_text(alias_bomb())
    print(len(path.read_text()), 'bytes')
    with pytest.raises(ValueError, match=r'bomb.yaml: line 4: YAML aliases are not read'):
        params.read_params_file(path)
    with pytest.raises(ValueError, match='aliases'):
        load_sim_scene(path)


def test_tags_other_than_str_are_refused_and_depth_is_bounded(tmp_path: Path) -> None:
    path = tmp_path / 'tagged.yaml'
    for text, why in (('x: !!float 1', "YAML tag 'tag:yaml.org,2002:float' is not read"),
                      ('x: !!python/object:os.system {}', 'is not read'),
                      ('x: !custom 1', "YAML tag '!custom' is not read"),
                      ('x: ' + '[' * (PARAMS_FILE_MAX_DEPTH + 1) + ']' * (
                          PARAMS_FILE_MAX_DEPTH + 1), 'nested deeper than'),
                      ('x:', 'no value'), ('x: [[1.0], [2.0]]', 'must hold plain values')):
        path.write_text(f'/**:\n  ros__parameters:\n    {text}\n')
        with pytest.raises(ValueError, match=why):
            params.read_params_file(path)


@pytest.fixture(scope='module')
def recorded(tmp_path_factory: pytest.TempPathFactory) -> Path:
    bag = tmp_path_factory.mktemp('rec') / 'bag'
    assert sim_main(['--offline', '--params', str(BALL), '--record', str(bag),
                     '--duration', '0.05']) == 0
    return bag


def with_params(bag: Path, where: Path, value: object) -> Path:
    """A copy of ``bag`` whose recorded params are ``value``."""
    copy = where / 'copy'
    shutil.copytree(bag, copy)
    meta = copy / 'metadata.yaml'
    document = yaml.safe_load(meta.read_text())
    document['rosbag2_bagfile_information']['custom_data']['collres_ros.params'] = value
    meta.write_text(yaml.safe_dump(document, sort_keys=False))
    return copy


def replay_error(bag: Path, out: Path, capsys: pytest.CaptureFixture) -> str:
    assert replay_main([str(bag), str(out)]) == 1
    lines = capsys.readouterr().err.strip().splitlines()
    print(lines)
    assert len(lines) == 1 and lines[0].startswith('error: ') and not out.exists()
    return lines[0]


def test_recorded_params_are_read_by_the_same_rules(recorded: Path, tmp_path: Path,
                                                    capsys: pytest.CaptureFixture) -> None:
    bag = with_params(recorded, tmp_path, alias_bomb())
    assert 'YAML aliases are not read' in replay_error(bag, tmp_path / 'out', capsys)


def test_a_recorded_mesh_path_is_not_read(recorded: Path, tmp_path: Path,
                                          capsys: pytest.CaptureFixture) -> None:
    secret = tmp_path / 'elsewhere.obj'
    secret.write_text('v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nv 0.3 0.3 0.3\n')
    for mesh in (str(secret), '../' * 12 + str(secret).lstrip('/')):
        text = yaml.safe_load((recorded / 'metadata.yaml').read_text())[
            'rosbag2_bagfile_information']['custom_data']['collres_ros.params']
        head, _, tail = text.rpartition("mesh: ''")   # the ball's: the last body
        text = (head + f'mesh: {mesh}' + tail).replace('shape: sphere', 'shape: convex')
        bag = with_params(recorded, tmp_path, text)
        line = replay_error(bag, tmp_path / 'out', capsys)
        assert 'body.ball.mesh: a recorded scene carries its vertices' in line
        shutil.rmtree(bag)


@pytest.mark.parametrize('value', [['/**', 'x'], {'/**': {'ros__parameters': {}}}, 7])
def test_recorded_params_that_are_not_text_are_one_line(recorded: Path, tmp_path: Path,
                                                        capsys: pytest.CaptureFixture,
                                                        value: object) -> None:
    bag = with_params(recorded, tmp_path, value)
    assert 'recorded params must be the text of a params file' in replay_error(
        bag, tmp_path / 'out', capsys)


def test_replay_refuses_an_unknown_topic(recorded: Path, tmp_path: Path,
                                         capsys: pytest.CaptureFixture) -> None:
    assert replay_main([str(recorded), str(tmp_path / 'out'), '--topics', 'nope']) == 1
    err = capsys.readouterr().err
    print(err)
    assert err.startswith("error: --topics: not an output topic: 'nope' (outputs: ")
    assert not (tmp_path / 'out').exists()
    assert replay_main([str(recorded), str(tmp_path / 'ok'), '--topics',
                        'contacts,bodies/ball/pose/corrected']) == 0
