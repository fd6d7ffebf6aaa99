"""Message conversion and the output builder (collres_ros/ros/messages.py)."""

from __future__ import annotations

import math

import pytest
from fake_world import FakeWorld, one_contact
from rclpy.serialization import deserialize_message, serialize_message

from collres_ros.ros import messages
from collres_ros.core.pipeline import Resolver
from collres_ros.msg import BodyState, BodyStateArray, ContactArray
from collres_ros.ros.params import scene_from_values
from geometry_msgs.msg import PoseStamped, TwistStamped
from visualization_msgs.msg import Marker, MarkerArray

T0 = 7 * 10**9 + 123


def scene():
    return scene_from_values({
        'bodies': ['floor', 'ball'], 'body.floor.shape': 'box',
        'body.floor.size': [10.0, 10.0, 0.2], 'body.floor.static': True,
        'body.ball.size': [0.1]})


def roundtrip(msg):
    return deserialize_message(serialize_message(msg), type(msg))


def test_stamp_conversion_is_exact():
    for ns in (0, 1, 999_999_999, 1_000_000_000, T0, 2**62):
        assert messages.stamp_ns(messages.to_stamp(ns)) == ns


def test_array_round_trip_to_inputs():
    msg = BodyStateArray()
    msg.header.frame_id = 'world'
    msg.header.stamp = messages.to_stamp(T0)
    state = BodyState(name='ball')
    state.pose.position.z = 1.25
    state.pose.orientation.w = 1.0
    state.twist.linear.x = -2.5
    state.twist.angular.y = 0.5
    msg.bodies = [state]
    inputs = messages.inputs_from_array(roundtrip(msg))
    assert len(inputs) == 1
    item = inputs[0]
    assert (item.name, item.frame_id, item.twist_frame_id) == ('ball', 'world', 'world')
    assert item.position == (0.0, 0.0, 1.25) and item.linear == (-2.5, 0.0, 0.0)
    assert item.angular == (0.0, 0.5, 0.0) and item.orientation == (0.0, 0.0, 0.0, 1.0)


def test_body_frame_twist_goes_out_in_the_body_frame():
    """A body-frame twist in, rotated to world inside, and back to the body frame out."""
    half = math.sqrt(0.5)   # 90 deg about z
    pose, twist = PoseStamped(), TwistStamped()
    pose.header.frame_id = 'world'
    pose.pose.orientation.z, pose.pose.orientation.w = half, half
    twist.header.frame_id = 'ball'
    twist.twist.linear.x = 1.0
    twist.twist.angular.x = 2.0
    s = scene()
    resolver = Resolver.for_scene(s, world=FakeWorld(s.bodies))
    step = resolver.resolve(T0, [messages.input_from_pose_twist('ball', pose, twist)])
    outputs = dict(messages.build_outputs(step, 'world', per_body=True))
    world = outputs['body_states/corrected'].bodies[0].twist
    assert (world.linear.x, world.linear.y) == pytest.approx((0.0, 1.0), abs=1e-12)
    back = roundtrip(outputs['bodies/ball/twist/corrected'])
    assert back.header.frame_id == 'ball'
    assert (back.twist.linear.x, back.twist.linear.y) == pytest.approx((1.0, 0.0), abs=1e-12)
    assert back.twist.angular.x == pytest.approx(2.0, abs=1e-12)
    pose_out = roundtrip(outputs['bodies/ball/pose/corrected'])
    assert pose_out.header.frame_id == 'world'
    assert messages.stamp_ns(pose_out.header.stamp) == T0


