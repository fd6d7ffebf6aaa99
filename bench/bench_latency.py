"""collres_node over DDS on a settled pile: rate sustained, drops, latency, callback split.

    .venv/bin/python bench/bench_latency.py [--sizes 10 100 1000] [--rates 100 100 30]
        [--duration 10] [--settle 2.0] [--modes estimator simulator] [--no-echo]
        [--sleeping on off] [--start-only RUNS]

For each size the pile of bench/pile.py is settled in-process with the core
(120 Hz, semi-implicit Euler), written as a params file, and then three
processes talk over real DDS on localhost in a private ROS_DOMAIN_ID:

* ``collres_node`` on that scene. Its start-up time is printed: from the process start
  to its first answer, in a probe run of its own (``first_answer``: this process sends the
  pile's input every 20 ms from the start; ``--start-only RUNS``: only that, RUNS times per
  size), and, in brackets, to every topic of the run connected;
* a publisher (this file, ``--role publisher``) in one of two modes
  (``--modes``): ``estimator``, the settled pile as an estimator measures it at rest
  (its poses, zero twists: ``input_bytes``) as pre-serialised
  BodyStateArray bytes with a new stamp each step, inputs independent of the
  answers; ``simulator``, each input the latest answer integrated one step (semi-implicit
  Euler with gravity, collres_sim's integrator; see ``Inputs``); ``per_body``, the
  estimator's inputs as ``bodies/<name>/pose`` and ``twist`` messages (the
  node steps once every body has both). First lock-step
  (publish, wait for the answer, repeat: the highest rate the node sustains),
  then paced at the given rate (``--rates``, one per size) for ``--duration`` s;
* this process: subscribers of ``body_states/corrected``, ``contacts`` and
  ``contact_markers`` (so the node builds and publishes all of them) and of
  ``/diagnostics`` (the node's own timing figures).

The in-process reference of ``World.step``: the node's own steps again, in this process:
the same scene (read back from the params file), every input the node answered, in order
(the same stamps, so the same dt and the same long steps across inputs it never took), each
built by the publisher's rule from the answer it was built from live (simulator mode: the
publisher records which), stepped by a ``Resolver`` (wall and thread CPU time, median over
the paced part). The core is deterministic, so these are the node's steps; the node's
``time.world_ms`` and ``time.world_cpu_ms`` beside it say what the live run adds to them:
the CPU time it lacks is time it waited for a core.

The echo floor: the same publisher against an echo process (``--role echo``:
subscribe ``body_states`` as bytes, publish them back on
``body_states/corrected``), in the same run, before the node; what the node
adds beyond it is ours.

Latency is publish to reception of the step's ``body_states/corrected``
(CLOCK_MONOTONIC, shared by the processes); ``send`` is the publisher's own part of it, the
time its ``publish`` calls took to hand the step over (in ``per_body`` mode the 2 x bodies
messages one after another, in Python). Dropped = paced steps without an answer. The node's
callback split comes from its ``/diagnostics`` values:
``time.decode_ms``, ``time.resolve_ms`` (Resolver.resolve), ``time.world_ms``
(World.step alone), ``time.encode_ms``, ``time.publish_ms`` and
``callback_time_mean_ms``; an older node reports only the callback and
``step_time_mean_ms`` (resolve), so the others show ``n/a``.

``--sleeping``: the node runs with ``solver.sleeping`` on (the default) and/or off (every
step detected and solved); the row says which, and how many bodies the node's last
/diagnostics reported asleep. The pile falls asleep in the lock-step run once the node has
answered ``time_to_sleep`` (0.5 s) of stamps of a still pile, 50 steps at 100 Hz; with
sleeping on, the lock-step goes on past ``--lockstep`` until an answer holds every body
still (``--until-rest``), so the paced run measures the settled, asleep pile: a lock-step of
fixed wall time ended, on a loaded machine, after 17-82 awake 1000-body steps (the pile
needs ~42 at 30 Hz), and the paced run then measured the awake solver (an awake 1000-body
step at 30 Hz costs more than the 33 ms period, and the node never caught up). The row's
``lock-step`` cell says how many steps that took and whether the pile was still.

A simulator that integrates its own state when an answer is late (collres_sim
--realtime) wakes the asleep pile with one late answer: its next input is the last answer
integrated two steps (every body 3 g dt^2 below its rest, at 2 g dt), and the core wakes
the islands it touches (in-process, 100 bodies at 100 Hz: kinetic energy 0 -> 0.007 J,
bodies at up to 4 cm/s, not asleep again 1 s later); at 1000 bodies an awake step costs
more than the 30 Hz period, so the node then stays behind. The core's
matter (its solver's speed and its sleep); the row's ``asleep`` says how the run ended.

An input the node drops (it was behind) is no fresh start: the next
answered step spans the time since the last answered one (up to ``max_dt``), its warm start
follows the load that step carries, and a pile can fall asleep, and stays asleep, across it.

Runs against whatever ``collres_ros`` the interpreter imports (set PYTHONPATH
to a checkout to measure that one; its generated ``msg/`` must be present).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from pile import integrate, make_pile  # noqa: E402

SETTLE_DT = 1.0 / 120.0
T0 = 1_000_000_000_000   # first stamp, ns
PROBE_PERIOD = 0.02      # s between the start probe's inputs (``first_answer``)
TIMING_KEYS = ('time.queued_ms', 'time.decode_ms', 'time.resolve_ms', 'time.world_ms',
               'time.world_cpu_ms', 'time.encode_ms',
               'time.publish_ms', 'callback_time_mean_ms', 'step_time_mean_ms',
               'answer_time_mean_ms')


# --- the scene ----------------------------------------------------------------------------------

def settled_pile(count: int, settle_s: float) -> tuple[list[Any], Any, float]:
    """(bodies, settled states, mean World.step ms of the last settling steps, awake)."""
    from collres_ros.core.config import SolverSettings
    from collres_ros.core.world import World
    bodies, state = make_pile(count)
    world = World(bodies, SolverSettings(sleeping=False))   # the awake step
    times = []
    for _ in range(max(1, int(round(settle_s / SETTLE_DT)))):
        current = integrate(state, world.dynamic, SETTLE_DT)
        start = time.perf_counter()
        state = world.step(state, current, SETTLE_DT).states
        times.append(time.perf_counter() - start)
    return bodies, state, 1e3 * float(np.median(times[-10:]))


def _list(values: Any) -> str:
    return '[' + ', '.join(repr(float(v)) for v in values) + ']'


def write_scene(path: Path, bodies: list[Any], state: Any, sleeping: bool = True) -> Path:
    """A params file of the pile, initial poses = the settled state."""
    lines = ['/**:', '  ros__parameters:', '    world_frame: world',
             f'    bodies: [{", ".join(b.name for b in bodies)}]', '    body:']
    for k, b in enumerate(bodies):
        fields = [f'shape: {b.shape}', f'size: {_list(b.size)}']
        if b.static:
            fields.append('static: true')
        else:
            fields += [f'mass: {b.mass!r}', f'restitution: {b.restitution!r}',
                       f'static_friction: {b.static_friction!r}',
                       f'kinetic_friction: {b.kinetic_friction!r}']
        # static bodies too: the bin's floor and walls are where the pile settled against them
        fields += [f'position: {_list(state.position[k])}',
                   f'orientation: {_list(state.orientation[k])}']
        lines.append(f'      {b.name}: {{{", ".join(fields)}}}')
    lines += ['    solver:', f'      sleeping: {str(sleeping).lower()}',
              '/**/collres_node:', '  ros__parameters:', '    diagnostics_period: 0.5',
              '    queue_depth: 10']
    path.write_text('\n'.join(lines) + '\n')
    return path


def input_bytes(bodies: list[Any], state: Any) -> bytes:
    """Serialised BodyStateArray of the dynamic bodies of the settled pile as an estimator
    measures it at rest: its poses, zero twists, the same every step.

    Not the pose plus one gravity step with twist g dt (what this bench sent before): an
    integrator's prediction, not a measurement; a pose that never moves with a twist that
    says it falls 0.1 m/s (at 100 Hz) contradicts itself, each answer then drifts from the
    input (the node advances a body in contact from its own last pose) and the pile's
    sleeping islands read the input as a correction and wake every step: the 100-body pile
    never fell asleep (in-process, 300 steps at 100 Hz: 0 of 100 asleep; with zero twists 94
    after 100 steps)."""
    from rclpy.serialization import serialize_message

    from collres_ros.msg import BodyState, BodyStateArray
    msg = BodyStateArray()
    msg.header.frame_id = 'world'
    for k, b in enumerate(bodies):
        if b.static:
            continue
        body = BodyState(name=b.name)
        p, q = body.pose.position, body.pose.orientation
        p.x, p.y, p.z = (float(v) for v in state.position[k])
        q.x, q.y, q.z, q.w = (float(v) for v in state.orientation[k])
        msg.bodies.append(body)   # twist: zero
    return bytes(serialize_message(msg))


def stamp_of(data: bytes) -> int:
    """Header stamp (ns) of serialised stamped CDR (sec, nanosec right after the header)."""
    sec = int.from_bytes(data[4:8], 'little', signed=True)
    return sec * 1_000_000_000 + int.from_bytes(data[8:12], 'little')


def with_stamp(template: bytearray, stamp: int) -> bytes:
    template[4:8] = (stamp // 1_000_000_000).to_bytes(4, 'little', signed=True)
    template[8:12] = (stamp % 1_000_000_000).to_bytes(4, 'little')
    return bytes(template)


# Fast DDS announces a participant 5 times at start, 0.1 s apart, then every 3 s. Which side
# sees the other first is a race: a probe that missed the node's first announcements waited
# for its next one (at 1000 bodies, load 2-3, the first answer came 3.7-4.6 s after the start
# in most runs, 2-3 s after the node was ready). The bench's own participants (this process's
# probe and listener, the publisher) announce themselves every 0.25 s instead, so the node
# learns of them, and they of it, within a quarter second of its start, whatever the race:
# set on the probe side only, through Fast DDS's default profile file; the node's and the
# echo's processes keep the environment a user gives them.
PROBE_PROFILE = """<?xml version="1.0" encoding="UTF-8"?>
<dds xmlns="http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles">
  <profiles>
    <participant profile_name="collres_bench_probe" is_default_profile="true">
      <rtps><builtin><discovery_config>
        <leaseAnnouncement><sec>0</sec><nanosec>250000000</nanosec></leaseAnnouncement>
      </discovery_config></builtin></rtps>
    </participant>
  </profiles>
