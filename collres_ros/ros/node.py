"""collres_node: resolve rigid-body contacts in a topic pipeline (a thin adapter on the core).

Run: ``collres_node --ros-args --params-file FILE`` (default file: the
package's ``config/collres.yaml``). Every parameter is declared with a
descriptor (description, type, range) generated from ``core/config.py``; the
scene comes from the same validator as ``params.load_scene``, so a bad file
stops the node at start with one line (``error: <parameter>: <why>``, exit
code 1). Solver settings, materials (restitution, static_friction,
kinetic_friction), the collision filter (``body.<name>.collision_group``,
``body.<name>.collision_mask``, ``ignore_pairs``) and node settings may change
at runtime and take effect on the next step; shapes, sizes, masses, poses and
the body list are read-only.
Range and type errors are refused by rclpy's descriptor check, naming the
parameter and its range; the rest (choices, kinetic <= static friction,
``ignore_pairs`` entries) by an on-set callback with the validator's one-line
reason.

Topics (relative names): in ``body_states`` (BodyStateArray, one step per
message) and ``bodies/<name>/pose`` + ``bodies/<name>/twist`` (a step when
every non-stale dynamic body has both for one stamp, see ``sync.py``); out
``body_states/corrected``, ``bodies/<name>/{pose,twist}/corrected`` (for
per-body steps), ``contacts``, ``contact_markers`` and ``body_markers`` (each of these
built only while someone subscribes), ``bodies/<name>/contact_wrench`` (with
``contact_wrench``), ``bodies/<name>/in_contact`` (with ``contact_state``), ``/tf``
(with ``publish_tf``, where tf2_msgs is installed), ``/diagnostics``; the service
``get_contacts`` answers the last step's contacts (``ros/contact_sensing.py``). The inputs
are served by threads of their own, not by the executor (``ros/inputs.py``): ``body_states``
and ``/tf``, ``/tf_static`` by one, the per-body subscriptions (a second node,
``<name>_per_body``, made for a body once its topics have a publisher) by another, each
taking every waiting message per wake-up; the ``body_states`` path costs the same whatever
the number of bodies' topics. The executor
serves parameters, services and the diagnostics timer.

The edge is raw CDR: the subscriptions take serialised bytes (``raw=True``),
``ros/codec.py`` decodes them with numpy straight into the core's arrays (no
Python message objects) after checking their size (more bodies than
``max_message_bodies``, a malformed message, a negative or unnormalised stamp:
refused at once and counted; bodies the scene does not know are refused one by
one, ``unknown_body``, and the known ones served), and every output is published
as bytes built by ``messages.OutputEncoder``, the answer
(``body_states/corrected``) first, before the other outputs are built. ``/diagnostics``
reports the callback's time split (``time.decode_ms``, ``time.resolve_ms``,
``time.world_ms``, ``time.world_cpu_ms``: the thread's CPU time in it,
``answer_time_mean_ms``: to the answer published, then
``time.encode_ms``, ``time.publish_ms``: the other outputs) and how long a ``body_states``
input waited between its reception by the DDS and its callback (``time.queued_ms``, mean,
``queued_max_ms``: a thread that waited for a core, for the lock or for the step before),
and whether the second thread took part (``threads.*``: the runs posted for two threads, the
share run paired and the share of their chunks the second thread ran).
Behind (a newer ``body_states``
input waits when a step is answered), that step's markers are skipped and counted
(``outputs_skipped_behind``); its answer, contacts, wrenches and ``/tf`` are always
published: every input is answered, no contact event is lost, the node catches up sooner.

QoS (``ros/qos.py``): reliable and volatile. The subscriptions keep the last
``queue_depth`` (10): a control loop wants every step delivered in order but never a
backlog of old states. The answers, contacts, wrenches and ``/tf`` keep the last 1000
(a reliable reader that falls behind, a recorder on a loaded machine, loses no step; a
volatile writer holds only what is not yet acknowledged); markers the last ``queue_depth``
(a viewer wants the newest). ``/diagnostics`` is reliable,
depth 10 (diagnostic_updater uses 1; ten let a slow aggregator miss no
report). Every publisher and subscription takes
rclpy's QoS overrides from the parameters (``qos_overrides./<topic>.
{publisher,subscription}.{history,depth,reliability,durability}``, ``ros/qos.py``).

Fast DDS (the default rmw): unless the user configured it, the node's process sends through
a 16 MB shared-memory segment (``config/fastdds_large_outputs.xml``; the builtin 512 KB
cannot hold a 1000-body step's outputs, and the next answer waited for room), see
``large_outputs_profile``.

Bad input never stops the node: it is refused per body (``core/validation``),
logged at most once a second per reason, counted in ``/diagnostics``; the
other bodies are still served. Time comes from the message stamps only, so
``use_sim_time`` works. SIGINT and SIGTERM shut the node down with exit 0.
"""

from __future__ import annotations

import gc
import os
import threading
import time
from collections import Counter
from functools import partial
from pathlib import Path
from typing import Any, Optional, Sequence

