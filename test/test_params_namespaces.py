"""One parameter reader: collres_sim and collres_replay read params files as the node does.

rcl chooses the sections of a params file by the node's fully qualified name
(``/**``, ``/**/collres_node``, ``/r1/collres_node``, ``/*/collres_node``,
``/r1/**``; a bare ``collres_node`` is ``/collres_node``, the root namespace
only) and merges them leaf by leaf in file order. ``params.read_params_file``
must give what rclpy hands a node of that name as its parameter overrides.
"""

from __future__ import annotations

from pathlib import Path

import pytest

pytest.importorskip('rclpy')

from collres_ros.ros import params  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
SECTIONS = '''
/**:
  ros__parameters:
    shared: 1
    body: {a: {x: 1.0}, b: {x: 1.0}}
collres_node:
  ros__parameters: {bare: 1}
/collres_node:
  ros__parameters: {root: 1, shared: 2}
/r1/collres_node:
  ros__parameters:
    in_r1: 1
    body: {b: {x: 2.0}}
/*/collres_node:
  ros__parameters: {one_level: 1}
/**/collres_node:
  ros__parameters: {any_level: 1}
/r1/*:
  ros__parameters: {r1_any_node: 1}
/r1/**:
  ros__parameters: {below_r1: 1, shared: 3}
/r2/collres_node:
  ros__parameters: {in_r2: 1}
/r1/sub/collres_node:
  ros__parameters: {in_r1_sub: 1, label: '1.5', flag: 'true'}
collres_sim:
  ros__parameters: {sim_root: 1}
/**/collres_sim:
  ros__parameters: {sim_any: 1}
'''


def rcl_overrides(path: Path, name: str, namespace: str) -> dict:
    """What rclpy gives a node ``namespace``/``name`` started with ``--params-file path``."""
    import rclpy
    from rclpy.node import Node
    context = rclpy.Context()
    rclpy.init(context=context, args=['x', '--ros-args', '--params-file', str(path)])
    try:
        node = Node(name, namespace=namespace, context=context,
                    automatically_declare_parameters_from_overrides=False)
        values = {k: p.value for k, p in node._parameter_overrides.items()}
        node.destroy_node()
        return {k: list(v) if isinstance(v, (list, tuple)) or hasattr(v, 'tolist') else v
                for k, v in values.items()}
    finally:
        rclpy.try_shutdown(context=context)


@pytest.mark.parametrize('namespace', ['/', '/r1', '/r1/sub', '/r2'])
@pytest.mark.parametrize('name', ['collres_node', 'collres_sim'])
def test_sections_apply_as_rcl_applies_them(tmp_path: Path, name: str, namespace: str) -> None:
    path = tmp_path / 'params.yaml'
    path.write_text(SECTIONS)
    expected = rcl_overrides(path, name, namespace)
    got = params.read_params_file(path, [name], namespace)
    print(f'{namespace}/{name}: {sorted(got.items())}')
    assert got == expected
    assert MATCHED[name, namespace] <= set(got), 'the namespace-specific sections'


MATCHED = {
    ('collres_node', '/'): {'bare', 'root', 'any_level'},
    ('collres_node', '/r1'): {'in_r1', 'one_level', 'r1_any_node', 'below_r1', 'any_level'},
    ('collres_node', '/r1/sub'): {'in_r1_sub', 'below_r1', 'any_level'},
    ('collres_node', '/r2'): {'in_r2', 'one_level', 'any_level'},
    ('collres_sim', '/'): {'sim_root', 'sim_any'},
    ('collres_sim', '/r1'): {'sim_any', 'r1_any_node', 'below_r1'},
    ('collres_sim', '/r1/sub'): {'sim_any', 'below_r1'},
    ('collres_sim', '/r2'): {'sim_any'},
}


def test_the_reader_keeps_rcl_types_and_refuses_mixed_lists(tmp_path: Path) -> None:
    path = tmp_path / 'params.yaml'
    path.write_text(SECTIONS)
    got = params.read_params_file(path, ['collres_node'], '/r1/sub')
    assert got['label'] == '1.5' and got['flag'] == 'true'   # quoted: strings, as in rcl
    mixed = tmp_path / 'mixed.yaml'
    mixed.write_text('/**:\n  ros__parameters:\n    gravity: [0, 0, -9.81]\n')
    with pytest.raises(ValueError, match=r'^gravity: a list must hold values of one type'):
        params.read_params_file(mixed)


NAMESPACED_SCENE = '''
/**:
  ros__parameters:
    bodies: [floor, ball]
    body:
      floor: {shape: box, size: [4.0, 4.0, 0.2], static: true, position: [0.0, 0.0, -0.1]}
      ball: {shape: sphere, size: [0.1], restitution: 0.5, position: [0.0, 0.0, 0.5]}
/r1/collres_node:
  ros__parameters:
    solver: {restitution_rule: min}
/r1/collres_sim:
  ros__parameters: {rate_hz: 100.0, duration: 0.2}
collres_sim:
  ros__parameters: {rate_hz: 50.0, duration: 0.1}
'''


def test_sim_and_replay_read_the_sections_of_their_namespace(tmp_path: Path) -> None:
    from collres_ros.ros.bag import BagReader
    from collres_ros.ros.offline import replay
    from collres_ros.ros.simulation import load_sim_scene
    from collres_ros.sim import main
    path = tmp_path / 'scene.yaml'
    path.write_text(NAMESPACED_SCENE)
    r1, root = load_sim_scene(path, namespace='/r1'), load_sim_scene(path)
    print(f'/r1: {r1.rate_hz} Hz {r1.duration} s {r1.scene.solver.restitution_rule}; '
          f'/: {root.rate_hz} Hz {root.duration} s {root.scene.solver.restitution_rule}')
    assert (r1.rate_hz, r1.duration, r1.scene.solver.restitution_rule) == (100.0, 0.2, 'min')
    root_values = (root.rate_hz, root.duration, root.scene.solver.restitution_rule)
    assert root_values == (50.0, 0.1, 'max')
    # collres_sim in /r1 (the remap launch passes): its own section, topics under /r1
    bag = tmp_path / 'rec'
    assert main(['--offline', '--params', str(path), '--record', str(bag),
                 '--ros-args', '-r', '__ns:=/r1']) == 0
    with BagReader(bag) as reader:
        assert reader.topic_count('/r1/body_states') == 21    # 0.2 s at 100 Hz, both ends
        assert '/body_states' not in reader.topics
    # collres_replay --namespace /r1 reads /r1/collres_node's solver section
    summary = replay(bag, tmp_path / 'out', path, namespace='/r1')
    assert summary.steps == 21
    with BagReader(tmp_path / 'out') as reader:
        assert reader.topic_count('/r1/body_states/corrected') == 21
        recorded = reader.custom_data['collres_ros.params']
    assert 'restitution_rule: min' in recorded