</dds>
"""
PROFILE_VARIABLE = 'FASTRTPS_DEFAULT_PROFILES_FILE'
USER_ENV = dict(os.environ)   # the environment as given, before the probe's profile is set


def use_probe_profile(workdir: Path) -> None:
    """This process's participants, and the publisher's, announce every 0.25 s (see
    ``PROBE_PROFILE``); before this process's first participant."""
    path = workdir / 'probe_profile.xml'
    path.write_text(PROBE_PROFILE)
    os.environ[PROFILE_VARIABLE] = str(path)


def ros_env(domain: int, probe: bool = True) -> dict[str, str]:
    """The environment of a process of the run: the probe side's (``probe``: this process's
    own, with its Fast DDS profile) or a server's (the node, the echo: the user's)."""
    env = dict(os.environ if probe else USER_ENV, ROS_DOMAIN_ID=str(domain),
               ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST', PYTHONUNBUFFERED='1',
               RCUTILS_COLORIZED_OUTPUT='0')
    return env


# --- the publisher process ----------------------------------------------------------------------

class Inputs:
    """The publisher's next input: the template with a new stamp (estimator), or
    (simulator) the latest answer received integrated one step under the new stamp, as a
    simulator that takes the last correction it has for its state and steps it does.

    Its state's time is wrong by n - 1 steps when the answer is n steps old: for a pile
    still settling that puts every moving body back where it was, the node corrects
    towards it, and the older the answers the more energy goes in. In 1000 @ 30 runs whose
    lock-step ended before the pile slept (17 awake steps, load 1.7-1.9) the answers fell
    5-20 steps behind and, replayed in-process, the pile's kinetic energy rose from 0.0014 J
    (step 25, the input built from the answer one step old) to 0.1 J (step 36, 7 steps old)
    and 1-8 J (15-20 steps old): it never slept, 141 of 600 inputs answered. Hence the
    lock-step until the pile is still (``--until-rest``): an asleep pile's answers are all
    the same, and so are the inputs built from any of them.

    The time-consistent rules were tried and are worse at rest: each makes a late answer a
    free fall, without collisions, of as many steps as the answer is late, and one late
    answer (two steps of fall) wakes the asleep pile (the core's sleep), whose awake steps
    then fall behind, so that the next answers are later still. ``collres_sim
    --realtime``'s rule (a late answer never adopted, the step goes on with the simulator's
    own state): 100 @ 100, 2312 of 3000 inputs unanswered, ``World.step`` 26 ms of CPU
    where an awake step takes 2; the latest answer integrated to the input's stamp: the
    same, the lag 1 -> 4 -> 9 steps within 1 s of the first late answer (a virtual-time
    replay in-process), and a 30 s run at 100 @ 100 that had not ended after 5 minutes."""

    def __init__(self, template: bytes, mode: str, dt: float) -> None:
        from collres_ros.ros.codec import StatesCodec
        self.template, self.mode, self.dt = bytearray(template), mode, dt
        self.codec = StatesCodec()
        self.latest: bytes = bytes(template)   # the last answer (simulator)
        self.base = 0   # the stamp of that answer (simulator; 0: none yet, the template)

    def answer(self, data: bytes) -> None:
        if self.mode == 'simulator':
            self.latest, self.base = bytes(data), stamp_of(data)

    def next(self, stamp: int) -> bytes:
        return self.from_answer(stamp, self.latest)

    def from_answer(self, stamp: int, answer: bytes) -> bytes:
        """The input at ``stamp`` when ``answer`` is the last answer the publisher has."""
        if self.mode in ('estimator', 'per_body'):
            return with_stamp(self.template, stamp)
        from collres_ros.ros.messages import state_values, states_of
        decoded = self.codec.decode(answer)
        states = states_of(decoded.values)
        current = integrate(states, np.ones(len(decoded.names), bool), self.dt)
        return self.codec.encode(stamp, decoded.frame_id, decoded.names, state_values(current))


