"""The numpy CDR codec (collres_ros/ros/codec.py) against rclpy's own serialisation.

Property tests (hypothesis), for random messages with empty, long and
non-ASCII names and empty arrays:

* decoding rclpy's bytes gives rclpy's values, bit for bit (NaN and Inf included);
* the codec's bytes decode with rclpy to the message encoded;
* the codec's bytes equal rclpy's bytes with the padding zero-filled. rclpy
  (Fast-CDR) leaves alignment padding uninitialised, so its raw bytes vary in
  those positions; the zero-filled reference is rclpy's bytes read and written
  again by rosbags' independent CDR serializer, which writes zeros there (and
  must leave every other byte as it was: the lengths are checked too).

Then the refusals: oversized, truncated, negative or unnormalised stamps.
"""

from __future__ import annotations

import struct

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

pytest.importorskip('rclpy')

from geometry_msgs.msg import PoseStamped, TwistStamped, WrenchStamped  # noqa: E402
from rclpy.serialization import deserialize_message, serialize_message  # noqa: E402
from visualization_msgs.msg import Marker, MarkerArray  # noqa: E402

from collres_ros.msg import BodyState, BodyStateArray, Contact, ContactArray  # noqa: E402
from collres_ros.ros import codec  # noqa: E402
from collres_ros.ros.bag import typestore  # noqa: E402