import numpy as np
import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped, TwistStamped, WrenchStamped
from rcl_interfaces.msg import SetParametersResult
from rclpy.clock import Clock, ClockType
from rclpy.event_handler import PublisherEventCallbacks
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from visualization_msgs.msg import MarkerArray

from collres_ros.core.pipeline import ResolvedStep, Resolver
from collres_ros.msg import BodyStateArray, ContactArray
from collres_ros.core.types import InputBatch
from collres_ros.ros import cli, codec, description, messages, names, params, qos
from collres_ros.ros.contact_sensing import ContactSensing
from collres_ros.ros.diagnostics import (DiagnosticsSnapshot, diagnostics_bytes, sleep_values,
                                         status_name)
from collres_ros.ros.health import Health
from collres_ros.ros.inputs import InputServer, PerBodyInputs, ServedElsewhere
from collres_ros.ros.losses import LossCounter
from collres_ros.ros.stamps import seconds_ns
from collres_ros.ros.tf_links import TfLinks, with_links
from collres_ros.ros.sync import StampSync, names_text

NAME = 'collres_node'
CLASSES = {messages.TYPES[names.CORRECTED_STATES]: BodyStateArray,
           messages.TYPES[names.CONTACTS]: ContactArray,
           messages.TYPES[names.MARKERS]: MarkerArray,
           messages.POSE_TYPE: PoseStamped, messages.TWIST_TYPE: TwistStamped,
           messages.WRENCH_TYPE: WrenchStamped}
try:   # /tf where tf2_msgs is installed (a ROS install; it is not on PyPI)
    from tf2_msgs.msg import TFMessage
    CLASSES[messages.TYPES[names.TF]] = TFMessage
except ImportError:
    pass
# The parts of a callback timed for /diagnostics (time.<part>_ms, means over the period):
# decode (CDR -> arrays), resolve (Resolver.resolve), world (World.step alone, inside
# resolve; world_cpu: the CPU time the thread had in it, the rest it waited for a core),
# encode and publish (every output after the answer, body_states/corrected, which goes out
# first: answer_time_mean_ms is from the callback's start to it published).
TIMED = ('decode', 'resolve', 'world', 'world_cpu', 'encode', 'publish')
LOG_PERIOD = 1.0   # s, at most one warning per reason per period
UNPAIRED_AFTER = 1.0   # s of per-body inputs without a per-body step before /diagnostics warns


def contact_state(settings: Any) -> tuple[bool, float, int]:
    """The in_contact settings of the node settings (a change restarts the states)."""
    return settings.contact_state, settings.contact_on_impulse, settings.contact_off_steps


def params_file_dir(argv: Sequence[str]) -> Optional[Path]:
    """Directory of the last ``--params-file`` in ``argv`` (relative mesh paths start there)."""
    path = cli.last_params_file(argv)
    return path.resolve().parent if path is not None else None


def default_params_file() -> Optional[Path]:
    from collres_ros.ros.resources import config_path
    try:
        return config_path('collres.yaml')
    except FileNotFoundError:
        return None