def at_rest(answer: bytes) -> bool:
    """Whether a ``body_states/corrected`` answer holds every body still (zero twists: the
    node answers an asleep body with its held state)."""
    from collres_ros.ros.codec import StatesCodec
    values = StatesCodec().decode(answer).values
    return len(values) > 0 and not values[:, 7:13].any()


def publisher(args: argparse.Namespace) -> int:
    """Lock-step, then paced; writes {'lockstep': {...}, 'sent': {stamp: t_ns}} as JSON."""
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import QoSProfile, ReliabilityPolicy

    from collres_ros.msg import BodyStateArray
    period = int(round(1e9 / args.rate))
    inputs = Inputs(Path(args.bytes).read_bytes(), args.mode, period * 1e-9)
    rclpy.init(domain_id=args.domain)
    node = rclpy.create_node('collres_bench_publisher')
    qos = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
    pub = node.create_publisher(BodyStateArray, 'body_states', qos)
    inputs_of = [pub]
    if args.mode == 'per_body':
        from geometry_msgs.msg import PoseStamped, TwistStamped

        from collres_ros.ros import codec, names
        body_names = inputs.codec.decode(bytes(inputs.template)).names
        from rclpy.event_handler import PublisherEventCallbacks
        quiet = PublisherEventCallbacks(use_default_callbacks=False)   # as collres_sim's
        parts = [(node.create_publisher(PoseStamped, names.pose_topic(n), qos,
                                        event_callbacks=quiet),
                  node.create_publisher(TwistStamped, names.twist_topic(n), qos,
                                        event_callbacks=quiet))
                 for n in body_names]
        inputs_of = [p for pair in parts for p in pair]

        class Split:
            """Every body's pose and twist of a BodyStateArray, one publish each."""

            def publish(self, data: bytes) -> None:
                decoded = inputs.codec.decode(data)
                poses = codec.encode_stamped(decoded.stamp_ns, 'world', decoded.values[:, 0:7])
                twists = codec.encode_stamped(decoded.stamp_ns, 'world',
                                              decoded.values[:, 7:13])
                for (p, t), pose, twist in zip(parts, poses, twists):
                    p.publish(pose)
                    t.publish(twist)
        pub = Split()
    answered: dict[int, int] = {}
    last_answer = [b'']

    def on_answer(data: bytes) -> None:
        answered.setdefault(stamp_of(data), time.monotonic_ns())
        last_answer[0] = data
        inputs.answer(data)
    node.create_subscription(BodyStateArray, 'body_states/corrected', on_answer, qos, raw=True)
    executor = SingleThreadedExecutor()
    executor.add_node(node)

    def spin_until(predicate: Any, timeout: float) -> bool:
        deadline = time.monotonic() + timeout
        while not predicate():
            if time.monotonic() > deadline:
                return False
            executor.spin_once(timeout_sec=0.005)
        return True

    result: dict[str, Any] = {}
    try:
        if not spin_until(lambda: all(p.get_subscription_count() >= args.subscribers
                                      for p in inputs_of), 60.0):
            raise RuntimeError('no subscriber of the inputs')
        stamp = T0
        # every input sent: (stamp, the stamp of the answer it was integrated from)
        result['inputs'] = sent_inputs = []
        # lock-step: the next step as soon as the previous one is answered, for --lockstep s
        # and then (--until-rest) until an answer holds every body still, the pile asleep
        times, lost, still = [], 0, False
        lock_end = time.monotonic() + args.lockstep
        while time.monotonic() < lock_end or (
                not still and time.monotonic() < lock_end + args.until_rest):
            stamp += period
            data = inputs.next(stamp)
            sent_inputs.append((stamp, inputs.base))
            sent = time.monotonic_ns()
            pub.publish(data)
            if spin_until(lambda: stamp in answered, 5.0):
                times.append(answered[stamp] - sent)
                still = args.until_rest > 0 and at_rest(last_answer[0])
            else:
                lost += 1
        warm = times[len(times) // 5:] or times
        result['lockstep'] = {'steps': len(times), 'lost': lost, 'still': still,
                              'rate_hz': 1e9 / float(np.mean(warm)) if warm else 0.0,
                              'p50_ms': float(np.percentile(warm, 50)) / 1e6 if warm else 0.0}
        spin_until(lambda: False, 0.5)   # drain
        # paced: one step every 1/rate s for --duration s
        sent_at: dict[int, int] = {}
        sending: list[int] = []   # ns the publisher took to hand each step over (publish)
        begin = time.monotonic_ns()
        count = int(round(args.duration * args.rate))
        for k in range(count):
            due = begin + k * period
            while True:
                now = time.monotonic_ns()
                if now >= due:
                    break
                executor.spin_once(timeout_sec=min((due - now) * 1e-9, 0.002))
            stamp += period
            data = inputs.next(stamp)
            sent_inputs.append((stamp, inputs.base))
            sent_at[stamp] = time.monotonic_ns()
            pub.publish(data)
            sending.append(time.monotonic_ns() - sent_at[stamp])
        spin_until(lambda: all(s in answered for s in sent_at), 5.0)
        result['sent'] = {str(s): t for s, t in sent_at.items()}
        result['answered'] = list(answered)
        result['send_ms'] = [float(np.percentile(sending, q)) / 1e6 for q in (50, 99)]
        result['publish_late_ms'] = (time.monotonic_ns() - begin) / 1e6 - args.duration * 1e3
    finally:
        Path(args.out).write_text(json.dumps(result))
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


def echo(args: argparse.Namespace) -> int:
    """The floor: body_states bytes in, the same bytes out on body_states/corrected."""
    import rclpy
    from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
    from rclpy.qos import QoSProfile, ReliabilityPolicy

    from collres_ros.msg import BodyStateArray
    rclpy.init(domain_id=args.domain)
    node = rclpy.create_node('collres_bench_echo')
    qos = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
    out = node.create_publisher(BodyStateArray, 'body_states/corrected', qos)
    node.create_subscription(BodyStateArray, 'body_states', out.publish, qos, raw=True)
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    try:
        executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


# --- one size -----------------------------------------------------------------------------------

class Listener:
    """Subscribers of the node's outputs in this process, spun in a thread."""

    def __init__(self, domain: int) -> None:
        import rclpy
        from diagnostic_msgs.msg import DiagnosticArray
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.qos import QoSProfile, ReliabilityPolicy
        from visualization_msgs.msg import MarkerArray

        from collres_ros.msg import BodyStateArray, ContactArray
        self.context = rclpy.Context()
        rclpy.init(context=self.context, domain_id=domain)
        self.node = rclpy.create_node('collres_bench_listener', context=self.context)
        qos = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
        self.arrived: dict[int, int] = {}
        self.counts = {'contacts': 0, 'contact_markers': 0}
        self.diagnostics: list[tuple[int, dict[str, str]]] = []
        from collres_ros.ros.inputs import InputServer, ServedElsewhere
        # body_states/corrected: taken by a thread of its own (as the node takes its inputs),
        # not by the executor that runs the other callbacks (contacts, markers: their Python
        # callbacks, in the executor's thread, delayed answers by up to ~1 ms at 240 Hz)
        self.subscriptions = [
            self.node.create_subscription(BodyStateArray, 'body_states/corrected',
                                          self._corrected, qos, raw=True,
                                          callback_group=ServedElsewhere()),
            self.node.create_subscription(ContactArray, 'contacts',
                                          lambda d: self._count('contacts'), qos, raw=True),
            self.node.create_subscription(MarkerArray, 'contact_markers',
                                          lambda d: self._count('contact_markers'), qos,
                                          raw=True),
            self.node.create_subscription(DiagnosticArray, '/diagnostics', self._diagnostics,
                                          10)]
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.server = InputServer(self.node, 'collres_bench_answers', lambda: [
            (self.subscriptions[0], self._corrected)]).start()
        self.thread = threading.Thread(target=self._spin, daemon=True)
        self.thread.start()

    def _spin(self) -> None:
        try:
            self.executor.spin()
        except Exception:
            pass

    def _corrected(self, data: bytes, info: Any = None) -> None:
        self.arrived.setdefault(stamp_of(data), time.monotonic_ns())

    def _count(self, topic: str) -> None:
        self.counts[topic] += 1

    def _diagnostics(self, msg: Any) -> None:
        for status in msg.status:
            if 'collres' in status.name:
                self.diagnostics.append((time.monotonic_ns(),
                                         {kv.key: kv.value for kv in status.values}))

    def connected(self, only_states: bool = False) -> bool:
        """Every output of the node (``only_states``: body_states/corrected) has a publisher."""
        wanted = self.subscriptions[:1] if only_states else self.subscriptions
        return all(s.get_publisher_count() > 0 for s in wanted)

    def close(self) -> None:
        import rclpy
        self.server.close()
        self.executor.shutdown(timeout_sec=1.0)
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.context)