SETTINGS = settings(max_examples=60, deadline=None,
                    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
# names: empty, long, non-ASCII (no NUL: a ROS string ends at its first NUL)
NAMES = st.text(st.characters(blacklist_characters='\x00', blacklist_categories=('Cs',)),
                max_size=300)
FLOATS = st.floats(allow_nan=True, allow_infinity=True, width=64)
STAMPS = st.integers(0, 2**31 - 1).flatmap(
    lambda sec: st.integers(0, 999_999_999).map(lambda ns: sec * 10**9 + ns))


def zero_filled(data: bytes, msgtype: str) -> bytes:
    """rclpy's bytes with the alignment padding zeroed (a rosbags read and write)."""
    store = typestore()
    out = bytes(store.serialize_cdr(store.deserialize_cdr(data, msgtype), msgtype))
    assert len(out) == len(data)
    return out


def bits(values) -> np.ndarray:
    return np.ascontiguousarray(values, '<f8').view('<u8')


def stamp_of(ns: int):
    from builtin_interfaces.msg import Time
    return Time(sec=ns // 10**9, nanosec=ns % 10**9)


@st.composite
def body_state_arrays(draw):
    names = draw(st.lists(NAMES, max_size=12))
    values = np.array(draw(st.lists(st.lists(FLOATS, min_size=13, max_size=13),
                                    min_size=len(names), max_size=len(names))),
                      float).reshape(len(names), 13)
    sleeping = np.array(draw(st.lists(st.booleans(), min_size=len(names),
                                      max_size=len(names))), bool)
    return draw(STAMPS), draw(NAMES), names, values, sleeping


def rclpy_states(stamp: int, frame: str, names, values, sleeping=None) -> BodyStateArray:
    msg = BodyStateArray()
    msg.header.stamp, msg.header.frame_id = stamp_of(stamp), frame
    flags = [False] * len(names) if sleeping is None else list(map(bool, sleeping))
    for name, v, flag in zip(names, values.tolist(), flags):
        b = BodyState(name=name, sleeping=flag)
        p, q, t = b.pose.position, b.pose.orientation, b.twist
        p.x, p.y, p.z, q.x, q.y, q.z, q.w = v[0:7]
        t.linear.x, t.linear.y, t.linear.z, t.angular.x, t.angular.y, t.angular.z = v[7:13]
        msg.bodies.append(b)
    return msg


@SETTINGS
@given(body_state_arrays())
def test_body_state_array_both_ways(case) -> None:
    stamp, frame, names, values, sleeping = case
    theirs = bytes(serialize_message(rclpy_states(stamp, frame, names, values, sleeping)))
    for states in (codec.StatesCodec(), codec.StatesCodec()):   # parsed, then (2nd) cached
        for _ in range(2):
            got = states.decode(theirs)
            assert (got.stamp_ns, got.frame_id, got.names) == (stamp, frame, names)
            assert np.array_equal(bits(got.values), bits(values))
            assert got.sleeping.tolist() == sleeping.tolist() and not got.legacy
    ours = codec.StatesCodec().encode(stamp, frame, names, values, sleeping)
    assert ours == zero_filled(theirs, 'collres_ros/msg/BodyStateArray')
    back = deserialize_message(ours, BodyStateArray)
    assert [b.name for b in back.bodies] == names and back.header.frame_id == frame
    assert [b.sleeping for b in back.bodies] == sleeping.tolist()


# BodyState as it was before ``sleeping`` (what old bags embed and old publishers send)
LEGACY_BODY_STATE = '''string name
geometry_msgs/Pose pose
geometry_msgs/Twist twist
'''
LEGACY_ARRAY = '''std_msgs/Header header
collres_ros_legacy/BodyState[] bodies
'''


def legacy_bytes(stamp: int, frame: str, names, values) -> bytes:
    """A BodyStateArray serialised with the definition of before ``sleeping`` (rosbags)."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore
    store = get_typestore(Stores.ROS2_JAZZY)
    types = get_types_from_msg(LEGACY_BODY_STATE, 'collres_ros_legacy/msg/BodyState')
    types.update(get_types_from_msg(LEGACY_ARRAY, 'collres_ros_legacy/msg/BodyStateArray'))
    store.register(types)
    State = store.types['collres_ros_legacy/msg/BodyState']
    Array = store.types['collres_ros_legacy/msg/BodyStateArray']
    g = store.types
    header = g['std_msgs/msg/Header'](g['builtin_interfaces/msg/Time'](
        stamp // 10**9, stamp % 10**9), frame)
    bodies = []
    for name, v in zip(names, values.tolist()):
        pose = g['geometry_msgs/msg/Pose'](g['geometry_msgs/msg/Point'](*v[0:3]),
                                           g['geometry_msgs/msg/Quaternion'](*v[3:7]))
        twist = g['geometry_msgs/msg/Twist'](g['geometry_msgs/msg/Vector3'](*v[7:10]),
                                             g['geometry_msgs/msg/Vector3'](*v[10:13]))
        bodies.append(State(name, pose, twist))
    return bytes(store.serialize_cdr(Array(header, bodies),
                                     'collres_ros_legacy/msg/BodyStateArray'))


@SETTINGS
@given(body_state_arrays())
def test_body_state_array_without_sleeping_is_read_as_awake(case) -> None:
    """Old bags and publishers (no ``sleeping`` byte): decoded with the flags false, the
    same values; ``upgrade`` gives bytes rclpy reads as the same bodies, not sleeping."""
    stamp, frame, names, values, _ = case
    old = legacy_bytes(stamp, frame, names, values)
    states = codec.StatesCodec()
    for _ in range(2):   # parsed, then cached
        got = states.decode(old)
        assert (got.stamp_ns, got.frame_id, got.names) == (stamp, frame, names)
        assert np.array_equal(bits(got.values), bits(values))
        assert not got.sleeping.any() and got.legacy == bool(names)
    new = states.upgrade(old)
    assert new == codec.StatesCodec().encode(stamp, frame, names, values)
    back = deserialize_message(new, BodyStateArray)
    assert [b.name for b in back.bodies] == names
    assert not any(b.sleeping for b in back.bodies)
    current = codec.StatesCodec().encode(stamp, frame, names, values)
    assert states.upgrade(current) == current


@SETTINGS
@given(STAMPS, NAMES, st.lists(FLOATS, min_size=13, max_size=13))
def test_pose_and_twist_stamped_both_ways(stamp: int, frame: str, v: list) -> None:
    pose, twist = PoseStamped(), TwistStamped()
    pose.header.stamp = twist.header.stamp = stamp_of(stamp)
    pose.header.frame_id = twist.header.frame_id = frame
    p, q = pose.pose.position, pose.pose.orientation
    p.x, p.y, p.z, q.x, q.y, q.z, q.w = v[0:7]
    t = twist.twist
    t.linear.x, t.linear.y, t.linear.z, t.angular.x, t.angular.y, t.angular.z = v[7:13]
    for msg, decode, encode, n, kind in (
            (pose, codec.decode_pose, codec.encode_pose, slice(0, 7), 'PoseStamped'),
            (twist, codec.decode_twist, codec.encode_twist, slice(7, 13), 'TwistStamped')):
        theirs = bytes(serialize_message(msg))
        got = decode(theirs)
        assert (got.stamp_ns, got.frame_id) == (stamp, frame)
        assert np.array_equal(bits(got.values), bits(v[n]))
        ours = encode(stamp, frame, v[n])
        assert ours == zero_filled(theirs, f'geometry_msgs/msg/{kind}')
        assert codec.encode_stamped(stamp, frame, np.array([v[n]]))[0] == ours


@SETTINGS
@given(STAMPS, NAMES, st.lists(st.lists(FLOATS, min_size=6, max_size=6), max_size=4))
def test_wrench_stamped_encodes_as_rclpy(stamp: int, frame: str, rows: list) -> None:
    values = np.array(rows, float).reshape(len(rows), 6)
    batch = codec.encode_stamped(stamp, frame, values)
    assert len(batch) == len(rows)
    for v, ours in zip(rows, batch):
        msg = WrenchStamped()
        msg.header.stamp, msg.header.frame_id = stamp_of(stamp), frame
        f, t = msg.wrench.force, msg.wrench.torque
        f.x, f.y, f.z, t.x, t.y, t.z = v
        theirs = bytes(serialize_message(msg))
        assert ours == zero_filled(theirs, 'geometry_msgs/msg/WrenchStamped')
        assert codec.encode_wrench(stamp, frame, v) == ours
        back = deserialize_message(ours, WrenchStamped)
        assert back.header.frame_id == frame
        got = (back.wrench.force.x, back.wrench.force.y, back.wrench.force.z,
               back.wrench.torque.x, back.wrench.torque.y, back.wrench.torque.z)
        assert np.array_equal(bits(got), bits(v))


@st.composite
def contact_arrays(draw):
    pool = draw(st.lists(NAMES, min_size=1, max_size=6))
    pieces = draw(st.lists(NAMES, min_size=1, max_size=6))
    count = draw(st.integers(0, 12))
    index = st.integers(0, len(pool) - 1)
    piece = st.integers(0, len(pieces) - 1)
    rows = st.lists(FLOATS, min_size=11, max_size=11)
    return (draw(STAMPS), draw(NAMES), pool, pieces,
            np.array(draw(st.lists(index, min_size=count, max_size=count)), np.int64),
            np.array(draw(st.lists(index, min_size=count, max_size=count)), np.int64),
            np.array(draw(st.lists(piece, min_size=count, max_size=count)), np.int64),
            np.array(draw(st.lists(piece, min_size=count, max_size=count)), np.int64),
            np.array(draw(st.lists(rows, min_size=count, max_size=count)), float
                     ).reshape(count, 11),
            np.array(draw(st.lists(STAMPS, min_size=count, max_size=count)), np.int64),
            np.array(draw(st.lists(st.integers(0, 255), min_size=count, max_size=count)),
                     np.uint8))


@SETTINGS
@given(contact_arrays())
def test_contact_array_encodes_as_rclpy(case) -> None:
    stamp, frame, pool, pieces, a, b, pa, pb, v, toi, state = case
    ours = codec.encode_contacts(stamp, frame, codec.NamePool(pool), a, b, v[:, 0:3],
                                 v[:, 3:6], v[:, 6], toi, v[:, 7], v[:, 8:11], state,
                                 (codec.NamePool(pieces), pa, pb))
    msg = ContactArray()
    msg.header.stamp, msg.header.frame_id = stamp_of(stamp), frame
    for k in range(len(a)):
        c = Contact(body_a=pool[a[k]], body_b=pool[b[k]], piece_a=pieces[pa[k]],
                    piece_b=pieces[pb[k]], state=int(state[k]))
        c.position.x, c.position.y, c.position.z = v[k, 0:3].tolist()
        c.normal.x, c.normal.y, c.normal.z = v[k, 3:6].tolist()
        c.depth, c.normal_impulse = float(v[k, 6]), float(v[k, 7])
        c.friction_impulse.x, c.friction_impulse.y, c.friction_impulse.z = v[k, 8:11].tolist()
        c.time_of_impact = stamp_of(int(toi[k]))
        msg.contacts.append(c)
    theirs = bytes(serialize_message(msg))
    assert ours == zero_filled(theirs, 'collres_ros/msg/ContactArray')
    back = deserialize_message(ours, ContactArray)
    assert [(c.body_a, c.body_b, c.piece_a, c.piece_b, c.state) for c in back.contacts] == \
        [(c.body_a, c.body_b, c.piece_a, c.piece_b, c.state) for c in msg.contacts]
    # without pieces (no compound body) every piece name is ''
    alone = codec.encode_contacts(stamp, frame, codec.NamePool(pool), a, b, v[:, 0:3],
                                  v[:, 3:6], v[:, 6], toi, v[:, 7], v[:, 8:11], state)
    for c in msg.contacts:
        c.piece_a = c.piece_b = ''
    assert alone == zero_filled(bytes(serialize_message(msg)), 'collres_ros/msg/ContactArray')


@SETTINGS
@given(contact_arrays(), contact_arrays(), st.randoms(use_true_random=False))
def test_contacts_of_the_same_pairs_rewritten_in_place_are_a_fresh_encoding(
        case, other, rng) -> None:
    """One ``ContactsEncoder`` writes a message of the last message's pairs into that
    message's buffer (numbers and stamps only): every message of a sequence that keeps,
    changes and returns to a set of pairs, with new numbers, stamps and states each time,
    is the bytes ``encode_contacts`` gives it from scratch."""
    stamp, frame, pool, pieces, a, b, pa, pb, v, toi, state = case
    names, piece_names = codec.NamePool(pool), codec.NamePool(pieces)
    encoder = codec.ContactsEncoder()
    other_pairs = other[4:8] if len(pool) == len(other[2]) and len(pieces) == len(other[3]) \
        else (b, a, pb, pa)
    same = (a, b, pa, pb)
    # the same pairs; another body_b only; other pieces only; other pairs; the same again
    sequence = [same, same, (a, np.roll(b, 1), pa, pb), (a, b, np.roll(pa, 1), pb), same,
                (a, b, pa, np.roll(pb, 1)), other_pairs, same, same]
    for k, (ia, ib, ipa, ipb) in enumerate(sequence):
        count = len(ia)
        order = rng.sample(range(len(v)), len(v)) if len(v) else []
        values = (v[order] if len(v) else v)[:count] + k
        if len(values) < count:   # the other pairs have more rows: numbers of their own
            values = np.resize(values if len(values) else np.ones((1, 11)), (count, 11))
        times = (np.resize(toi, count) if len(toi) else np.zeros(count, np.int64)) - k
        states = (np.resize(state, count) if len(state) else np.zeros(count, np.uint8)) + k
        now = stamp + k * 10_000_000
        got = encoder.message(now, frame, names, ia, ib, values[:, 0:3], values[:, 3:6],
                              values[:, 6], times, values[:, 7], values[:, 8:11],
                              states.astype(np.uint8), (piece_names, ipa, ipb)).data()
        fresh = codec.encode_contacts(now, frame, names, ia, ib, values[:, 0:3],
                                      values[:, 3:6], values[:, 6], times, values[:, 7],
                                      values[:, 8:11], states.astype(np.uint8),
                                      (piece_names, ipa, ipb))
        assert got == fresh, k


@st.composite
def marker_specs(draw):
    specs = []
    for _ in range(draw(st.integers(0, 4))):
        count = draw(st.integers(0, 8))
        points = np.array(draw(st.lists(st.lists(FLOATS, min_size=3, max_size=3),
                                        min_size=count, max_size=count)), float
                          ).reshape(count, 3)
        colours = np.array(draw(st.lists(st.lists(st.floats(0, 1, width=32), min_size=4,
                                                  max_size=4), min_size=count,
                                         max_size=count)), np.float32).reshape(count, 4)
        specs.append(codec.MarkerSpec(
            action=draw(st.sampled_from([0, 2, 3])), type=draw(st.integers(0, 12)),
            ns=draw(NAMES), id=draw(st.integers(-2**31, 2**31 - 1)),
            pose=tuple(draw(st.lists(FLOATS, min_size=7, max_size=7))),
            scale=tuple(draw(st.lists(FLOATS, min_size=3, max_size=3))),
            color=tuple(draw(st.lists(st.floats(0, 1, width=32), min_size=4, max_size=4))),
            lifetime_ns=draw(st.integers(0, 10**12)), points=points, colors=colours))
    return draw(STAMPS), draw(NAMES), specs


@SETTINGS
@given(marker_specs())
def test_marker_array_encodes_as_rclpy(case) -> None:
    from builtin_interfaces.msg import Duration
    from geometry_msgs.msg import Point
    from std_msgs.msg import ColorRGBA
    stamp, frame, specs = case
    ours = codec.encode_markers(stamp, frame, specs)
    msg = MarkerArray()
    for s in specs:
        m = Marker(ns=s.ns, id=s.id, type=s.type, action=s.action)
        m.header.stamp, m.header.frame_id = stamp_of(stamp), frame
        p, q = m.pose.position, m.pose.orientation
        p.x, p.y, p.z, q.x, q.y, q.z, q.w = s.pose
        m.scale.x, m.scale.y, m.scale.z = s.scale
        m.color = ColorRGBA(r=s.color[0], g=s.color[1], b=s.color[2], a=s.color[3])
        m.lifetime = Duration(sec=s.lifetime_ns // 10**9, nanosec=s.lifetime_ns % 10**9)
        m.points = [Point(x=x, y=y, z=z) for x, y, z in s.points.tolist()]
        m.colors = [ColorRGBA(r=r, g=g, b=b, a=a) for r, g, b, a in s.colors.tolist()]
        msg.markers.append(m)
    theirs = bytes(serialize_message(msg))
    assert ours == zero_filled(theirs, 'visualization_msgs/msg/MarkerArray')


@SETTINGS
@given(marker_specs(), marker_specs())
def test_markers_of_new_points_rewritten_in_place_are_a_fresh_encoding(case, other) -> None:
    """One ``MarkersEncoder`` writes markers that differ from its last ones only in their
    points' and colours' values into the last message's buffer: every message of a sequence
    that moves the points, changes a lifetime, a point count or every marker, and moves the
    points again, is the bytes ``encode_markers`` gives it from scratch."""
    import dataclasses
    stamp, frame, specs = case

    def moved(markers, k):   # the same markers, other points and colours
        return [dataclasses.replace(m, points=m.points[::-1] + k, colors=m.colors[::-1] / 2)
                for m in markers]

    def changed(markers, **fields):   # the first marker's fields changed
        return [dataclasses.replace(markers[0], **fields)] + markers[1:] if markers \
            else markers
    first = specs[0] if specs else None
    sequence = [specs, moved(specs, 1), moved(specs, 2),
                changed(specs, lifetime_ns=first.lifetime_ns + 1) if first else specs,
                moved(specs, 3),
                changed(specs, points=np.zeros((len(first.points) + 1, 3))) if first
                else specs, other[2], moved(other[2], 4), specs, moved(specs, -1)]
    encoder = codec.MarkersEncoder()
    for k, markers in enumerate(sequence):
        now = stamp + k * 10_000_000
        assert encoder.message(now, frame, markers).data() == \
            codec.encode_markers(now, frame, markers), k


# --- refusals ---------------------------------------------------------------------------------

def _states(names, stamp=5 * 10**9) -> bytes:
    return codec.StatesCodec().encode(stamp, 'world', names,
                                      np.zeros((len(names), 13)))


def _refused(data: bytes, reason: str, max_bodies: int | None = 3) -> str:
    with pytest.raises(codec.DecodeError) as caught:
        codec.StatesCodec(max_bodies).decode(data)
    assert caught.value.reason == reason, caught.value
    text = str(caught.value)
    assert '\n' not in text
    return text


def test_more_bodies_than_the_scene_is_refused_before_reading_them() -> None:
    """A 12 MB message announcing 100,000 bodies: refused on its count."""
    big = _states([f'b{k}' for k in range(100_000)])
    assert len(big) > 10_000_000
    print(_refused(big, 'too_many_bodies'))
    # the same announcement with nothing behind it: refused the same way, nothing read
    head = codec.Writer()
    head.header(5, 'world')
    head.u32(100_000)
    _refused(head.bytes(), 'too_many_bodies')
    _refused(head.bytes(), 'malformed', max_bodies=None)   # truncated


def test_negative_and_unnormalised_stamps_are_refused_with_a_reason() -> None:
    """sec < 0 and nanosec >= 1e9 are refused, never clamped."""
    data = bytearray(_states(['ball']))
    negative = bytes(data[:4]) + struct.pack('<iI', -1, 5) + bytes(data[12:])
    print(_refused(negative, 'negative_stamp'))
    unnormalised = bytes(data[:4]) + struct.pack('<iI', 1, 1_000_000_000) + bytes(data[12:])
    print(_refused(unnormalised, 'invalid_nanosec'))
    pose = bytearray(codec.encode_pose(10**9, 'world', [0.0] * 6 + [1.0]))
    pose[4:12] = struct.pack('<iI', -3, 0)
    with pytest.raises(codec.DecodeError, match='negative'):
        codec.decode_pose(bytes(pose))
    # a known layout does not skip the check (the cached path)
    states = codec.StatesCodec(3)
    states.decode(bytes(data))
    with pytest.raises(codec.DecodeError) as caught:
        states.decode(negative)
    assert caught.value.reason == 'negative_stamp'


def test_a_stamped_message_of_a_frame_seen_before_decodes_as_the_first() -> None:
    """A stream's poses and twists after the first of their frame (read with one lookup):
    the same values and frame as read field by field, their stamps still checked, and bytes
    of one kind given as the other still refused."""
    values = [0.5, -1.0, 2.0, 0.0, 0.0, 0.6, 0.8]
    for frame in ('world', 'odom', ''):
        first = codec.decode_pose(codec.encode_pose(10**9, frame, values))
        pose = codec.encode_pose(2 * 10**9 + 7, frame, [v + 1.0 for v in values])
        again = codec.decode_pose(pose)
        assert (again.stamp_ns, again.frame_id) == (2 * 10**9 + 7, frame) == \
            (again.stamp_ns, first.frame_id)
        assert list(again.values) == [v + 1.0 for v in values]
        twist = codec.encode_twist(3 * 10**9, frame, values[:6])
        assert codec.decode_twist(twist).values == codec.decode_twist(twist).values \
            == tuple(values[:6])
        negative = bytearray(pose)
        negative[4:12] = struct.pack('<iI', -1, 0)
        with pytest.raises(codec.DecodeError) as caught:
            codec.decode_pose(bytes(negative))
        assert caught.value.reason == 'negative_stamp'
        with pytest.raises(codec.DecodeError, match='trailing'):
            codec.decode_twist(pose)


def test_malformed_messages_are_refused_not_crashed_on() -> None:
    data = _states(['ball', 'box'])
    for broken in (b'', b'\x00\x01', b'\x01\x00\x00\x00' + data[4:], data[:-1],
                   data + b'\x00' * 8, data[:20]):
        _refused(broken, 'malformed', max_bodies=None)
    bad_utf8 = data.replace(b'ball\x00', b'b\xffll\x00')
    assert bad_utf8 != data
    _refused(bad_utf8, 'malformed', max_bodies=None)
    with pytest.raises(codec.DecodeError):
        codec.decode_twist(b'\x00\x01\x00\x00' + b'\x00' * 10)


def test_payload_padded_to_4_bytes_between_processes_is_read() -> None:
    """Between processes rmw_fastrtps delivers a BodyStateArray (it ends with a bool) padded
    with zeros to a multiple of 4 (272 bytes for a message of 269): decoded as the message;
    a non-zero byte there, or 4 of them, is refused."""
    names, values = ['ball', 'box'], np.arange(26, dtype=float).reshape(2, 13)
    data = codec.StatesCodec().encode(5, 'world', names, values, np.array([True, False]))
    pad = -len(data) % 4
    assert pad   # 4 + header + bodies, the last one ending with its flag
    padded = data + bytes(pad)
    cached = codec.StatesCodec()
    cached.decode(data)
    for states in (codec.StatesCodec(), cached):   # parsed, and from a cached layout
        got = states.decode(padded)
        assert got.names == names and got.sleeping.tolist() == [True, False]
        assert np.array_equal(got.values, values)
    assert deserialize_message(padded, BodyStateArray).bodies[0].sleeping
    _refused(data + bytes(pad - 1) + b'\x01', 'malformed', max_bodies=None)
    _refused(data + bytes(pad + 4), 'malformed', max_bodies=None)


def legacy_contacts(stamp_ns: int, frame: str, rows: list[tuple]) -> bytes:
    """A ContactArray as recorded before Contact had piece_a / piece_b, written by hand:
    each row (body_a, body_b, 11 doubles: position, normal, depth, normal impulse,
    friction; toi ns; state)."""
    out = bytearray(b'\x00\x01\x00\x00')

    def align(k: int) -> None:
        out.extend(bytes(-(len(out) - 4) % k))

    def string(text: str) -> None:
        align(4)
        raw = text.encode() + b'\x00'
        out.extend(struct.pack('<I', len(raw)) + raw)
    out.extend(struct.pack('<iI', stamp_ns // 10**9, stamp_ns % 10**9))
    string(frame)
    align(4)
    out.extend(struct.pack('<I', len(rows)))
    for a, b, v, toi, state in rows:
        string(a)
        string(b)
        align(8)
        out.extend(struct.pack('<7d', *v[:7]))
        out.extend(struct.pack('<iI', toi // 10**9, toi % 10**9))
        out.extend(struct.pack('<4d', *v[7:]))
        out.append(state)
    return bytes(out)


def test_contacts_recorded_before_piece_names_read_with_empty_pieces() -> None:
    from collres_ros.ros.bag import _before_pieces
    rows = [('floor', 'ball', [0.1, 0.2, 0.3, 0.0, 0.0, 1.0, 1e-3, 0.5, 0.01, 0.02, 0.0],
             7 * 10**9 + 5, 2),
            ('ball', 'box_long_name', [1.0, 2.0, 3.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
             0, 1)]
    old = legacy_contacts(12 * 10**9 + 34, 'world', rows)
    msg = deserialize_message(codec.upgrade_contacts(old), ContactArray)
    assert (msg.header.frame_id, msg.header.stamp.sec, msg.header.stamp.nanosec) == \
        ('world', 12, 34)
    for c, (a, b, v, toi, state) in zip(msg.contacts, rows, strict=True):
        assert (c.body_a, c.body_b, c.piece_a, c.piece_b, c.state) == (a, b, '', '', state)
        assert [c.position.x, c.position.y, c.position.z, c.normal.x, c.normal.y, c.normal.z,
                c.depth, c.normal_impulse, c.friction_impulse.x, c.friction_impulse.y,
                c.friction_impulse.z] == v
        assert c.time_of_impact.sec * 10**9 + c.time_of_impact.nanosec == toi

    class Connection:   # what rosbags hands over: the recorded definition
        def __init__(self, text: str) -> None:
            self.msgdef = type('Definition', (), {'data': text})()
    assert _before_pieces(Connection('string body_a\nstring body_b\nfloat64 depth'))
    assert not _before_pieces(Connection('string body_a\nstring piece_a\n'))
    assert not _before_pieces(Connection(''))   # no definition recorded: read as today's
