"""The step's output messages (the ONE builder) and ROS messages <-> the core's types.

``OutputEncoder`` builds every output of a step as serialised CDR bytes with
``codec`` (the node publishes them, replay and the offline sim write them to
bags: the same bytes everywhere); ``build_outputs`` is the same as rclpy
message objects, for tests and Python users. ``batch_from_group`` turns the
decoded per-body parts of one synchronised step into the core's arrays.

Twist frames (per-body topics): a ``TwistStamped`` whose ``header.frame_id``
is the body's own name (e.g. ``ball``) is in the body frame: linear velocity
of the body origin and angular velocity, both expressed in the body axes. A
frame_id equal to the world frame (or empty) means the world frame. Any other
frame is refused (``wrong_frame``). The corrected twist goes out in the frame
it came in. ``BodyStateArray`` twists are always in the world frame.
Poses must be in the world frame (no tf2 here).
"""

from __future__ import annotations

from typing import Any, Container, Mapping, Optional, Sequence

import numpy as np
from geometry_msgs.msg import PoseStamped, TwistStamped
from rclpy.serialization import deserialize_message

from collres_ros.core.pipeline import ResolvedStep
from collres_ros.core.rotation import to_matrix
from collres_ros.core.shapes import piece_names
from collres_ros.core.types import BodyInput, BodySpec, BodyStates, InputBatch
from collres_ros.core.wrench import contact_wrenches
from collres_ros.msg import BodyStateArray
from collres_ros.ros import codec
from collres_ros.ros.diagnostics import (DiagnosticsSnapshot, diagnostics_array,
                                         diagnostics_bytes)
from collres_ros.ros.markers import contact_marker_specs
from collres_ros.ros.names import (  # noqa: F401 (the topic names, re-exported)
    BODY_MARKERS, CONTACTS, CORRECTED_STATES, DIAGNOSTICS, MARKERS, STATES, TF, pose_topic,
    twist_topic, wrench_topic)
from collres_ros.ros.stamps import stamp_ns, to_stamp  # noqa: F401 (re-exported)

__all__ = ['DiagnosticsSnapshot', 'diagnostics_array', 'stamp_ns', 'to_stamp']


# --- BodyStateArray: the one builder and reader -----------------------------------------------

def state_values(states: BodyStates) -> np.ndarray:
    """(K, 13) rows of BodyStates: position, orientation, linear, angular (the wire order)."""
    return np.concatenate([states.position, states.orientation, states.linear,
                           states.angular], axis=1)


def states_of(values: np.ndarray) -> BodyStates:
    """BodyStates of (K, 13) rows (copies)."""
    v = np.asarray(values, float).reshape(-1, 13)
    return BodyStates(v[:, 0:3].copy(), v[:, 3:7].copy(), v[:, 7:10].copy(), v[:, 10:13].copy())


def body_state_array(names: Sequence[str], states: BodyStates, stamp: int, frame_id: str,
                     rows: Optional[Sequence[int]] = None) -> BodyStateArray:
    """BodyStateArray of bodies ``rows`` (default: all) of ``states`` at ``stamp`` (ns)."""
    index = np.arange(len(names)) if rows is None else np.asarray(rows, np.int64)
    data = codec.StatesCodec().encode(stamp, frame_id, [names[k] for k in index],
                                      state_values(states)[index])
    return deserialize_message(data, BodyStateArray)


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

TYPES = {
    STATES: 'collres_ros/msg/BodyStateArray', CORRECTED_STATES: 'collres_ros/msg/BodyStateArray',
    CONTACTS: 'collres_ros/msg/ContactArray',
    MARKERS: 'visualization_msgs/msg/MarkerArray',
    BODY_MARKERS: 'visualization_msgs/msg/MarkerArray', TF: 'tf2_msgs/msg/TFMessage',
    DIAGNOSTICS: 'diagnostic_msgs/msg/DiagnosticArray'}
POSE_TYPE, TWIST_TYPE = 'geometry_msgs/msg/PoseStamped', 'geometry_msgs/msg/TwistStamped'
WRENCH_TYPE = 'geometry_msgs/msg/WrenchStamped'