def first_answer(count: int, args: argparse.Namespace, workdir: Path) -> tuple[float, float]:
    """(first answer, ready) s from ``collres_node``'s process start on the pile's scene.

    This process publishes the pile's input (estimator mode, a new stamp each time) every
    ``PROBE_PERIOD`` from the moment the node's process is started, and the start is over
    when the first ``body_states/corrected`` arrives: imports, parameters, resolver, topics,
    discovery and the first step, all that a user waits for. ``ready``: to the node's
    ``resolving ...`` log line (its topics exist; the rest is DDS discovery and the step).
    Discovery between two new participants may wait for the next periodic announcement of
    Fast DDS (every 3 s by default), so the first figure was bimodal: at 1000 bodies, load
    4.5, first answers 1.17, 3.74, 4.10, 3.75, 3.74, 3.74 s with the node ready after
    0.90-1.35 s; the probe's participant now announces itself every 0.25 s
    (``PROBE_PROFILE``, this side only): 1.26-1.40 s, 0.04-0.05 s after the node was ready,
    in 6 runs of 6 (same load). The node is then stopped; the runs that follow start their
    own.
    """
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import QoSProfile, ReliabilityPolicy

    from collres_ros.msg import BodyStateArray
    template = bytearray((workdir / f'input{count}.cdr').read_bytes())
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=args.domain)
    probe = rclpy.create_node('collres_bench_start_probe', context=context)
    qos = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
    pub = probe.create_publisher(BodyStateArray, 'body_states', qos)
    answered: list[int] = []
    probe.create_subscription(BodyStateArray, 'body_states/corrected',
                              lambda data: answered.append(time.monotonic_ns()), qos, raw=True)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(probe)
    command = [str(Path(sys.executable).parent / 'collres_node'), '--ros-args',
               '--params-file', str(workdir / f'pile{count}_on.yaml')]
    stamp = T0 // 2   # before any stamp of the runs (this node is stopped before them)
    try:
        with open(workdir / f'start{count}.log', 'wb') as log:
            wall, begin = time.time(), time.monotonic_ns()
            node = subprocess.Popen(command, env=ros_env(args.domain, probe=False), stdout=log,
                                    stderr=subprocess.STDOUT, start_new_session=True)
        try:
            deadline = begin + 120 * 10**9
            while not answered and time.monotonic_ns() < deadline:
                stamp += int(PROBE_PERIOD * 1e9)
                pub.publish(with_stamp(template, stamp))
                sent = time.monotonic_ns()
                while not answered and time.monotonic_ns() - sent < PROBE_PERIOD * 1e9:
                    executor.spin_once(timeout_sec=PROBE_PERIOD / 4)
            if not answered:
                raise RuntimeError(f'the node never answered ({workdir}/start{count}.log)')
        finally:
            node.send_signal(2)
            try:
                node.wait(15)
            except subprocess.TimeoutExpired:
                node.kill()
        # rcutils' default line: [INFO] [<epoch s>] [collres_node]: resolving ...
        ready = next((float(line.split('[')[2].split(']')[0]) - wall for line in
                      (workdir / f'start{count}.log').read_text().splitlines()
                      if 'resolving' in line and line.count('[') >= 3), float('nan'))
        return (answered[0] - begin) * 1e-9, ready
    finally:
        executor.shutdown(timeout_sec=1.0)
        probe.destroy_node()
        rclpy.try_shutdown(context=context)