class CollresNode(Node):
    """The ROS adapter around ``Resolver`` (see module docstring)."""

    def __init__(self, base_dir: Optional[Path] = None, **kwargs: Any) -> None:
        super().__init__(NAME, automatically_declare_parameters_from_overrides=False, **kwargs)
        overrides = {name: params.plain_value(p.value)
                     for name, p in self._parameter_overrides.items()}
        if overrides.get('robot_description_topic') is True \
                and not overrides.get('robot_description'):
            overrides['robot_description'] = self._wait_for_robot_description()
        self.scene = params.scene_from_values(overrides, base_dir)   # ValueError: one line
        self._declare_parameters()
        self._pending: Optional[params.Scene] = None
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self.add_post_set_parameters_callback(self._after_set_parameters)
        self._steady = Clock(clock_type=ClockType.STEADY_TIME)
        # one step at a time: the per-body inputs' thread and the executor's callbacks share
        # the resolver, the sync and the counters
        self._lock = threading.RLock()
        self._last_log: dict[str, float] = {}
        self._suppressed: dict[str, int] = {}
        self.configured = False   # resolver, topics and timer exist (always, unless managed)
        self.serving = False      # inputs are resolved and answered (managed: while active)
        self.serving_since_ns = 0   # system time (ns) serving began (managed: activation)
        if not self.MANAGED:
            self.configure_resolution(serve=True)

    MANAGED = False   # ros/lifecycle.py: configure/activate through the lifecycle services

    def _wait_for_robot_description(self) -> str:
        """The URDF text of the first message on ``robot_description`` (transient local: the
        one robot_state_publisher holds), waited for with a log line every 5 s."""
        return description.wait_for(self, None, self.get_logger().info)

    def configure_resolution(self, serve: bool = False) -> None:
        """Create the resolver, the codecs, every topic and the diagnostics timer; then
        start serving inputs when ``serve`` (a managed node: when activated)."""
        self.resolver = Resolver.for_scene(self.scene)
        body_names = self.scene.names
        # the edge: CDR bytes in and out, decoded into and encoded from the core's arrays
        self.states_codec = codec.StatesCodec(max_bodies=self.scene.node.max_message_bodies)
        self.encoder = messages.OutputEncoder(body_names, self.scene.world_frame,
                                              self.scene.bodies)
        self.refused: Counter[str] = Counter()   # inputs refused before the resolver
        # bodies/<name>/in_contact (with contact_state) and the get_contacts service; the
        # service runs in the executor's thread, outside the step's lock: an encoder of its
        # own (the step's writes its last messages in place)
        self.contact_sensing = ContactSensing(self, body_names, messages.OutputEncoder(
            body_names, self.scene.world_frame, self.scene.bodies).contacts)
        self._configure_contact_state()
        statics = [b.name for b in self.scene.bodies if b.static]
        self.dynamic = [b.name for b in self.scene.bodies if not b.static]
        # a per-body step's bodies, in the scene's order (``messages.batch_from_group``)
        self._body_order = tuple(b.name for b in self.scene.bodies)
        self._dynamic_names = frozenset(self.dynamic)
        self.sync = StampSync(self.dynamic, statics, seconds_ns(self.scene.node.sync_slop),
                              seconds_ns(self.scene.node.stale_timeout))
        self._publishers_by_topic: dict[str, Any] = {}
        for topic, kind in ((names.CORRECTED_STATES, BodyStateArray),
                            (names.CONTACTS, ContactArray),
                            (names.MARKERS, MarkerArray),
                            (names.BODY_MARKERS, MarkerArray)):
            self._publisher(topic, kind)
        self._diagnostics = self.create_publisher(
            DiagnosticArray, names.DIAGNOSTICS, qos.state_qos(qos.DIAGNOSTICS_DEPTH),
            qos_overriding_options=qos.OVERRIDES)
        self.losses = LossCounter()   # inputs lost before they were taken (sequence gaps)
        # body_states (and /tf, /tf_static with a robot): the node's own subscriptions,
        # served by a thread of its own (inputs.py), not by the executor
        self._inputs = [self.create_subscription(
            BodyStateArray, names.STATES, self._on_states, self.state_qos(), raw=True,
            qos_overriding_options=qos.OVERRIDES, callback_group=ServedElsewhere())]
        self._served_inputs: list[tuple[Any, Any]] = [(self._inputs[0], self._on_states)]
        self.tf_links = self._subscribe_tf()
        self.states_input = InputServer(self, 'collres_states', lambda: self._served_inputs)
        self._timer = self._diagnostics_timer()
        self._window = self._new_window(time.monotonic())
        self.last_step: Optional[ResolvedStep] = None
        self.health = Health()
        self._served = 0                 # bodies served, all steps
        self._thread_runs = self.resolver.world.thread_runs   # at the last report
        self.skipped_behind = 0          # steps answered without their markers (behind)
        self._parts_since_step = 0       # per-body inputs since the last per-body step
        self._last_part_step = time.monotonic()
        self._reported: dict[str, Any] = {}   # what was logged once (slop, sync refusals)
        self.serving = serve
        self.per_body_inputs = PerBodyInputs(self, body_names)
        if self.MANAGED:   # configured by a transition: the executor spins already
            self.start_inputs()
        self.configured = True
        # what the start built (rclpy, numpy, the scene, the resolver, the codecs' layouts) is
        # out of the collector's passes from now on: a full collection walked it all, 37 ms at
        # 100 bodies, every few thousand steps, stalling the step it fell in
        gc.freeze()
        if self.scene.node.publish_tf and messages.TYPES[names.TF] not in CLASSES:
            self.get_logger().warning('publish_tf: tf2_msgs is not installed here: no /tf')
        self.get_logger().info(
            f'resolving {len(body_names)} bodies ({names_text(body_names)}) in frame '
            f'{self.scene.world_frame!r}')

    def start_inputs(self) -> None:
        """Start the input threads (``inputs.py``). An unmanaged node's main calls it once
        its executor exists, inside the shutdown handling that closes them: a thread left
        running in rcl while the process exits (a signal during the start) aborts it."""
        for server in (self.per_body_inputs.server, self.states_input):
            if server.thread.ident is None and not server.closing:   # never started
                server.start()

    def input_failure(self) -> Optional[BaseException]:
        """What ended an input thread (``inputs.py``), None while they serve."""
        return self.states_input.failure or self.per_body_inputs.failure

    def _subscribe_tf(self) -> Optional[TfLinks]:
        """With robot_description: /tf and /tf_static pose the static bodies named as their
        child frames, the links (tf_links.py); None without a robot or without tf2_msgs."""
        kind = CLASSES.get(messages.TYPES[names.TF])
        if not self.scene.values.get('robot_description') or kind is None:
            return None

        def pose(name: str) -> np.ndarray:   # a root of a chain: as the resolver holds it
            state, k = self.resolver.state, self.resolver.index_of[name]
            return np.concatenate([state.position[k], state.orientation[k]])

        links = TfLinks([b.name for b in self.scene.bodies if b.static], self.scene.names,
                        self.scene.world_frame, pose)
        for topic, profile in ((names.TF, qos.state_qos(100)),
                               (names.TF_STATIC, qos.tf_static_qos())):
            callback = partial(self._on_tf, topic)
            self._inputs.append(self.create_subscription(
                kind, topic, callback, profile, raw=True, callback_group=ServedElsewhere()))
            self._served_inputs.append((self._inputs[-1], callback))
        return links

    def _on_tf(self, topic: str, data: bytes, info: Any = None) -> None:
        """A /tf or /tf_static message (taken while configured, active or not: the links'
        poses are what the robot is, and /tf_static is sent once)."""
        with self._lock:
            try:
                self.tf_links.take(codec.decode_tf(data))
            except codec.DecodeError as refusal:
                self._refuse(refusal, topic)

    def release_resolution(self) -> None:
        """Undo ``configure_resolution``: every topic, the timer and the resolver go."""
        self.states_input.close()
        self.per_body_inputs.close()
        self.contact_sensing.close()
        self.serving = self.configured = False
        self.destroy_timer(self._timer)
        for subscription in self._inputs:
            self.destroy_subscription(subscription)
        for publisher in [*self._publishers_by_topic.values(), self._diagnostics]:
            self.destroy_publisher(publisher)
        self._inputs, self._publishers_by_topic, self._served_inputs = [], {}, []
        del self.resolver, self.sync, self.encoder, self.states_codec, self.tf_links
        self.last_step = None
        # what configure froze goes back to the collector, so that what is dropped here can
        # be freed (a managed node configured again freezes its new objects)
        gc.unfreeze()

    def destroy_node(self) -> None:
        if self.configured:   # the per-body inputs' thread stops first
            self.release_resolution()
        super().destroy_node()

    # --- parameters -------------------------------------------------------------------------

    def _declare_parameters(self) -> None:
        params.declare_scene(self, self.scene)

    def _on_set_parameters(self, parameters: list[Parameter]) -> SetParametersResult:
        changes = {p.name: params.plain_value(p.value) for p in parameters
                   if p.name not in params.ROS_BUILTIN
                   and not p.name.startswith(qos.OVERRIDE_PREFIX)}
        if not changes:
            return SetParametersResult(successful=True)
        try:
            self._pending = params.with_changes(self.scene, changes)
        except ValueError as error:
            return SetParametersResult(successful=False, reason=str(error))
        return SetParametersResult(successful=True)

    def _after_set_parameters(self, parameters: list[Parameter]) -> None:
        with self._lock:
            self._apply_parameters(parameters)

    def _apply_parameters(self, parameters: list[Parameter]) -> None:
        new, self._pending = self._pending, None
        if new is None:
            return
        old, self.scene = self.scene, new
        if not self.configured:   # a managed node applies them when configured
            return
        if new.solver != old.solver:
            self.resolver.settings = new.solver
        for before, after in zip(old.bodies, new.bodies):
            changed = {m: getattr(after, m) for m in params.MATERIALS
                       if getattr(after, m) != getattr(before, m)}
            if changed:
                self.resolver.set_material(after.name, **changed)
        if new.collision_filter != old.collision_filter:
            self.resolver.collision_filter = new.collision_filter
        self.resolver.stale_timeout = new.node.stale_timeout
        self.states_codec.max_bodies = new.node.max_message_bodies
        self.sync.slop_ns = seconds_ns(new.node.sync_slop)
        self.sync.stale_timeout_ns = seconds_ns(new.node.stale_timeout)
        if contact_state(new.node) != contact_state(old.node):
            self._configure_contact_state()
        if new.node.diagnostics_period != old.node.diagnostics_period:
            self.destroy_timer(self._timer)
            self._timer = self._diagnostics_timer()
        self.get_logger().info('parameters changed: ' + ', '.join(p.name for p in parameters))

    # --- inputs -----------------------------------------------------------------------------

    def _on_states(self, data: bytes, info: Any) -> None:
        with self._lock:
            self._take_states(data, info)

    def _take_states(self, data: bytes, info: Any) -> None:
        if not self.serves(info):
            return
        start, taken_ns = time.perf_counter(), time.time_ns()
        try:
            try:
                decoded = self.states_codec.decode(data)
            except codec.DecodeError as refusal:
                self._refuse(refusal, 'body_states')
                return
            batch = InputBatch(decoded.names, decoded.values, decoded.frame_id,
                               decoded.frame_id)
            self._step(decoded.stamp_ns, batch, False, start)
        finally:   # the input's bookkeeping, once its answer is out
            self._count_input(info, taken_ns)

    def _count_input(self, info: Any, taken_ns: int) -> None:
        """A ``body_states`` input taken at ``taken_ns`` (system time): how long it waited
        between its reception by the DDS and its callback, and the inputs lost before it
        (``losses.py``; the publisher count is an rmw query, 50 us a step in the node)."""
        received = info.get('received_timestamp', 0) if isinstance(info, dict) else 0
        if received > 0:   # from its reception by the DDS to its callback: waited, ns
            waited = (taken_ns - received) * 1e-9
            w = self._window
            w['queued'] += waited
            w['queued_max'] = max(w['queued_max'], waited)
            w['queued_inputs'] += 1
        self.losses.count(names.STATES, info, self._inputs[0].get_publisher_count())

    def serves(self, info: Any) -> bool:
        """Whether an input is served: while serving, and received after serving began (a
        managed node's input threads may take a message that arrived while it was inactive
        after its activation; the rmw's reception time says when it arrived)."""
        received = info.get('received_timestamp', 0) if isinstance(info, dict) else 0
        return self.serving and not (0 < received < self.serving_since_ns)

    def on_part(self, name: str, kind: str, data: bytes, info: Any) -> None:
        """A per-body pose or twist (bytes), from the per-body inputs' thread."""
        with self._lock:
            self._take_part(name, kind, data, info)

    def _take_part(self, name: str, kind: str, data: bytes, info: Any) -> None:
        if not self.serves(info):
            return
        start = time.perf_counter()
        self.losses.count(f'{name}/{kind}', info)
        self._parts_since_step += 1
        try:
            part = codec.decode_pose(data) if kind == 'pose' else codec.decode_twist(data)
        except codec.DecodeError as refusal:
            topic = names.pose_topic(name) if kind == 'pose' else names.twist_topic(name)
            self._refuse(refusal, topic)
            return
        groups = self.sync.add(name, kind, part.stamp_ns, part)
        jump = self.sync.take_jump()
        if jump is not None:
            backwards = jump.after_ns < jump.before_ns
            if backwards:
                self.resolver.restart()
            self.get_logger().warning(
                f'{jump.text()}: ' + ('a new run of the source; per-body sync and every '
                                      "body's history reset" if backwards else
                                      'bodies left behind turn stale'))
        for group in groups:
            self._parts_since_step = 0
            self._last_part_step = time.monotonic()
            batch = messages.batch_from_group(group.parts, self._dynamic_names,
                                              self._body_order)
            self._step(group.stamp_ns, batch, True, start)
            start = time.perf_counter()

    def _refuse(self, refusal: codec.DecodeError, topic: str) -> None:
        """A message refused before decoding into the core: counted, logged (rate-limited)."""
        self.refused[refusal.reason] += 1
        self._warn(refusal.reason, f'input refused [{refusal.reason}]: {topic}: {refusal}')

    # --- one step ---------------------------------------------------------------------------

    def _step(self, stamp: int, batch: InputBatch, per_body: bool, start: float) -> None:
        """Resolve, encode and publish one step; ``start``: when its callback began."""
        if self.tf_links is not None:   # the links /tf poses, unless the batch holds them
            batch = with_links(batch, self.tf_links.inputs())
        decoded = time.perf_counter()
        step = self.resolver.resolve(stamp, batch)
        resolved = time.perf_counter()
        # the answer first: the control loop waiting for it does not wait for the rest
        self._publisher(names.CORRECTED_STATES, BodyStateArray).publish(
            self.encoder.corrected(step))
        if per_body and self.scene.node.per_body_outputs:   # to the subscribed topics only
            self.per_body_inputs.publish(step, self.encoder)
        answered = time.perf_counter()
        # behind: a newer body_states input waits already; this step's pictures (contact
        # and body markers) are skipped and counted, so the node catches up sooner; its
        # data (the answer, contacts, wrenches, /tf) are always published
        more = not per_body and self.states_input.waiting(self._inputs[0])
        self.skipped_behind += more
        # what nobody subscribes to is not built
        markers = self._publisher(names.MARKERS, MarkerArray).get_subscription_count() > 0
        contacts = self._publisher(names.CONTACTS, ContactArray).get_subscription_count() > 0
        node = self.scene.node
        bodies = self._publisher(names.BODY_MARKERS, MarkerArray).get_subscription_count() > 0
        outputs = self.encoder.encode(
            step, per_body=False, marker_lifetime=node.marker_lifetime,
            markers=markers and not more, contacts=contacts,
            wrenches=node.contact_wrench,
            body_markers=node.body_markers_period if bodies and not more else None,
            tf=node.publish_tf and messages.TYPES[names.TF] in CLASSES,
            corrected=False)
        encoded = time.perf_counter()
        for topic, kind, data in outputs:
            self._publisher(topic, CLASSES[kind]).publish(data)
        done = time.perf_counter()
        self.last_step = step
        self.contact_sensing.step(step)
        self._served += len(step.names)
        w = self._window
        w['steps'] += 1
        w['time'] += step.step_time_s
        w['max'] = max(w['max'], step.step_time_s)
        w['decode'] += decoded - start
        w['resolve'] += resolved - decoded
        w['world'] += step.world_time_s
        w['world_cpu'] += step.world_cpu_s
        w['answer'] += answered - start
        w['encode'] += encoded - answered
        w['publish'] += done - encoded
        w['callback'] += done - start
        if any(step.budget) and 'budget' not in self._reported:
            self._reported['budget'] = True   # warned once; every such step is counted
            self.get_logger().warning(
                f'step over the contact budget: {step.budget[0]} pairs and {step.budget[1]} '
                'contact rows dropped, the deepest kept (solver.max_pairs '
                f'{self.scene.solver.max_pairs}, solver.max_contacts '
                f'{self.scene.solver.max_contacts}); counted as contact_budget in /diagnostics')
        for item in step.rejected:
            self._warn(item.reason, f'input refused [{item.reason}]: {item.detail}')
        happened = 'resumed asleep' if step.resumed_asleep else 'fresh start'
        for item in step.resets:
            self._warn(item.reason, f'{happened} [{item.reason}]: {item.detail}')

    def _configure_contact_state(self) -> None:
        node = self.scene.node
        self.contact_sensing.configure(node.contact_state, node.contact_on_impulse,
                                       node.contact_off_steps)

    def _publisher(self, topic: str, kind: type) -> Any:
        publisher = self._publishers_by_topic.get(topic)
        if publisher is None:
            if topic.startswith(names.BODIES):   # per body (contact_wrench): as PerBodyInputs
                profile = qos.overridden(self, self.resolve_topic_name(topic), 'publisher',
                                         self.publisher_qos(topic))
                publisher = self.create_publisher(kind, topic, profile, event_callbacks=(
                    PublisherEventCallbacks(use_default_callbacks=False)))
            else:
                publisher = self.create_publisher(kind, topic, self.publisher_qos(topic),
                                                  qos_overriding_options=qos.OVERRIDES)
            self._publishers_by_topic[topic] = publisher
        return publisher

    def state_qos(self) -> Any:
        """A new profile of the subscriptions (rclpy writes an entity's overrides into it)."""
        return qos.state_qos(self.scene.node.queue_depth)

    def publisher_qos(self, topic: str) -> Any:
        """A new profile of the publisher of ``topic`` (``qos.offered``)."""
        return qos.offered(topic, self.scene.node.queue_depth)

    def _warn(self, reason: str, text: str) -> None:
        """At most one warning per reason per LOG_PERIOD, with the count of the others."""
        now = time.monotonic()
        if now - self._last_log.get(reason, -LOG_PERIOD) < LOG_PERIOD:
            self._suppressed[reason] = self._suppressed.get(reason, 0) + 1
            return
        more = self._suppressed.pop(reason, 0)
        self._last_log[reason] = now
        suffix = f' (+{more} more since last report)' if more else ''
        self.get_logger().warning(f'{text}{suffix}')

    # --- diagnostics ------------------------------------------------------------------------

    def _diagnostics_timer(self) -> Any:
        return self.create_timer(self.scene.node.diagnostics_period, self._publish_diagnostics,
                                 clock=self._steady)

    def snapshot(self) -> DiagnosticsSnapshot:
        """Counters for /diagnostics (resets the rate window)."""
        w = self._window
        now = time.monotonic()
        elapsed = max(now - w['since'], 1e-9)
        totals = self.resolver.totals
        counts = {k: v for k, v in (totals + self.refused).items()
                  if k not in ('steps', 'contacts')}
        counts.update({k: v for k, v in self.sync.refused.items() if v})
        if self.sync.time_jumps:
            counts['time_jump'] = self.sync.time_jumps
        stale = sorted(set(self.sync.stale()) | set(self.last_step.stale if self.last_step
                                                    else ()))
        received = sum(self.losses.received.values())
        self.health.update(now, {**counts, 'steps': totals['steps'], 'inputs': received,
                                 'served': self._served, 'lost': self.losses.total_lost,
                                 'sync_dropped': self.sync.dropped}, elapsed)
        # silent for the whole window (and the stale timeout): nothing current to judge
        quiet = max(self.scene.node.stale_timeout,
                    self.health.window_reports * self.scene.node.diagnostics_period)
        status = self.health.status(now, quiet, self.scene.node.min_rate, stale,
                                    self._unpaired(now), self._slop_problem(),
                                    names_text(stale))
        self._log_sync_refusals()
        mean = (lambda key: f'{1e3 * w[key] / max(w["steps"], 1):.3f}')
        snap = DiagnosticsSnapshot(
            stamp_ns=self.get_clock().now().nanoseconds, steps=totals['steps'],
            rate_hz=w['steps'] / elapsed,
            step_time_mean_ms=1e3 * w['time'] / w['steps'] if w['steps'] else 0.0,
            step_time_max_ms=1e3 * w['max'],
            contacts=self.last_step.report.contacts.count if self.last_step else 0,
            counts=counts, stale=stale, status=status,
            name=status_name(self.get_fully_qualified_name()),
            extra={'bodies': len(self.scene.bodies), 'sync_dropped': self.sync.dropped,
                   'inputs_received': received, 'inputs_lost': self.losses.total_lost,
                   'body_states_publishers': self._inputs[0].get_publisher_count(),
                   'loss_counting': 'exact' if not self.losses.uncounted else (
                       'not inferred while several publishers share a topic: '
                       + ', '.join(sorted(self.losses.uncounted))),
                   'inputs_uncounted': sum(self.losses.uncounted.values()),
                   **{f'messages_refused.{k}': v for k, v in sorted(self.refused.items())},
                   'contacts_total': totals['contacts'],
                   'outputs_skipped_behind': self.skipped_behind,
                   'per_body_answers_published': self.per_body_inputs.published,
                   'per_body_inputs_subscribed': self.per_body_inputs.subscribed,
                   'callback_time_mean_ms': mean('callback'), 'window_steps': w['steps'],
                   'answer_time_mean_ms': mean('answer'),
                   'time.queued_ms': f'{1e3 * w["queued"] / max(w["queued_inputs"], 1):.3f}',
                   'queued_max_ms': f'{1e3 * w["queued_max"]:.3f}',
                   **{f'time.{key}_ms': mean(key) for key in TIMED},
                   **self._thread_values(),
                   **sleep_values(self.resolver)})
        self._window = self._new_window(now)
        return snap

    def _thread_values(self) -> dict[str, Any]:
        """/diagnostics values of the second thread (``threads``; resets the window):
        runs posted for two threads and those run paired, since start, and over the
        period the share of them run paired and the share of their chunks the second thread
        ran ('n/a' without such a run: one thread, or a scene too small to share)."""
        now = self.resolver.world.thread_runs
        runs, paired, chunks, helped = (a - b for a, b in zip(now, self._thread_runs))
        self._thread_runs = now
        return {'threads': self.resolver.world.threads, 'threads.runs': now[0],
                'threads.paired_runs': now[1],
                'threads.paired_share': f'{paired / runs:.3f}' if runs else 'n/a',
                'threads.second_share': f'{helped / chunks:.3f}' if chunks else 'n/a'}

    @staticmethod
    def _new_window(since: float) -> dict[str, float]:
        """Counters of one diagnostics period: steps, step times, callback parts (s)."""
        return {'steps': 0, 'time': 0.0, 'max': 0.0, 'callback': 0.0, 'answer': 0.0,
                'since': since, 'queued': 0.0, 'queued_max': 0.0, 'queued_inputs': 0,
                **{key: 0.0 for key in TIMED}}

    def _publish_diagnostics(self) -> None:
        """The report: its figures taken under the lock, its message built and published
        after it (an input waiting for the lock meanwhile waited 0.8 ms, up to 4 ms under
        load, with the message built from rclpy objects inside it)."""
        with self._lock:
            if not self.serving:
                return
            snapshot = self.snapshot()
        self._diagnostics.publish(diagnostics_bytes(snapshot))

    def _unpaired(self, now: float) -> str:
        """Why per-body inputs give no step, once they have not for UNPAIRED_AFTER s."""
        if not self._parts_since_step or now - self._last_part_step < UNPAIRED_AFTER:
            return ''
        reason = self.sync.unpaired()
        if reason:
            self._warn('unpaired', f'no per-body step for '
                       f'{now - self._last_part_step:.1f} s: {reason}')
        return reason

    def _slop_problem(self) -> str:
        """The slop warning (logged once per slop value)."""
        problem = self.sync.slop_problem() or ''
        if problem and self._reported.get('slop') != self.sync.slop_ns:
            self._reported['slop'] = self.sync.slop_ns
            self.get_logger().warning(problem)
        return problem

    def _log_sync_refusals(self) -> None:
        """Per-body messages refused for a stamp far from the others (logged when new)."""
        refused = dict(self.sync.refused)
        if refused != self._reported.get('sync_refused', {}):
            self._reported['sync_refused'] = refused
            self._warn('stray_stamp', 'per-body messages refused, stamps far from the others '
                       f'and never confirmed: {", ".join(f"{k} {v}" for k, v in refused.items())}')


