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

from dataclasses import dataclass, field
from typing import Any, Container, Mapping, Optional, Sequence

import numpy as np
from builtin_interfaces.msg import Duration, Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import Point, PoseStamped, TwistStamped, Vector3
from std_msgs.msg import ColorRGBA, Header
from visualization_msgs.msg import Marker, MarkerArray

from collres_ros.core.pipeline import ResolvedStep
from collres_ros.core.rotation import to_matrix
from collres_ros.core.types import BodyInput, ContactState
from collres_ros.msg import BodyState, BodyStateArray, Contact, ContactArray

# Relative output topic names (the node publishes them in its namespace).
CORRECTED_STATES = 'body_states/corrected'
CONTACTS = 'contacts'
MARKERS = 'contact_markers'
DIAGNOSTICS = '/diagnostics'


def pose_topic(name: str, corrected: bool = False) -> str:
    return f'bodies/{name}/pose' + ('/corrected' if corrected else '')


def twist_topic(name: str, corrected: bool = False) -> str:
    return f'bodies/{name}/twist' + ('/corrected' if corrected else '')


# --- time -------------------------------------------------------------------------------------

def stamp_ns(stamp: Any) -> int:
    """builtin_interfaces/Time -> integer ns."""
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def to_stamp(ns: int) -> Time:
    """Integer ns -> builtin_interfaces/Time (negative times clamp to 0)."""
    sec, nanosec = divmod(max(int(ns), 0), 1_000_000_000)
    return Time(sec=sec, nanosec=nanosec)


def _duration(seconds: float) -> Duration:
    sec, nanosec = divmod(int(round(seconds * 1e9)), 1_000_000_000)
    return Duration(sec=sec, nanosec=nanosec)


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
    inputs = []
    for body in msg.bodies:
        position, orientation = _pose_tuple(body.pose)
        linear, angular = _twist_tuple(body.twist)
        inputs.append(BodyInput(body.name, position, orientation,  # type: ignore[arg-type]
                                linear, angular, frame, frame))
    return inputs


def input_from_pose_twist(name: str, pose: PoseStamped, twist: TwistStamped) -> BodyInput:
    """BodyInput of one body's PoseStamped + TwistStamped (twist frame rule: module doc)."""
    position, orientation = _pose_tuple(pose.pose)
    linear, angular = _twist_tuple(twist.twist)
    return BodyInput(name, position, orientation, linear, angular,  # type: ignore[arg-type]
                     pose.header.frame_id, twist.header.frame_id)


# --- outputs ----------------------------------------------------------------------------------

STATE_COLOURS = {
    ContactState.IMPACT: (1.0, 0.2, 0.1), ContactState.RESTING: (0.2, 0.6, 1.0),
    ContactState.SLIDING: (1.0, 0.8, 0.1), ContactState.STICKING: (0.2, 0.9, 0.3)}
POINT_DIAMETER = 0.02   # m, contact point sphere
ARROW_LENGTH = 0.1      # m, normal arrow


def _point(v: np.ndarray) -> Point:
    return Point(x=float(v[0]), y=float(v[1]), z=float(v[2]))


def _vector(v: np.ndarray) -> Vector3:
    return Vector3(x=float(v[0]), y=float(v[1]), z=float(v[2]))


def corrected_array(step: ResolvedStep, world_frame: str) -> BodyStateArray:
    """body_states/corrected: the accepted bodies, world frame, at the step stamp."""
    s = step.states
    header = Header(stamp=to_stamp(step.stamp_ns), frame_id=world_frame)
    bodies = []
    for k, name in enumerate(step.names):
        body = BodyState(name=name)
        p, q = body.pose.position, body.pose.orientation
        p.x, p.y, p.z = (float(c) for c in s.position[k])
        q.x, q.y, q.z, q.w = (float(c) for c in s.orientation[k])
        v, w = body.twist.linear, body.twist.angular
        v.x, v.y, v.z = (float(c) for c in s.linear[k])
        w.x, w.y, w.z = (float(c) for c in s.angular[k])
        bodies.append(body)
    return BodyStateArray(header=header, bodies=bodies)


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