def _wait(predicate: Any, timeout: float) -> bool:
    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > deadline:
            return False
        time.sleep(0.01)
    return True


def _timings(diagnostics: list[tuple[int, dict[str, str]]], since: int) -> dict[str, float]:
    """Step-weighted means of the node's timing values over the reports after ``since``."""
    sums: dict[str, float] = {}
    total = 0.0
    for t, values in diagnostics:
        if t < since:
            continue
        steps = float(values.get('steps_window', values.get('window_steps', 1)) or 1)
        total += steps
        for key in TIMING_KEYS:
            if key in values:
                sums[key] = sums.get(key, 0.0) + steps * float(values[key])
    return {k: v / total for k, v in sums.items()} if total else {}


def _threads(diagnostics: list[tuple[int, dict[str, str]]], since: int) -> str:
    """The second thread's part over the reports after ``since``: the share of the runs
    posted for two threads that ran paired (``threads.runs``, ``threads.paired_runs``: the
    change over those reports) and the step-weighted mean of the periods' shares of chunks
    the second thread ran (``threads.second_share``); 'n/a' from a node without them or
    without such a run."""
    reports = [v for t, v in diagnostics if t >= since and 'threads.runs' in v]
    if len(reports) < 2:
        return 'n/a'
    runs = int(reports[-1]['threads.runs']) - int(reports[0]['threads.runs'])
    paired = int(reports[-1]['threads.paired_runs']) - int(reports[0]['threads.paired_runs'])
    shares = [(float(v.get('window_steps', 1) or 1), float(v['threads.second_share']))
              for v in reports[1:] if v.get('threads.second_share', 'n/a') != 'n/a']
    if not runs or not shares:
        return 'n/a'
    second = sum(w * x for w, x in shares) / sum(w for w, _ in shares)
    return f'{paired / runs:.2f} / {second:.2f}'


