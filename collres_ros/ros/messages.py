"""ROS messages <-> the core's types, and the ONE builder of a step's output messages.

The node, the replay tool and the offline sim all call ``build_outputs``, so
what replay writes equals what the node publishes.

Twist frames (per-body topics): a ``TwistStamped`` whose ``header.frame_id``
is the body's own name (e.g. ``ball``) is in the body frame: linear velocity
of the body origin and angular velocity, both expressed in the body axes. A
frame_id equal to the world frame (or empty) means the world frame. Any other
frame is refused (``wrong_frame``). The corrected twist goes out in the frame
it came in. ``BodyStateArray`` twists are always in the world frame.
Poses must be in the world frame (no tf2 here).

Messages are plain rclpy classes: no node or context needed (they serialise
with ``rclpy.serialization``).
"""

from __future__ import annotations

from typing import Any, Container, Mapping, Optional, Sequence

import numpy as np
from geometry_msgs.msg import Point, PoseStamped, TwistStamped, Vector3
from std_msgs.msg import Header

from collres_ros.core.pipeline import ResolvedStep
from collres_ros.core.rotation import to_matrix
from collres_ros.core.types import BodyInput, BodyStates
from collres_ros.msg import BodyState, BodyStateArray, Contact, ContactArray
from collres_ros.ros.diagnostics import DiagnosticsSnapshot, diagnostics_array
from collres_ros.ros.markers import contact_markers
from collres_ros.ros.names import (  # noqa: F401 (the topic names, re-exported)
    CONTACTS, CORRECTED_STATES, DIAGNOSTICS, MARKERS, STATES, pose_topic, twist_topic)
from collres_ros.ros.stamps import stamp_ns, to_stamp  # noqa: F401 (re-exported)

__all__ = ['DiagnosticsSnapshot', 'diagnostics_array', 'contact_markers', 'stamp_ns', 'to_stamp']


# --- BodyStateArray: the one builder and reader -----------------------------------------------

def body_state_array(names: Sequence[str], states: BodyStates, stamp: int, frame_id: str,
                     rows: Optional[Sequence[int]] = None) -> BodyStateArray:
    """BodyStateArray of bodies ``rows`` (default: all) of ``states`` at ``stamp`` (ns)."""
    header = Header(stamp=to_stamp(stamp), frame_id=frame_id)
    bodies = []
    for k in (range(len(names)) if rows is None else rows):
        body = BodyState(name=names[k])
        p, q = body.pose.position, body.pose.orientation
        p.x, p.y, p.z = (float(c) for c in states.position[k])
        q.x, q.y, q.z, q.w = (float(c) for c in states.orientation[k])
        v, w = body.twist.linear, body.twist.angular
        v.x, v.y, v.z = (float(c) for c in states.linear[k])
        w.x, w.y, w.z = (float(c) for c in states.angular[k])
        bodies.append(body)
    return BodyStateArray(header=header, bodies=bodies)


def read_body_state_array(msg: BodyStateArray) -> tuple[list[str], BodyStates]:
    """(names, states) of a BodyStateArray's bodies, in message order (its frame: the header's)."""
    names = [body.name for body in msg.bodies]
    values = np.array([(b.pose.position.x, b.pose.position.y, b.pose.position.z,
                        b.pose.orientation.x, b.pose.orientation.y, b.pose.orientation.z,
                        b.pose.orientation.w, b.twist.linear.x, b.twist.linear.y,
                        b.twist.linear.z, b.twist.angular.x, b.twist.angular.y,
                        b.twist.angular.z) for b in msg.bodies], float).reshape(-1, 13)
    return names, BodyStates(values[:, 0:3].copy(), values[:, 3:7].copy(),
                             values[:, 7:10].copy(), values[:, 10:13].copy())


# --- inputs -----------------------------------------------------------------------------------

def _pose_tuple(pose: Any) -> tuple[tuple[float, ...], tuple[float, ...]]:
    p, q = pose.position, pose.orientation
    return (p.x, p.y, p.z), (q.x, q.y, q.z, q.w)


def _twist_tuple(twist: Any) -> tuple[tuple[float, ...], tuple[float, ...]]:
    v, w = twist.linear, twist.angular
    return (v.x, v.y, v.z), (w.x, w.y, w.z)


def inputs_from_array(msg: BodyStateArray) -> list[BodyInput]:
    """BodyInputs of a BodyStateArray (pose and twist in ``header.frame_id``)."""
    frame = msg.header.frame_id
    names, states = read_body_state_array(msg)
    return inputs_from_states(names, states, frame)


def inputs_from_states(names: Sequence[str], states: BodyStates, frame: str) -> list[BodyInput]:
    """BodyInputs of decoded states (pose and twist both in ``frame``)."""
    rows = np.concatenate([states.position, states.orientation, states.linear,
                           states.angular], axis=1).tolist()
    return [BodyInput(name, tuple(v[0:3]), tuple(v[3:7]),  # type: ignore[arg-type]
                      tuple(v[7:10]), tuple(v[10:13]), frame, frame)
            for name, v in zip(names, rows)]