def contact_markers(step: ResolvedStep, world_frame: str,
                    lifetime: float = 0.5) -> MarkerArray:
    """contact_markers: DELETEALL, then a sphere and a normal arrow per contact.

    Namespace per body pair (``a/b``); ids count the pair's points (point 2k,
    arrow 2k+1). Each marker also has ``lifetime`` (s; 0 = forever).
    """
    header = Header(stamp=to_stamp(step.stamp_ns), frame_id=world_frame)
    markers = [Marker(header=header, action=Marker.DELETEALL)]
    c = step.report.contacts
    seen: dict[str, int] = {}
    life = _duration(lifetime)
    for k in range(c.count):
        a, b = step.contact_names(k)
        namespace = f'{a}/{b}'
        n = seen.get(namespace, 0)
        seen[namespace] = n + 1
        r, g, bl = STATE_COLOURS.get(ContactState(int(step.report.state[k])), (1.0, 1.0, 1.0))
        colour = ColorRGBA(r=r, g=g, b=bl, a=1.0)
        # check_fields=False: the fields are typed here; rclpy's checks cost ~100 us a marker
        point = Marker(header=header, ns=namespace, id=2 * n, type=Marker.SPHERE,
                       action=Marker.ADD, color=colour, lifetime=life, check_fields=False)
        point.pose.position = _point(c.point[k])
        point.scale = Vector3(x=POINT_DIAMETER, y=POINT_DIAMETER, z=POINT_DIAMETER)
        arrow = Marker(header=header, ns=namespace, id=2 * n + 1, type=Marker.ARROW,
                       action=Marker.ADD, color=colour, lifetime=life,
                       points=[_point(c.point[k]),
                               _point(c.point[k] + ARROW_LENGTH * c.normal[k])],
                       check_fields=False)
        arrow.scale = Vector3(x=0.005, y=0.01, z=0.02)  # shaft, head diameters, head length
        markers += [point, arrow]
    return MarkerArray(markers=markers)


@dataclass
class DiagnosticsSnapshot:
    """What /diagnostics reports; counts are cumulative since start, by reason key."""

    stamp_ns: int
    steps: int = 0
    rate_hz: float = 0.0              # steps per second of wall time since the last report
    step_time_mean_ms: float = 0.0
    step_time_max_ms: float = 0.0
    contacts: int = 0                 # in the last step
    counts: Mapping[str, int] = field(default_factory=dict)   # rejections/resets by reason
    stale: Sequence[str] = ()
    extra: Mapping[str, Any] = field(default_factory=dict)
    name: str = 'collres_node: resolver'


def diagnostics_array(snapshot: DiagnosticsSnapshot) -> DiagnosticArray:
    """One DiagnosticStatus: WARN when bodies are stale or inputs were refused."""
    problems = {k: v for k, v in snapshot.counts.items() if v}
    level = DiagnosticStatus.OK
    message = f'{snapshot.steps} steps, {snapshot.rate_hz:.1f} Hz'
    if snapshot.stale:
        level = DiagnosticStatus.WARN
        message += f'; stale: {", ".join(snapshot.stale)}'
    if problems:
        level = DiagnosticStatus.WARN
        message += '; refused/reset inputs: ' + ', '.join(
            f'{k} {v}' for k, v in sorted(problems.items()))
    values = {
        'steps': snapshot.steps, 'rate_hz': f'{snapshot.rate_hz:.3f}',
        'step_time_mean_ms': f'{snapshot.step_time_mean_ms:.3f}',
        'step_time_max_ms': f'{snapshot.step_time_max_ms:.3f}',
        'contacts_last_step': snapshot.contacts,
        'stale_bodies': ','.join(snapshot.stale),
        **{f'count.{k}': v for k, v in sorted(snapshot.counts.items())},
        **snapshot.extra}
    status = DiagnosticStatus(level=level, name=snapshot.name, message=message,
                              hardware_id='collres_ros',
                              values=[KeyValue(key=k, value=str(v)) for k, v in values.items()])
    return DiagnosticArray(header=Header(stamp=to_stamp(snapshot.stamp_ns)), status=[status])


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
