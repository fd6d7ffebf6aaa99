"""Sleeping in bags: a golden with a sleeping body replays bit-exactly, and a bag recorded
before BodyState had ``sleeping`` still reads and replays.

* slope_hold's box falls asleep for half of its golden: the replay (the same Resolver as
  the node, sleeping on by default) gives the golden bit for bit, flags included;
* the same input written with the old BodyState definition (no ``sleeping``; the bag
  embeds that definition, as bags recorded before it did) reads through ``BagReader`` with
  the flags false and replays to the same golden.
"""

from __future__ import annotations

from pathlib import Path

import pytest

pytest.importorskip('rclpy')

from test_regression import DATA, SCENES, first_difference  # noqa: E402

OLD_BODY_STATE = 'string name\ngeometry_msgs/Pose pose\ngeometry_msgs/Twist twist\n'
ARRAY = 'std_msgs/Header header\ncollres_ros/BodyState[] bodies\n'
STATES_TYPE = 'collres_ros/msg/BodyStateArray'


def _golden_matches(out: Path) -> None:
    from collres_ros.ros.bag import read_messages
    golden = read_messages(DATA / 'slope_hold' / 'golden')
    asleep = [m for m in golden if m.topic == '/body_states/corrected'
              and any(b.sleeping for b in m.msg.bodies)]
    assert len(asleep) > 100, 'the box never slept: the check would be vacuous'
    difference = first_difference(read_messages(out), golden)
    assert difference is None, difference


def test_a_golden_with_a_sleeping_body_replays_bit_exactly(tmp_path: Path) -> None:
    from collres_ros.ros.offline import replay
    replay(DATA / 'slope_hold' / 'input', tmp_path / 'out', SCENES / 'slope_hold.yaml',
           topics=('body_states/corrected', 'contacts'))
    _golden_matches(tmp_path / 'out')


def _old_bag(path: Path) -> int:
    """slope_hold's input re-written with the BodyState of before ``sleeping``."""
    from rosbags.rosbag2 import Writer
    from rosbags.rosbag2.enums import StoragePlugin
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    from collres_ros.ros.bag import BagReader
    from collres_ros.ros.codec import StatesCodec
    store = get_typestore(Stores.ROS2_JAZZY)
    types = get_types_from_msg(OLD_BODY_STATE, 'collres_ros/msg/BodyState')
    types.update(get_types_from_msg(ARRAY, STATES_TYPE))
    store.register(types)
    t = store.types
    codec, count = StatesCodec(), 0
    with BagReader(DATA / 'slope_hold' / 'input') as reader, \
            Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        (topic,) = reader.topics
        connection = writer.add_connection(topic, STATES_TYPE, typestore=store)
        assert 'sleeping' not in connection.msgdef.data
        for _, _, log_time, data in reader.raw():
            d = codec.decode(data)
            bodies = [t['collres_ros/msg/BodyState'](
                name, t['geometry_msgs/msg/Pose'](t['geometry_msgs/msg/Point'](*v[0:3]),
                                                  t['geometry_msgs/msg/Quaternion'](*v[3:7])),
                t['geometry_msgs/msg/Twist'](t['geometry_msgs/msg/Vector3'](*v[7:10]),
                                             t['geometry_msgs/msg/Vector3'](*v[10:13])))
                for name, v in zip(d.names, d.values.tolist())]
            header = t['std_msgs/msg/Header'](t['builtin_interfaces/msg/Time'](
                d.stamp_ns // 10**9, d.stamp_ns % 10**9), d.frame_id)
            writer.write(connection, log_time, bytes(store.serialize_cdr(
                t[STATES_TYPE](header, bodies), STATES_TYPE)))
            count += 1
    return count


def test_a_bag_recorded_before_sleeping_reads_and_replays_to_the_same_golden(
        tmp_path: Path) -> None:
    from collres_ros.ros.bag import read_messages
    from collres_ros.ros.offline import replay
    count = _old_bag(tmp_path / 'old')
    read = read_messages(tmp_path / 'old')
    assert len(read) == count > 100
    assert all(not b.sleeping for m in read for b in m.msg.bodies)
    summary = replay(tmp_path / 'old', tmp_path / 'out', SCENES / 'slope_hold.yaml',
                     topics=('body_states/corrected', 'contacts'))
    assert summary.steps == count and not summary.rejected
    _golden_matches(tmp_path / 'out')