def pose_twist_messages(msg: BodyStateArray) -> list[tuple[str, PoseStamped, TwistStamped]]:
    """(name, PoseStamped, TwistStamped) of each body of a BodyStateArray, its header each."""
    return [(body.name, PoseStamped(header=msg.header, pose=body.pose),
             TwistStamped(header=msg.header, twist=body.twist)) for body in msg.bodies]


def input_from_pose_twist(name: str, pose: PoseStamped, twist: TwistStamped) -> BodyInput:
    """BodyInput of one body's PoseStamped + TwistStamped (twist frame rule: module doc)."""
    position, orientation = _pose_tuple(pose.pose)
    linear, angular = _twist_tuple(twist.twist)
    return BodyInput(name, position, orientation, linear, angular,  # type: ignore[arg-type]
                     pose.header.frame_id, twist.header.frame_id)


# --- outputs ----------------------------------------------------------------------------------

def _point(v: np.ndarray) -> Point:
    return Point(x=float(v[0]), y=float(v[1]), z=float(v[2]))


def _vector(v: np.ndarray) -> Vector3:
    return Vector3(x=float(v[0]), y=float(v[1]), z=float(v[2]))


def corrected_array(step: ResolvedStep, world_frame: str) -> BodyStateArray:
    """body_states/corrected: the accepted bodies, world frame, at the step stamp."""
    return body_state_array(step.names, step.states, step.stamp_ns, world_frame)


def _per_body(step: ResolvedStep, array: BodyStateArray,
              world_frame: str) -> list[tuple[str, Any]]:
    """bodies/<name>/{pose,twist}/corrected; twists back in the frame they came in."""
    out: list[tuple[str, Any]] = []
    rotation = to_matrix(step.states.orientation) if step.twist_in_body.any() else None
    for k, body in enumerate(array.bodies):
        header = array.header
        pose = PoseStamped(header=header, pose=body.pose)
        twist = TwistStamped(header=header, twist=body.twist)
        if step.twist_in_body[k] and rotation is not None:
            twist = TwistStamped(header=Header(stamp=header.stamp, frame_id=body.name))
            twist.twist.linear = _vector(rotation[k].T @ step.states.linear[k])
            twist.twist.angular = _vector(rotation[k].T @ step.states.angular[k])
        out.append((pose_topic(body.name, True), pose))
        out.append((twist_topic(body.name, True), twist))
    return out


def contact_array(step: ResolvedStep, world_frame: str) -> ContactArray:
    """contacts: every solved contact, world frame, normal from body_a to body_b."""
    report = step.report
    c = report.contacts
    depth = c.depth
    contacts = []
    for k in range(c.count):
        a, b = step.contact_names(k)
        contacts.append(Contact(
            body_a=a, body_b=b, position=_point(c.point[k]), normal=_vector(c.normal[k]),
            depth=float(depth[k]), time_of_impact=to_stamp(int(step.toi_ns[k])),
            normal_impulse=float(report.normal_impulse[k]),
            friction_impulse=_vector(report.friction_impulse[k]),
            state=int(report.state[k])))
    return ContactArray(header=Header(stamp=to_stamp(step.stamp_ns), frame_id=world_frame),
                        contacts=contacts)


def build_outputs(step: ResolvedStep, world_frame: str, per_body: bool = False,
                  marker_lifetime: float = 0.5,
                  diagnostics: Optional[DiagnosticsSnapshot] = None,
                  markers: bool = True) -> list[tuple[str, Any]]:
    """Every output message of one step as (topic, message), topics relative to the node.

    Order: body_states/corrected, [per-body pose/twist corrected], contacts,
    [contact_markers], [/diagnostics when a snapshot is given]. ``markers``
    False skips the markers (the node does when nobody subscribes to them:
    they cost ~30 us per contact to build).
    """
    array = corrected_array(step, world_frame)
    out: list[tuple[str, Any]] = [(CORRECTED_STATES, array)]
    if per_body:
        out += _per_body(step, array, world_frame)
    out.append((CONTACTS, contact_array(step, world_frame)))
    if markers:
        out.append((MARKERS, contact_markers(step, world_frame, marker_lifetime)))
    if diagnostics is not None:
        out.append((DIAGNOSTICS, diagnostics_array(diagnostics)))
    return out


def inputs_from_group(parts: Mapping[str, Mapping[str, Any]], dynamic: Container[str]
                      ) -> list[BodyInput]:
    """BodyInputs of one synchronised per-body group ({name: {'pose': .., 'twist': ..}}).

    A dynamic body needs both its pose and its twist; a static body may publish
    its pose only (zero twist, in the pose's frame).
    """
    inputs = []
    for name, found in parts.items():
        pose, twist = found.get('pose'), found.get('twist')
        if pose is None or (twist is None and name in dynamic):
            continue
        if twist is None:
            twist = TwistStamped()
            twist.header.frame_id = pose.header.frame_id
        inputs.append(input_from_pose_twist(name, pose, twist))
    return inputs