def _check_files(argv: Sequence[str], read: bool = False) -> None:
    """The params files exist (``read``: and our reader reads them, the one-line reason rcl's
    cryptic parser error lacks): ValueError/OSError, one line."""
    for name in cli.params_files(argv):
        path = Path(name)
        if not path.is_file():
            raise FileNotFoundError(f'params file not found: {path}')
        if read:
            params.read_params_file(path, ())


def _print_help_if_asked(argv: Sequence[str]) -> bool:
    """``collres_node -h|--help`` (before any ``--ros-args``): print usage, True."""
    if not {'-h', '--help'} & set(_own_args(argv)):
        return False
    import argparse
    parser = argparse.ArgumentParser(
        prog=NAME, formatter_class=argparse.RawDescriptionHelpFormatter,
        usage=f'{NAME} [-h] [--lifecycle] [--ros-args --params-file FILE [-p NAME:=VALUE ...]]',
        description=__doc__, epilog='-p NAME:=VALUE (e.g. -p contact_wrench:=true) wins over '
        'the params file and the shipped ones. Parameters: see README.md, or print them with '
        '`python -m collres_ros.ros.params`. --lifecycle: run as a managed (lifecycle) node, '
        'unconfigured until its change_state service says otherwise (ros/lifecycle.py).')
    parser.print_help()
    return True