class OutputEncoder:
    """Every output of a step as (topic, wire type, CDR bytes), topics relative to the node.

    ``body_names``: the scene's N names (contacts index them). Layouts are
    cached here, so keep one encoder per scene (node, replay, offline sim).
    ``bodies``: the scene's N BodySpecs, for body_markers (None: no body markers).
    """

    def __init__(self, body_names: Sequence[str], world_frame: str,
                 bodies: Optional[Sequence[BodySpec]] = None) -> None:
        self.body_names = tuple(body_names)
        self.world_frame = world_frame
        self.states = codec.StatesCodec()
        self.names = codec.NamePool(self.body_names)
        # piece names of contacts: every body's pieces in one pool ('' for a body of one
        # shape; a triangle mesh's triangle_<k>), body k's from piece_start[k]; None
        # without compound bodies or triangle meshes (all '')
        self.piece_names: Optional[codec.NamePool] = None
        self.piece_start = np.zeros(len(self.body_names), np.int64)
        names = [piece_names(b) for b in bodies] if bodies is not None else []
        if any(n != [''] for n in names):
            self.piece_start = np.cumsum([0] + [len(n) for n in names[:-1]]).astype(np.int64)
            self.piece_names = codec.NamePool([n for group in names for n in group])
        # the scene's body markers, built when first asked for (``body_markers``): their
        # triangles took 25 ms of a 1000-body start, for a topic few subscribe to
        self._bodies = None if bodies is None else tuple(bodies)
        self._body_markers: Optional[Any] = None
        self._last_body_markers: Optional[int] = None   # stamp (ns) of the last ones
        # topic -> (the step its last message was built or restamped for, the lifetime of
        # its markers, the message): a step whose report is that step's (``ResolvedStep.
        # unchanged``: a sleeping pile's held contacts) only restamps it
        self._last: dict[str, tuple[int, float, codec.Restampable]] = {}
        # contacts of the last message's pairs: their numbers written into its buffer
        self._contacts = codec.ContactsEncoder()
        self._markers = codec.MarkersEncoder()   # markers likewise

    def body_markers(self, step: ResolvedStep, period: float, lifetime: float
                     ) -> Optional[bytes]:
        """body_markers (``body_markers.py``), or None when the last ones are younger than
        ``period`` s by stamp (a stamp going backwards starts again)."""
        last, now = self._last_body_markers, step.stamp_ns
        if self._bodies is None or (last is not None and 0 <= now - last
                                    < int(round(period * 1e9))):
            return None
        if self._body_markers is None:
            from collres_ros.ros.body_markers import BodyMarkers
            self._body_markers = BodyMarkers(self._bodies)
        self._last_body_markers = now
        life = int(round((lifetime + period) * 1e9))
        return codec.encode_markers(now, self.world_frame,
                                    self._body_markers.specs(step.poses, life))

    def tf(self, step: ResolvedStep) -> bytes:
        """/tf: world_frame -> every body at its corrected pose (TFMessage)."""
        return codec.encode_tf(step.stamp_ns, self.world_frame, self.names, step.poses)

    def corrected(self, step: ResolvedStep) -> bytes:
        """body_states/corrected: the accepted bodies, world frame, at the step stamp."""
        return self.states.encode(step.stamp_ns, self.world_frame, step.names, step.values,
                                  step.sleeping)

    def per_body(self, step: ResolvedStep) -> list[tuple[str, str, bytes]]:
        """bodies/<name>/{pose,twist}/corrected; twists back in the frame they came in."""
        every = np.ones((len(step.names), 2), bool)
        return [(pose_topic(step.names[k], True), POSE_TYPE, data) if kind == 0 else
                (twist_topic(step.names[k], True), TWIST_TYPE, data)
                for k, kind, data in self.per_body_wanted(step, every)]

    def per_body_wanted(self, step: ResolvedStep, wanted: np.ndarray
                        ) -> list[tuple[int, int, bytes]]:
        """The per-body answers ``wanted`` ((len(step.names), 2) bools: pose, twist) asks
        for, as (row of ``step.names``, 0 pose or 1 twist, bytes), by row then pose first;
        only those are encoded. Twists go back in the frame they came in."""
        s = step.states
        rows = np.flatnonzero(wanted.any(axis=1))
        poses = codec.encode_stamped(step.stamp_ns, self.world_frame,
                                     step.values[rows, 0:7])
        twist = step.values[rows, 7:13]   # a copy (rows taken)
        body = np.flatnonzero(step.twist_in_body[rows])
        if len(body):
            rotation = to_matrix(s.orientation[rows[body]])              # body -> world
            twist[body, 0:3] = np.einsum('kji,kj->ki', rotation, s.linear[rows[body]])
            twist[body, 3:6] = np.einsum('kji,kj->ki', rotation, s.angular[rows[body]])
        twists = codec.encode_stamped(step.stamp_ns, self.world_frame, twist)
        for j in body:
            twists[j] = codec.encode_twist(step.stamp_ns, step.names[rows[j]], twist[j])
        out = []
        for j, k in enumerate(rows):
            if wanted[k, 0]:
                out.append((int(k), 0, poses[j]))
            if wanted[k, 1]:
                out.append((int(k), 1, twists[j]))
        return out

    def contacts(self, step: ResolvedStep) -> bytes:
        """contacts: every solved contact, world frame, normal from body_a to body_b."""
        reused = self._reused(CONTACTS, step, 0.0)
        if reused is not None:   # the stamp and each contact's time of impact are new
            return reused.restamped(np.concatenate([[step.stamp_ns], step.toi_ns]))
        r = step.report
        c = r.contacts
        piece_a, piece_b = c.pieces()
        pieces = None if self.piece_names is None else (
            self.piece_names, self.piece_start[c.body_a] + piece_a,
            self.piece_start[c.body_b] + piece_b)
        message = self._contacts.message(step.stamp_ns, self.world_frame, self.names,
                                         c.body_a, c.body_b, c.point, c.normal, c.depth,
                                         step.toi_ns, r.normal_impulse, r.friction_impulse,
                                         r.state, pieces)
        self._last[CONTACTS] = (step.number, 0.0, message)
        return message.data()

    def wrenches(self, step: ResolvedStep) -> list[tuple[str, str, bytes]]:
        """bodies/<name>/contact_wrench of every body of the scene (zero without contacts):
        net contact force and torque about the centre of mass, world frame
        (``core/wrench.py``)."""
        values = contact_wrenches(step.report, step.poses[:, 0:3], step.dt)
        data = codec.encode_stamped(step.stamp_ns, self.world_frame, values)
        return [(wrench_topic(name), WRENCH_TYPE, d) for name, d in zip(self.body_names, data)]

    def markers(self, step: ResolvedStep, lifetime: float) -> bytes:
        """contact_markers (markers.py)."""
        reused = self._reused(MARKERS, step, lifetime)
        if reused is not None:
            return reused.restamped(step.stamp_ns)
        message = self._markers.message(step.stamp_ns, self.world_frame,
                                        contact_marker_specs(step, lifetime))
        self._last[MARKERS] = (step.number, lifetime, message)
        return message.data()

    def _reused(self, topic: str, step: ResolvedStep, lifetime: float
                ) -> Optional[codec.Restampable]:
        """The last message of ``topic`` when ``step``'s report is the one it was built from:
        built or reused for the step before, whose report this one's is (``ResolvedStep.
        unchanged``), with the same marker lifetime; None otherwise (it is built anew)."""
        last = self._last.get(topic)
        if last is None or not step.unchanged or last[0] != step.number - 1 \
                or last[1] != lifetime:
            return None
        self._last[topic] = (step.number, lifetime, last[2])
        return last[2]

    def encode(self, step: ResolvedStep, per_body: bool = False, marker_lifetime: float = 0.5,
               diagnostics: Optional[DiagnosticsSnapshot] = None,
               markers: bool = True, wrenches: bool = False,
               body_markers: Optional[float] = None, tf: bool = False,
               contacts: bool = True, corrected: bool = True
               ) -> list[tuple[str, str, bytes]]:
        """Every output of one step. Order: [body_states/corrected], [per-body pose/twist
        corrected], [contacts], [per-body contact_wrench], [contact_markers], [body_markers:
        when ``body_markers`` is a period (s) and it has passed], [/tf], [/diagnostics when
        a snapshot is given]."""
        out = [(CORRECTED_STATES, TYPES[CORRECTED_STATES], self.corrected(step))] \
            if corrected else []
        if per_body:
            out += self.per_body(step)
        if contacts:
            out.append((CONTACTS, TYPES[CONTACTS], self.contacts(step)))
        if wrenches:
            out += self.wrenches(step)
        if markers:
            out.append((MARKERS, TYPES[MARKERS], self.markers(step, marker_lifetime)))
        if body_markers is not None:
            data = self.body_markers(step, body_markers, marker_lifetime)
            if data is not None:
                out.append((BODY_MARKERS, TYPES[BODY_MARKERS], data))
        if tf:
            out.append((TF, TYPES[TF], self.tf(step)))
        if diagnostics is not None:
            out.append((DIAGNOSTICS, TYPES[DIAGNOSTICS],
                        diagnostics_bytes(diagnostics)))
        return out