def test_outputs_of_a_step_with_a_contact():
    s = scene()
    world = FakeWorld(s.bodies)
    resolver = Resolver.for_scene(s, world=world)
    resolver.resolve(T0, [messages.inputs_from_array(_array(1.0))[0]])
    world.report = one_contact(0, 1, 0.5)
    step = resolver.resolve(T0 + 4_000_000, messages.inputs_from_array(_array(0.9)))
    outputs = messages.build_outputs(step, 'world')
    topics = [t for t, _ in outputs]
    assert topics == ['body_states/corrected', 'contacts', 'contact_markers']
    contacts = roundtrip(dict(outputs)['contacts'])
    assert isinstance(contacts, ContactArray) and len(contacts.contacts) == 1
    c = contacts.contacts[0]
    assert (c.body_a, c.body_b, c.state) == ('floor', 'ball', 1)
    assert messages.stamp_ns(c.time_of_impact) == T0 + 2_000_000
    assert c.depth == pytest.approx(0.001) and c.normal.z == 1.0
    assert c.normal_impulse == 0.5 and c.friction_impulse.x == 0.1
    markers = roundtrip(dict(outputs)['contact_markers'])
    assert isinstance(markers, MarkerArray)
    assert markers.markers[0].action == Marker.DELETEALL
    # a constant number of markers, the contacts as list markers, one per state
    assert len(markers.markers) == 11   # DELETEALL, points and normals of 5 states
    assert [(m.ns, m.id, m.type, m.action) for m in markers.markers[1:3]] == [
        ('contact_points', 1, Marker.SPHERE_LIST, Marker.ADD),
        ('contact_normals', 1, Marker.LINE_LIST, Marker.ADD)]
    assert markers.markers[1].lifetime.nanosec == 500_000_000
    assert len(markers.markers[1].points) == 1 and len(markers.markers[2].points) == 2
    assert markers.markers[1].color.r == pytest.approx(1.0)   # IMPACT: red
    assert {m.action for m in markers.markers[3:]} == {Marker.DELETE}   # no other state
    diag = messages.build_outputs(step, 'world', diagnostics=messages.DiagnosticsSnapshot(
        T0, steps=2, counts={'non_finite': 3}, stale=['box']))[-1]
    assert diag[0] == '/diagnostics'
    status = roundtrip(diag[1]).status[0]
    values = {kv.key: kv.value for kv in status.values}
    assert values['count.non_finite'] == '3' and values['stale_bodies'] == 'box'
    assert status.level == status.WARN


def test_outputs_never_hold_nan_for_bad_input():
    s = scene()
    resolver = Resolver.for_scene(s, world=FakeWorld(s.bodies))
    msg = _array(float('nan'))
    step = resolver.resolve(T0, messages.inputs_from_array(msg))
    array = dict(messages.build_outputs(step, 'world'))['body_states/corrected']
    assert [r.reason for r in step.rejected] == ['non_finite'] and array.bodies == []


def _array(z: float) -> BodyStateArray:
    msg = BodyStateArray()
    msg.header.frame_id = 'world'
    state = BodyState(name='ball')
    state.pose.position.z = z
    state.pose.orientation.w = 1.0
    msg.bodies = [state]
    return msg


def test_diagnostics_bytes_are_what_rclpy_serialises():
    """/diagnostics is encoded with the codec (no rclpy objects): the bytes decode, through
    rclpy, to the message ``diagnostics_array`` builds, unicode, an empty name list and a
    status with a window included; rclpy serialises that message to as many bytes (its
    padding bytes are uninitialised, so only the decoded messages are compared)."""
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.serialization import deserialize_message, serialize_message

    from collres_ros.ros.diagnostics import diagnostics_array, diagnostics_bytes
    from collres_ros.ros.health import Health
    health = Health()
    health.update(1.0, {'steps': 3, 'inputs': 4, 'unknown_body': 1}, 0.5)
    for snapshot in (
            messages.DiagnosticsSnapshot(stamp_ns=5 * 10**9 + 7, steps=3, counts={}),
            messages.DiagnosticsSnapshot(
                stamp_ns=12_345_678_901, steps=3, rate_hz=99.5, contacts=2,
                counts={'unknown_body': 1}, stale=['bäll', 'box'],
                status=health.status(1.0, 5.0, 0.0, ['box'], '', '', 'box'),
                name='/r1/collres_node: resolver', extra={'bodies': 3, 'note': 'ü'})):
        data = diagnostics_bytes(snapshot)
        built = diagnostics_array(snapshot)
        assert deserialize_message(data, DiagnosticArray) == built
        assert len(serialize_message(built)) == len(data)
