"""collres_ros.ros.bag: round trips through mcap and sqlite3 bags, independent readers."""

from __future__ import annotations

from pathlib import Path

import pytest

pytest.importorskip('rclpy')

from collres_ros.ros.bag import (BagError, BagReader, BagWriter, message_fields,  # noqa: E402
                                 read_messages, storage_of, typestore)


def _body_states(stamp_ns: int, z: float):
    from collres_ros.msg import BodyState, BodyStateArray
    msg = BodyStateArray()
    msg.header.frame_id = 'world'
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp_ns, 10**9)
    body = BodyState()
    body.name = 'ball'
    body.pose.position.z = z
    body.twist.linear.x = -1.5
    msg.bodies.append(body)
    return msg


def _contacts():
    from collres_ros.msg import Contact, ContactArray
    msg = ContactArray()
    msg.contacts.append(Contact(body_a='floor', body_b='ball', depth=0.001, normal_impulse=0.25,
                                state=Contact.RESTING))
    return msg


def _write(path: Path, storage: str, compress: bool = False) -> list:
    step = 4_166_667
    written = [('/body_states', 10**9 + i * step, _body_states(i * step, 1.0 - i))
               for i in range(3)]
    written.append(('/contacts', 2_000_000_000, _contacts()))
    with BagWriter(path, storage, compress) as writer:
        for topic, stamp, msg in written:
            writer.write(topic, stamp, msg)
    return written


@pytest.mark.parametrize('storage', ['mcap', 'sqlite3'])
def test_round_trip_decodes_the_same_fields(tmp_path: Path, storage: str) -> None:
    written = _write(tmp_path / 'bag', storage)
    assert storage_of(tmp_path / 'bag') == storage
    read = read_messages(tmp_path / 'bag')
    assert [(m.topic, m.log_time) for m in read] == [(t, s) for t, s, _ in written]
    for message, (_, _, original) in zip(read, written):
        assert message_fields(message.msg) == message_fields(original)
    with BagReader(tmp_path / 'bag') as reader:
        assert reader.topics == {'/body_states': 'collres_ros/msg/BodyStateArray',
                                 '/contacts': 'collres_ros/msg/ContactArray'}
        assert reader.topic_count('/body_states') == 3


@pytest.mark.parametrize('storage', ['mcap', 'sqlite3'])
def test_bag_opens_with_rosbags_alone(tmp_path: Path, storage: str) -> None:
    from rosbags.rosbag2 import Reader
    written = _write(tmp_path / 'bag', storage)
    store = typestore()
    with Reader(tmp_path / 'bag') as reader:
        decoded = [store.deserialize_cdr(data, c.msgtype)
                   for c, _, data in reader.messages()]
        assert all(c.msgdef.data for c in reader.connections)  # definitions embedded
    assert decoded[2].bodies[0].pose.position.z == written[2][2].bodies[0].pose.position.z
    assert decoded[3].contacts[0].normal_impulse == 0.25


@pytest.mark.parametrize('compress', [False, True])
def test_mcap_opens_with_the_independent_mcap_reader(tmp_path: Path, compress: bool) -> None:
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory
    _write(tmp_path / 'bag', 'mcap', compress)
    (file,) = (tmp_path / 'bag').glob('*.mcap')
    with open(file, 'rb') as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        decoded = [(channel.topic, schema.name, msg)
                   for schema, channel, _, msg in reader.iter_decoded_messages()]
    assert [d[1] for d in decoded] == ['collres_ros/msg/BodyStateArray'] * 3 + [
        'collres_ros/msg/ContactArray']
    assert decoded[1][2].bodies[0].twist.linear.x == -1.5
    assert decoded[3][2].contacts[0].state == 2


def test_errors_are_one_line_bag_errors(tmp_path: Path) -> None:
    with pytest.raises(BagError, match='bag not found'):
        BagReader(tmp_path / 'missing')
    with pytest.raises(BagError, match='unknown storage'):
        BagWriter(tmp_path / 'out', 'hdf5')
    _write(tmp_path / 'bag', 'mcap')
    with pytest.raises(BagError, match='already exists'):
        BagWriter(tmp_path / 'bag', 'mcap')
    meta = tmp_path / 'bag' / 'metadata.yaml'
    meta.write_text(meta.read_text().replace('storage_identifier: mcap',
                                             'storage_identifier: foo'))
    with pytest.raises(BagError, match="unknown storage 'foo'"):
        BagReader(tmp_path / 'bag')