def _own_args(argv: Sequence[str]) -> list[str]:
    """The arguments before ``--ros-args`` (the program name excluded)."""
    return list(argv[1:argv.index('--ros-args')] if '--ros-args' in argv else argv[1:])


def _spin(argv: Sequence[str]) -> int:
    """Create the node in the initialised context and spin it until shutdown."""
    kind: type = CollresNode
    if '--lifecycle' in _own_args(argv):
        from collres_ros.ros.lifecycle import ManagedCollresNode
        kind = ManagedCollresNode
    # The start allocates some 10^5 objects that live as long as the node (a 1000-body
    # scene's parameters, descriptors, specs): the collector's passes over them while they
    # are made took 0.1-0.2 s of the start; what is built is frozen (``configure_resolution``)
    gc.disable()
    try:
        node = kind(params_file_dir(argv))
    except Exception as failure:
        if not rclpy.ok():   # SIGINT/SIGTERM shut the context down while the node was created
            return 0
        if isinstance(failure, (ValueError, OSError)):
            return cli.error(failure)
        raise
    finally:
        gc.enable()
    try:
        executor = SingleThreadedExecutor()
        executor.add_node(node)
        if node.configured:   # a managed node starts them when a transition configures it
            node.start_inputs()
        executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except Exception:
        if rclpy.ok():   # a real failure; otherwise a signal shut us down while starting
            raise
    finally:
        failure = node.input_failure() if node.configured else None
        node.destroy_node()
    if failure is not None:
        raise failure
    return 0


