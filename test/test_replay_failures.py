"""collres_replay on bad bags: a clear error, a non-zero exit, no output left behind."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from collres_ros.ros import processes

ROOT = Path(__file__).resolve().parents[1]
BALL = ROOT / 'config' / 'scenes' / 'bouncing_ball.yaml'


def replay(*args):
    result = subprocess.run(processes.command('collres_replay') + [str(a) for a in args],
                            capture_output=True, text=True, timeout=300)
    print(result.returncode, result.stdout, result.stderr)
    return result


def string_bag(path, count):
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore
    store = get_typestore(Stores.ROS2_JAZZY)
    kind = store.types['std_msgs/msg/String']
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        connection = writer.add_connection('/body_states', 'std_msgs/msg/String',
                                           typestore=store)
        for i in range(count):
            writer.write(connection, 1000 + i,
                         store.serialize_cdr(kind(data='x'), 'std_msgs/msg/String'))
    return path


@pytest.mark.parametrize('count', [20, 0])
def test_a_wrong_type_input_topic_is_an_error_and_leaves_no_output(tmp_path, count):
    bag = string_bag(tmp_path / 'wrong', count)
    out = tmp_path / 'out'
    result = replay(bag, out, '--params', BALL, '--quiet')
    assert result.returncode == 1 and 'Traceback' not in result.stderr
    assert result.stderr.strip() == (
        f'error: {bag}: topic /body_states has type std_msgs/msg/String, expected '
        'collres_ros/msg/BodyStateArray')
    assert not out.exists()


@pytest.fixture(scope='module')
def recorded(tmp_path_factory):
    bag = tmp_path_factory.mktemp('sim') / 'good'
    result = subprocess.run(processes.command('collres_sim') + [
        '--offline', '--params', str(BALL), '--duration', '1', '--record', str(bag)],
        capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    return bag


def test_a_corrupt_mcap_is_reported_and_exits_non_zero(recorded, tmp_path):
    import shutil
    bag = tmp_path / 'corrupt'
    shutil.copytree(recorded, bag)
    f = next(bag.glob('*.mcap'))
    data = bytearray(f.read_bytes())
    n = len(data) // 3
    data[n:n + 4000] = bytes((x * 7 + 13) % 256 for x in data[n:n + 4000])
    f.write_bytes(bytes(data))
    out = tmp_path / 'out'
    result = replay(bag, out, '--params', BALL, '--quiet')
    assert result.returncode == 1 and 'Traceback' not in result.stderr
    assert result.stderr.startswith(f'error: {bag}: ') and (
        'damaged' in result.stderr or 'unreadable' in result.stderr)
    assert not out.exists()
    again = replay(recorded, out, '--params', BALL, '--quiet')   # a rerun is not blocked
    assert again.returncode == 0 and out.exists()


def test_nothing_resolved_is_an_error(recorded, tmp_path):
    wrong = tmp_path / 'wrong.yaml'
    wrong.write_text('/**:\n  ros__parameters:\n    bodies: [other]\n')
    out = tmp_path / 'out'
    result = replay(recorded, out, '--params', wrong, '--quiet')
    assert result.returncode == 1
    assert result.stderr.startswith('error: nothing resolved: every input was refused '
                                    '(unknown_body ')
    assert not out.exists()


if __name__ == '__main__':
    sys.exit(pytest.main([__file__]))