_ENCODERS: dict[tuple[tuple[str, ...], str], OutputEncoder] = {}


def build_outputs(step: ResolvedStep, world_frame: str, per_body: bool = False,
                  marker_lifetime: float = 0.5,
                  diagnostics: Optional[DiagnosticsSnapshot] = None,
                  markers: bool = True, wrenches: bool = False) -> list[tuple[str, Any]]:
    """``OutputEncoder.encode`` as rclpy message objects: [(topic, message), ...]."""
    key = (tuple(step.body_names), world_frame)
    encoder = _ENCODERS.get(key)
    if encoder is None:
        if len(_ENCODERS) > 8:
            _ENCODERS.clear()
        encoder = _ENCODERS[key] = OutputEncoder(step.body_names, world_frame)
    from collres_ros.ros.bag import message_class
    return [(topic, deserialize_message(data, message_class(kind)))
            for topic, kind, data in encoder.encode(step, per_body, marker_lifetime,
                                                    diagnostics, markers, wrenches)]


def batch_from_group(parts: Mapping[str, Mapping[str, codec.Stamped]],
                     dynamic: Container[str], order: Sequence[str] = ()) -> InputBatch:
    """InputBatch of one synchronised per-body group of decoded parts.

    ``parts[name] = {'pose': Stamped, 'twist': Stamped}``. A dynamic body needs
    both; a static body may publish its pose only (zero twist, in the pose's
    frame). The bodies come in ``order`` (the scene's names), then any other in the order
    their parts came: a stream's steps list the same names in the same order whichever
    part came first, so its answer's layout is the cached one (at 100 bodies, parts in a
    shuffled order: 3.5 -> 2.9 ms a step of 200 parts in-process).
    """
    listed = [name for name in order if name in parts]
    if len(listed) < len(parts):
        known = set(order)
        listed += [name for name in parts if name not in known]
    names, rows, frames, twist_frames = [], [], [], []
    for name in listed:
        found = parts[name]
        pose, twist = found.get('pose'), found.get('twist')
        if pose is None or (twist is None and name in dynamic):
            continue
        names.append(name)
        rows.append(tuple(pose.values) + (tuple(twist.values) if twist is not None
                                          else (0.0,) * 6))
        frames.append(pose.frame_id)
        twist_frames.append(twist.frame_id if twist is not None else pose.frame_id)
    values = np.array(rows, float).reshape(len(rows), 13)
    # one frame for all (the usual group): given as one, the check of a stream's usual step
    # takes it whole (core/validation.py), not body by body
    return InputBatch(names, values, _one(frames), _one(twist_frames))


def _one(frames: list[str]) -> str | list[str]:
    """``frames``' one frame when every entry is that frame, else ``frames``."""
    return frames[0] if frames and len(set(frames)) == 1 else frames


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