def node_env(variant: str) -> dict[str, str]:
    """The environment one ``--node-env`` variant adds to the node's process: 'default'
    (nothing), or ``NAME=VALUE[,NAME=VALUE...]``."""
    if variant == 'default':
        return {}
    return dict(item.split('=', 1) for item in variant.split(','))


def measure(count: int, rate: float, args: argparse.Namespace, workdir: Path,
            server: str, mode: str, sleeping: str = 'on',
            variant: str = 'default') -> dict[str, Any]:
    """One run of the publisher in ``mode`` against ``server`` ('node' or 'echo'; the
    node's process with the environment of ``variant``, see ``node_env``)."""
    scene, data = workdir / f'pile{count}_{sleeping}.yaml', workdir / f'input{count}.cdr'
    env = ros_env(args.domain)   # the publisher's
    server_env = dict(ros_env(args.domain, probe=False), **(
        node_env(variant) if server == 'node' else {}))   # the variant: the node's only
    if server == 'node':
        command = [str(Path(sys.executable).parent / 'collres_node'), '--ros-args',
                   '--params-file', str(scene)]
    else:
        command = [sys.executable, __file__, '--role', 'echo', '--domain', str(args.domain)]
    tag = f'{server}{count}{mode}{sleeping}_{time.monotonic_ns()}'
    begin = time.monotonic()
    with open(workdir / f'{tag}.log', 'wb') as log:
        node = subprocess.Popen(command, env=server_env, stdout=log, stderr=subprocess.STDOUT,
                                start_new_session=True)
    listener = Listener(args.domain)
    out = workdir / f'sent{tag}.json'
    pub = None
    try:
        if not _wait(lambda: listener.connected(server == 'echo'), 120.0):
            raise RuntimeError(f'{server} did not come up ({workdir}/{tag}.log)')
        startup = time.monotonic() - begin
        start = time.monotonic_ns()
        with open(workdir / f'pub{tag}.log', 'wb') as log:
            pub = subprocess.Popen(
                [sys.executable, __file__, '--role', 'publisher', '--bytes', str(data),
                 '--rate', str(rate), '--duration', str(args.duration), '--lockstep',
                 str(args.lockstep), '--domain', str(args.domain), '--out', str(out),
                 '--mode', mode, '--until-rest',
                 str(args.until_rest if server == 'node' and sleeping == 'on' else 0.0)],
                env=env, stdout=log, stderr=subprocess.STDOUT)
        pub.wait(timeout=args.duration + args.lockstep + args.until_rest + 300)
        result = json.loads(out.read_text())
        paced_from = min(int(t) for t in result['sent'].values())
        if server == 'node':
            time.sleep(args.diagnostics_wait)
        timings = _timings(listener.diagnostics, paced_from)
        lock_timings = {k: v for k, v in _timings(
            [d for d in listener.diagnostics if start <= d[0] < paced_from], start).items()}
    finally:
        listener.close()
        if pub is not None and pub.poll() is None:
            pub.kill()
        node.send_signal(2)
        try:
            node.wait(15)
        except subprocess.TimeoutExpired:
            node.kill()
    sent = {int(s): t for s, t in result['sent'].items()}
    latencies = [(listener.arrived[s] - t) / 1e6 for s, t in sent.items()
                 if s in listener.arrived]
    warm = latencies[len(latencies) // 10:] or latencies
    last = listener.diagnostics[-1][1] if listener.diagnostics else {}
    queued_max = max((float(v['queued_max_ms']) for t, v in listener.diagnostics
                      if t >= paced_from and 'queued_max_ms' in v), default=float('nan'))
    asleep = last.get('sleeping_bodies', '-')
    behind = last.get('outputs_skipped_behind', '-')
    return {'server': server if variant == 'default' else f'{server} {variant}', 'mode': mode,
            'bodies': count, 'rate': rate,
            'sleeping': sleeping if server == 'node' else '-', 'asleep': asleep,
            'startup_s': startup, 'lockstep': result['lockstep'], 'sent': len(sent),
            'answered': len(latencies), 'dropped': len(sent) - len(latencies), 'behind': behind,
            'p50': float(np.percentile(warm, 50)) if warm else float('nan'),
            'p99': float(np.percentile(warm, 99)) if warm else float('nan'),
            'send_ms': result.get('send_ms', [float('nan')] * 2),
            'contacts_msgs': listener.counts['contacts'],
            'markers_msgs': listener.counts['contact_markers'],
            'timings': timings, 'lock_timings': lock_timings, 'queued_max_ms': queued_max,
            'threads': _threads(listener.diagnostics, paced_from),
            # every input sent, in order, with what it was built from, and the node's steps:
            # the inputs it answered (received here or by the publisher; an input lost in
            # the node's queue was never stepped)
            'inputs': result['inputs'],
            'stepped': set(listener.arrived) | set(result.get('answered', []))}


def prepare(count: int, rate: float, args: argparse.Namespace, workdir: Path) -> None:
    """The settled pile's params files (solver.sleeping on and off) and input bytes."""
    bodies, state, _ = settled_pile(count, args.settle)
    for flag in ('on', 'off'):
        write_scene(workdir / f'pile{count}_{flag}.yaml', bodies, state, flag == 'on')
    (workdir / f'input{count}.cdr').write_bytes(input_bytes(bodies, state))


def in_process(count: int, rate: float, mode: str, scene: Path, sent: list[Any],
               stepped: set[int], last: int) -> tuple[float, float, float]:
    """(wall, CPU, paced CPU) median ms of World.step over the ``last`` of the node's steps,
    stepped again in this process: back to back, and paced (one step per period of ``rate``,
    as the node took them; this process sleeps in between).

    The scene read back from the params file into a ``Resolver`` as the node builds it, and
    the node's own steps: every input the publisher sent (``sent``: in order, each with the
    stamp of the answer it was built from) that the node answered (``stepped``), rebuilt by
    the publisher's rule (``Inputs``) from this process's answer of that stamp: the same
    stamps, so the same dt and the same long steps across the inputs it never took. The
    core is deterministic, so these are the node's steps; what the node's
    ``time.world_ms`` adds to them, the live run adds.

    Paced, the same steps cost more CPU than back to back, in this process, on one thread:
    at 100 bodies (a settled pile, 100 Hz, load 2.5) 0.85-0.98 ms against 0.33 ms with the
    solver's worker off, whether the 9 ms between steps are slept or spun in Python; what
    ran between the steps left the step's code and data out of the caches. That is what
    the node's steps pay too, so the paced CPU is the node's reference.
    """
    from collres_ros.core.pipeline import Resolver
    from collres_ros.core.types import InputBatch
    from collres_ros.ros import messages, params
    if not last:
        return float('nan'), float('nan'), float('nan')
    period = 1.0 / rate
    measured = set(sorted(s for s, _ in sent if s in stepped)[-last:])

    def replay(paced: bool) -> tuple[float, float]:
        resolver = Resolver.for_scene(params.load_scene(scene))
        encoder = messages.OutputEncoder(resolver.names, resolver.world_frame,
                                         resolver.bodies)
        inputs = Inputs((scene.parent / f'input{count}.cdr').read_bytes(), mode,
                        int(round(1e9 / rate)) * 1e-9)   # the publisher's period
        answers: dict[int, bytes] = {0: bytes(inputs.template)}   # 0: no answer yet
        world_step = resolver.world.step
        wall, cpu = [], []

        def timed(*a: Any, **k: Any) -> Any:
            start = time.thread_time()
            result = world_step(*a, **k)
            cpu.append(time.thread_time() - start)
            return result
        resolver.world.step = timed   # type: ignore[method-assign]
        begun = time.perf_counter()
        for stamp, base in sent:
            if stamp not in stepped:
                continue
            if base not in answers:   # built from an answer the node never gave
                return float('nan'), float('nan')
            data = inputs.from_answer(stamp, answers[base])
            for old in [s for s in answers if s < base]:   # bases only grow
                del answers[old]
            if paced and stamp in measured:   # the measured steps, one per period
                time.sleep(max(0.0, period - (time.perf_counter() - begun)))
            begun = time.perf_counter()
            decoded = inputs.codec.decode(data)
            step = resolver.resolve(stamp, InputBatch(decoded.names, decoded.values,
                                                      decoded.frame_id, decoded.frame_id))
            answers[stamp] = encoder.corrected(step)
            wall.append(step.world_time_s)
        return 1e3 * float(np.median(wall[-last:])), 1e3 * float(np.median(cpu[-last:]))
    wall, cpu = replay(False)
    return wall, cpu, replay(True)[1]


def _f(values: dict[str, float], key: str) -> str:
    return f'{values[key]:.2f}' if key in values else 'n/a'


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--sizes', type=int, nargs='+', default=[10, 100, 1000])
    parser.add_argument('--rates', type=float, nargs='+', default=[100.0, 100.0, 30.0],
                        help='paced rate per size, Hz')
    parser.add_argument('--duration', type=float, default=10.0, help='paced run, s')
    parser.add_argument('--lockstep', type=float, default=5.0, help='lock-step run, s')
    parser.add_argument('--until-rest', type=float, default=120.0, metavar='S',
                        help='with solver.sleeping on, the lock-step goes on past --lockstep '
                        'until an answer holds every body still (asleep), for up to S s more '
                        '(0: no)')
    parser.add_argument('--settle', type=float, default=2.0,
                        help='settling time, s (the pile is at rest 2 s after the drop)')
    parser.add_argument('--domain', type=int, default=int(os.environ.get('ROS_DOMAIN_ID', 90)))
    parser.add_argument('--diagnostics-wait', type=float, default=1.2)
    parser.add_argument('--modes', nargs='+', default=['estimator', 'simulator'],
                        choices=('estimator', 'simulator', 'per_body'),
                        help='how the publisher drives the node (see the docstring)')
    parser.add_argument('--no-echo', action='store_true', help='skip the echo floor')
    parser.add_argument('--sleeping', nargs='+', default=['on'], choices=('on', 'off'),
                        help='solver.sleeping of the node (see the docstring)')
    parser.add_argument('--node-env', nargs='+', default=['default'], dest='variants',
                        metavar='VARIANT',
                        help="the node's runs once per variant, interleaved: 'default' (the "
                        "environment as it is) or NAME=VALUE[,NAME=VALUE...] added to the "
                        "node's process only (e.g. RMW_FASTRTPS_PUBLICATION_MODE=SYNCHRONOUS)")
    parser.add_argument('--repeat', type=int, default=1,
                        help='runs of each (mode, sleeping, variant), interleaved')
    parser.add_argument('--json', help='also write the rows here')
    parser.add_argument('--start-only', type=int, default=0, metavar='RUNS',
                        help="only the node's start-up: RUNS first answers per size")
    parser.add_argument('--role', default='main', help=argparse.SUPPRESS)
    parser.add_argument('--bytes', help=argparse.SUPPRESS)
    parser.add_argument('--rate', type=float, default=100.0, help=argparse.SUPPRESS)
    parser.add_argument('--mode', default='estimator', help=argparse.SUPPRESS)
    parser.add_argument('--out', help=argparse.SUPPRESS)
    parser.add_argument('--subscribers', type=int, default=1, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.role == 'publisher':
        return publisher(args)
    if args.role == 'echo':
        return echo(args)
    rates = (args.rates + [args.rates[-1]] * len(args.sizes))[:len(args.sizes)]
    if args.start_only:
        with tempfile.TemporaryDirectory(prefix='collres_bench_') as tmp:
            use_probe_profile(Path(tmp))
            for count, rate in zip(args.sizes, rates):
                prepare(count, rate, args, Path(tmp))
                starts = [first_answer(count, args, Path(tmp)) for _ in range(args.start_only)]
                print(f'{count} bodies: first answer (ready) after '
                      f'{", ".join(f"{t:.2f} ({r:.2f})" for t, r in starts)} s', flush=True)
        return 0
    print('| bodies | server | mode | sleeping (asleep) | start s: answer / ready (topics) | '
          'lock-step Hz | '
          'lock-step p50 ms | paced Hz | sent | send p50 / p99 ms | dropped (behind) | p50 ms | '
          'p99 ms | '
          'callback ms | '
          'decode | resolve | World.step wall / CPU (in-process wall / CPU; paced CPU) | '
          'answer ms | '
          'encode | publish | overhead ms | queued mean / max ms | 2nd thread: paired / share |')
    print('|---' * 23 + '|')
    rows = []
    with tempfile.TemporaryDirectory(prefix='collres_bench_') as tmp:
        use_probe_profile(Path(tmp))
        for count, rate in zip(args.sizes, rates):
            prepare(count, rate, args, Path(tmp))
            start, ready = first_answer(count, args, Path(tmp))
            runs = ([] if args.no_echo else [('echo', 'estimator', 'on', 'default')]) + \
                [('node', mode, flag, variant) for mode in args.modes
                 for flag in args.sleeping for _ in range(args.repeat)
                 for variant in args.variants]
            for server, mode, flag, variant in runs:
                r = measure(count, rate, args, Path(tmp), server, mode, flag, variant)
                r['in_process_ms'] = in_process(
                    count, rate, mode, Path(tmp) / f'pile{count}_{flag}.yaml', r['inputs'],
                    r['stepped'], r['answered'])
                r['first_answer_s'] = start if server == 'node' else float('nan')
                r['ready_s'] = ready if server == 'node' else float('nan')
                rows.append(r)
                _print_row(r)
    print('lock-step: publish, wait for the answer, repeat (its steps; still: its last answer '
          'held every body still); paced: --duration s at the rate; '
          'dropped: paced steps without an answer (behind: steps the node answered while a newer '
          'input waited, their markers skipped, since its start); '
          'latency: publish to body_states/corrected received (it includes send: the '
          "publisher's own time to hand a step over, 2 x bodies messages in per_body mode); "
          "start: the node's process start to its first answer (a probe run of its own, "
          'the pile\'s input sent every 20 ms from the start) / to its \'resolving\' log line '
          '(ready: its topics exist), in brackets to every topic of the run connected; '
          'callback split: the node\'s /diagnostics means over the paced run; World.step '
          '(in-process wall / CPU): the node\'s own steps (every input it '
          'answered, the same stamps and inputs) stepped again by a Resolver in this process '
          '(median, thread CPU time beside; paced CPU: the same steps one per period, the CPU '
          "a step pays after other work, the node's reference, see in_process); "
          'answer: callback start to body_states/corrected published (the other outputs '
          'follow: encode, publish); overhead = answer - World.step; queued: a body_states '
          "input's wait from its reception by the node's DDS to its callback (the node's "
          "time.queued_ms, mean, and the largest queued_max_ms of the paced run); 2nd thread: "
          "of the node's runs posted for two threads over the paced run, the share run paired "
          "and the share of their chunks the second thread ran (its threads.* values)")
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1, default=str))
    return 0


