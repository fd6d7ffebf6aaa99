"""Self-describing bags: QoS profiles, params and package version in metadata.yaml.

Read back from metadata.yaml itself (plain YAML), as ``ros2 bag play`` and
``ros2 bag info`` read it: each topic's ``offered_qos_profiles`` in the form
rosbag2 Jazzy writes (metadata version 9: a list of profiles with policy
names), and ``custom_data`` with ``collres_ros.version`` and
``collres_ros.params``, from which ``collres_replay`` takes the scene when no
``--params`` is given.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
import yaml

pytest.importorskip('rclpy')

from collres_ros import __version__  # noqa: E402
from collres_ros.ros import params  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
SCENES = ROOT / 'config' / 'scenes'
INFINITE = {'sec': 9223372036, 'nsec': 854775807}
# one profile as rosbag2 Jazzy writes it for a reliable, volatile, keep-last publisher
EXPECTED_KEYS = ['history', 'depth', 'reliability', 'durability', 'deadline', 'lifespan',
                 'liveliness', 'liveliness_lease_duration', 'avoid_ros_namespace_conventions']


def metadata(bag: Path) -> dict:
    return yaml.safe_load((bag / 'metadata.yaml').read_text())['rosbag2_bagfile_information']


def topics(bag: Path) -> dict[str, dict]:
    return {t['topic_metadata']['name']: t['topic_metadata']
            for t in metadata(bag)['topics_with_message_count']}


def check_profiles(meta: dict, depth: int) -> None:
    profiles = meta['offered_qos_profiles']
    assert isinstance(profiles, list) and len(profiles) == 1, profiles
    (profile,) = profiles
    assert sorted(profile) == sorted(EXPECTED_KEYS)   # a mapping: order is free
    assert profile['history'] == 'keep_last' and profile['depth'] == depth
    assert profile['reliability'] == 'reliable' and profile['durability'] == 'volatile'
    assert profile['liveliness'] == 'automatic'
    for key in ('deadline', 'lifespan', 'liveliness_lease_duration'):
        assert profile[key] == INFINITE, (key, profile[key])
    assert profile['avoid_ros_namespace_conventions'] is False


def test_version_is_the_package_version() -> None:
    xml = (ROOT / 'package.xml').read_text()
    assert re.search(r'<version>(.*)</version>', xml).group(1) == __version__
    assert f"version='{__version__}'" in (ROOT / 'setup.py').read_text()


def test_scene_to_yaml_loads_back_as_the_same_scene(tmp_path: Path) -> None:
    for name in ('pile', 'box_stack', 'billiard_break'):
        scene = params.load_scene(SCENES / f'{name}.yaml')
        path = tmp_path / f'{name}.yaml'
        path.write_text(params.scene_to_yaml(scene))
        again = params.load_scene(path)
        assert again.bodies == scene.bodies, name
        assert (again.solver, again.node, again.sim) == (scene.solver, scene.node, scene.sim)
        for field in ('position', 'orientation', 'linear', 'angular'):
            assert np.array_equal(getattr(again.initial, field), getattr(scene.initial, field))


def test_offline_bag_carries_qos_params_and_version(tmp_path: Path) -> None:
    from collres_ros.sim import main
    bag = tmp_path / 'rec'
    assert main(['--offline', '--params', str(SCENES / 'box_stack.yaml'), '--duration', '0.1',
                 '--record', str(bag)]) == 0
    info = metadata(bag)
    assert info['version'] == 9
    found = topics(bag)
    print({name: meta['offered_qos_profiles'][0]['depth'] for name, meta in found.items()})
    assert set(found) == {'/body_states', '/body_states/corrected', '/contacts',
                          '/contact_markers', '/body_markers', '/diagnostics'}
    queue_depth = params.load_scene(SCENES / 'box_stack.yaml').node.queue_depth
    # the publishers of steps keep the last 1000 (a recorder that falls behind loses none),
    # markers the node's queue_depth, /diagnostics the last 10
    depths = {'/body_states': 1000, '/body_states/corrected': 1000, '/contacts': 1000,
              '/contact_markers': queue_depth, '/body_markers': queue_depth,
              '/diagnostics': 10}
    for name, meta in found.items():
        check_profiles(meta, depths[name])
    custom = info['custom_data']
    assert custom['collres_ros.version'] == __version__
    recorded = tmp_path / 'recorded.yaml'
    recorded.write_text(custom['collres_ros.params'])
    assert params.load_scene(recorded).bodies == params.load_scene(
        SCENES / 'box_stack.yaml').bodies


def test_replay_takes_the_params_from_the_bag(tmp_path: Path, capsys) -> None:
    from collres_ros.ros.bag import message_fields, read_messages
    from collres_ros.replay import main as replay_main
    from collres_ros.sim import main as sim_main
    scene = SCENES / 'bouncing_ball.yaml'
    assert sim_main(['--offline', '--params', str(scene), '--duration', '0.3',
                     '--record', str(tmp_path / 'rec')]) == 0
    assert replay_main([str(tmp_path / 'rec'), str(tmp_path / 'with'), '--params', str(scene),
                        '--quiet']) == 0
    assert replay_main([str(tmp_path / 'rec'), str(tmp_path / 'without'), '--quiet']) == 0
    capsys.readouterr()
    a = [(m.topic, m.log_time, message_fields(m.msg)) for m in read_messages(tmp_path / 'with')
         if m.topic != '/diagnostics']
    b = [(m.topic, m.log_time, message_fields(m.msg))
         for m in read_messages(tmp_path / 'without') if m.topic != '/diagnostics']
    assert a and a == b
    # the replay's own output is self-describing too: it replays again without --params
    check_profiles(topics(tmp_path / 'without')['/contacts'], 1000)
    assert metadata(tmp_path / 'without')['custom_data']['collres_ros.version'] == __version__
    assert replay_main([str(tmp_path / 'without'), str(tmp_path / 'again'), '--quiet',
                        '--topics', 'contacts']) == 1   # no inputs in a replay's output
    assert capsys.readouterr().err.startswith('error: no input topics')


def test_replay_of_a_bag_without_params_needs_params(tmp_path: Path, capsys) -> None:
    from collres_ros.ros.bag import BagWriter
    from collres_ros.replay import main
    from collres_ros.msg import BodyStateArray
    with BagWriter(tmp_path / 'plain') as writer:
        writer.write('/body_states', 1, BodyStateArray())
    assert main([str(tmp_path / 'plain'), str(tmp_path / 'out')]) == 1
    err = capsys.readouterr().err
    assert err.startswith('error: ') and 'give --params FILE' in err and len(err.splitlines()) == 1
    assert not (tmp_path / 'out').exists()