# Fast DDS's settings: one of these set means the user configured it (left alone)
FASTDDS_SETTINGS = ('FASTRTPS_DEFAULT_PROFILES_FILE', 'FASTDDS_DEFAULT_PROFILES_FILE',
                    'FASTDDS_BUILTIN_TRANSPORTS', 'RMW_FASTRTPS_USE_QOS_FROM_XML')
# the profiles Fast DDS loads from the working directory by itself
FASTDDS_FILES = ('DEFAULT_FASTRTPS_PROFILES.xml', 'DEFAULT_FASTDDS_PROFILES.xml')
FASTDDS_PROFILE = 'fastdds_large_outputs.xml'


def large_outputs_profile(environ: Any) -> Optional[str]:
    """Give this process's Fast DDS participant a 16 MB shared-memory segment for what it
    sends (``config/fastdds_large_outputs.xml``; the builtin is 512 KB) unless the rmw is
    another or the user configured Fast DDS: sets ``FASTRTPS_DEFAULT_PROFILES_FILE`` in
    ``environ`` before rclpy starts; returns the profile's path, or None.

    A step's outputs do not fit in 512 KB from a few hundred bodies in contact on (1000: the
    answer 0.12 MB, ``contacts`` 1.08 MB, ``contact_markers`` 0.54 MB): while a subscriber
    still holds the last step's, the next answer finds no room and is sent again late
    (``bench_latency.py``, 1000 bodies at 30 Hz: p99 136 -> 11 ms, lock-step 1.3 -> 529 Hz
    with this profile in the node's process only). Only the sender's segment counts, so the
    subscribers need nothing.
    """
    rmw = environ.get('RMW_IMPLEMENTATION', 'rmw_fastrtps_cpp') or 'rmw_fastrtps_cpp'
    if rmw != 'rmw_fastrtps_cpp' or any(environ.get(k) for k in FASTDDS_SETTINGS) \
            or any(Path(name).is_file() for name in FASTDDS_FILES):
        return None
    from collres_ros.ros.resources import config_path
    try:
        path = str(config_path(FASTDDS_PROFILE))
    except FileNotFoundError:
        return None
    environ['FASTRTPS_DEFAULT_PROFILES_FILE'] = path
    return path


def run(argv: list[str]) -> int:
    """``collres_node`` with ``argv`` (program name first): 0 on a clean shutdown, 1 on a bad
    configuration."""
    if _print_help_if_asked(argv):
        return 0
    large_outputs_profile(os.environ)
    if '--params-file' not in argv:
        default = default_params_file()
        if default is not None:   # first of the ROS arguments: `-p NAME:=VALUE` wins over it
            if '--ros-args' not in argv:
                argv += ['--ros-args']
            start = argv.index('--ros-args') + 1
            argv[start:start] = ['--params-file', str(default)]

    def run() -> int:
        _check_files(argv)
        # read by rcl in init; read again by ours only when rcl refuses them (0.2 s of a
        # 1000-body start when read every time)
        with cli.ros_init(args=argv, failure='cannot read parameters',
                          explain=lambda: _check_files(argv, read=True)):
            return _spin(argv)
    try:
        return cli.run(run)
    except (KeyboardInterrupt, ExternalShutdownException):
        return 0