def _print_row(r: dict[str, Any]) -> None:
    t = r['timings'] or r['lock_timings']
    answer, world = t.get('answer_time_mean_ms'), t.get('time.world_ms')
    overhead = answer - world if answer is not None and world is not None else None
    print(f'| {r["bodies"]} | {r["server"]} | {r["mode"]} | {r["sleeping"]} ({r["asleep"]}) | '
          f'{r["first_answer_s"]:.2f} / {r["ready_s"]:.2f} ({r["startup_s"]:.2f}) | '
          f'{r["lockstep"]["rate_hz"]:.1f} ({r["lockstep"]["steps"]} steps'
          f'{", still" if r["lockstep"].get("still") else ""}) | '
          f'{r["lockstep"]["p50_ms"]:.2f} | {r["rate"]:g} | '
          f'{r["sent"]} | {r["send_ms"][0]:.2f} / {r["send_ms"][1]:.2f} | {r["dropped"]} '
          f'({r["behind"]}) | '
          f'{r["p50"]:.2f} | {r["p99"]:.2f} | '
          f'{_f(t, "callback_time_mean_ms")} | {_f(t, "time.decode_ms")} | '
          f'{_f(t, "time.resolve_ms")} | {_f(t, "time.world_ms")} / '
          f'{_f(t, "time.world_cpu_ms")} '
          f'({r["in_process_ms"][0]:.2f} / {r["in_process_ms"][1]:.2f}; paced CPU '
          f'{r["in_process_ms"][2]:.2f}) | '
          f'{_f(t, "answer_time_mean_ms")} | '
          f'{_f(t, "time.encode_ms")} | '
          f'{_f(t, "time.publish_ms")} | '
          f'{"n/a" if overhead is None else f"{overhead:.2f}"} | '
          f'{_f(t, "time.queued_ms")} / {r["queued_max_ms"]:.2f} | {r["threads"]} |',
          flush=True)


if __name__ == '__main__':
    sys.exit(main())
