"""collres_sim: the launchable test simulator, live over DDS or offline into a bag.

Live (default)::

    collres_sim --ros-args --params-file config/scenes/bouncing_ball.yaml

integrates the scene of the params file (semi-implicit Euler with gravity,
``collres_ros.ros.integrator``) at ``rate_hz`` for ``duration`` s of simulated time.
Kinematic bodies (``body.<n>.kinematic: true``: static, infinite mass) move at
their prescribed ``linear_velocity`` / ``angular_velocity`` and are published
with it, so the node sees a conveyor or a turntable move; the sim never adopts
a corrected state for them.
Each step it publishes ``body_states`` (BodyStateArray of the dynamic and kinematic bodies,
stamped with simulated time; or, with ``--per-body``/``publish_per_body``,
``bodies/<name>/pose`` and ``bodies/<name>/twist`` instead) and ``/clock``,
waits for ``body_states/corrected`` of the same stamp and adopts it
(closing the loop). A step whose answer does
not arrive within ``--step-timeout`` s is counted as dropped and the sim goes
on with its own uncorrected state. The run is lock-step, as fast as the node
answers (``--realtime`` paces it to the wall clock). Exit code 0 at the end.

Offline::

    collres_sim --offline --params FILE [--duration S] --record BAG [--storage mcap|sqlite3]

runs the same scene through the same core in-process (``Resolver``, no DDS)
as fast as it can, and records ``/body_states`` and every output topic of the
node (built by the node's own message builder) to a rosbag2 bag. Log times
are the stamps (simulated time).
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

from collres_ros.core.types import BodyStates
from collres_ros.ros.integrator import euler_step

START_NS = 1_000_000_000  # stamp of the first state: t = 1 s of simulated time (never 0)
STATES_TOPIC = 'body_states'
CORRECTED_TOPIC = 'body_states/corrected'


# --- scene stepping shared by live and offline -------------------------------------------------

def stamps(rate_hz: float, duration: float, start_ns: int = START_NS) -> list[int]:
    """Stamps (ns) of every published state: t0, t0 + 1/rate, ... up to t0 + duration."""
    count = int(round(duration * rate_hz))
    return [start_ns + int(round(k * 1e9 / rate_hz)) for k in range(count + 1)]


def states_to_msg(names: Sequence[str], states: BodyStates, rows: Sequence[int],
                  stamp_ns: int, frame_id: str) -> Any:
    """Build the BodyStateArray of bodies ``rows`` of ``states`` (world frame) at a stamp."""
    from collres_ros.msg import BodyState, BodyStateArray
    msg = BodyStateArray()
    msg.header.frame_id = frame_id
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(int(stamp_ns), 10**9)
    for i in rows:
        body = BodyState()
        body.name = names[i]
        p, q, v, w = (states.position[i], states.orientation[i], states.linear[i],
                      states.angular[i])
        pose, twist = body.pose, body.twist
        pose.position.x, pose.position.y, pose.position.z = (float(x) for x in p)
        (pose.orientation.x, pose.orientation.y, pose.orientation.z,
         pose.orientation.w) = (float(x) for x in q)
        twist.linear.x, twist.linear.y, twist.linear.z = (float(x) for x in v)
        twist.angular.x, twist.angular.y, twist.angular.z = (float(x) for x in w)
        msg.bodies.append(body)
    return msg


def adopt(states: BodyStates, names: Sequence[str], msg: Any,
          only: np.ndarray | None = None) -> BodyStates:
    """``states`` with the bodies named in a BodyStateArray replaced by its values.

    ``only``: (N,) bool, adopt only these bodies (the others keep their state).
    """
    index = {name: i for i, name in enumerate(names) if only is None or only[i]}
    out = states.copy()
    for body in msg.bodies:
        i = index.get(body.name)
        if i is None:
            continue
        p, q, t = body.pose.position, body.pose.orientation, body.twist
        out.position[i] = (p.x, p.y, p.z)
        out.orientation[i] = (q.x, q.y, q.z, q.w)
        out.linear[i] = (t.linear.x, t.linear.y, t.linear.z)
        out.angular[i] = (t.angular.x, t.angular.y, t.angular.z)
    return out


def stamp_ns(stamp: Any) -> int:
    """builtin_interfaces/Time -> ns."""
    return int(stamp.sec) * 10**9 + int(stamp.nanosec)


@dataclass
class SimScene:
    """What the sim needs from a Scene (params.py): bodies, initial state, sim settings."""

    scene: Any                  # collres_ros.ros.params.Scene
    names: list[str]
    dynamic: np.ndarray         # (N,) bool
    initial: BodyStates
    gravity: np.ndarray         # (3,) m/s^2, world
    rate_hz: float
    duration: float             # s of simulated time
    world_frame: str
    per_body: bool = False
    kinematic: np.ndarray | None = None   # (N,) bool: static bodies moved at their twist
    namespace: str = '/'                   # of the sim and the node ('/' or '/r1')

    @property
    def driven(self) -> np.ndarray:
        """(N,) bool: the kinematic bodies (all False when there are none)."""
        return np.zeros_like(self.dynamic) if self.kinematic is None else self.kinematic

    @property
    def rows(self) -> list[int]:
        """Indices of the bodies the sim publishes (dynamic and kinematic ones)."""
        return [i for i in range(len(self.names)) if self.dynamic[i] or self.driven[i]]


def load_sim_scene(path: str | Path, duration: float | None = None,
                   rate_hz: float | None = None, namespace: str = '/') -> SimScene:
    """Load a params file (ValueError/OSError with a one-line reason when bad).

    ``namespace``: the sim's (and the node's) namespace: the file's sections
    are chosen for ``<namespace>/collres_sim`` and ``<namespace>/collres_node``
    as rcl chooses them for those nodes.
    """
    from collres_ros.ros import params
    scene = params.load_scene(path, namespace)
    sim = scene.sim
    return SimScene(
        scene=scene,
        names=[b.name for b in scene.bodies],
        dynamic=np.array([not b.static for b in scene.bodies], bool),
        initial=scene.initial.copy(),
        gravity=np.asarray(sim.gravity, float),
        rate_hz=float(rate_hz if rate_hz is not None else sim.rate_hz),
        duration=float(duration if duration is not None else sim.duration),
        world_frame=scene.world_frame,
        per_body=bool(getattr(sim, 'publish_per_body', False)),
        kinematic=scene.kinematic,
        namespace=params.fully_qualified_name(namespace, '').rstrip('/') or '/')


def run_loop(sim: SimScene, exchange: Callable[[int, Any], Any | None],
             on_step: Callable[[int, int], None] | None = None) -> tuple[int, int]:
    """Integrate and exchange states every step; returns (steps, dropped).

    ``exchange(stamp_ns, BodyStateArray)`` publishes the state and returns the
    corrected BodyStateArray of that stamp, or None when it did not come.
    """
    all_stamps = stamps(sim.rate_hz, sim.duration)
    states = sim.initial.copy()
    dropped = 0
    for k, stamp in enumerate(all_stamps):
        if k > 0:
            states = euler_step(states, sim.dynamic, sim.gravity,
                                (stamp - all_stamps[k - 1]) * 1e-9, sim.driven)
        corrected = exchange(stamp, states_to_msg(sim.names, states, sim.rows, stamp,
                                                  sim.world_frame))
        if corrected is None:
            dropped += 1
        else:   # kinematic bodies keep their prescribed motion
            states = adopt(states, sim.names, corrected, sim.dynamic)
        if on_step is not None:
            on_step(k + 1, len(all_stamps))
    return len(all_stamps), dropped


# --- offline -----------------------------------------------------------------------------------

@dataclass
class OfflineSummary:
    """What an offline run recorded: steps, bag messages, contacts by state, wall time (s)."""

    steps: int
    messages: int
    contacts: dict[str, int]
    wall_s: float


def run_core(sim: SimScene, sink: Callable[[int, list[tuple[str, Any]]], None],
             on_step: Callable[[int, int], None] | None = None, markers: bool = True) -> int:
    """Run the scene through the core in-process; returns the number of steps.

    ``sink(stamp_ns, [(topic, msg), ...])`` gets, per step, ('body_states',
    input) followed by every output of the node's message builder (relative
    topic names, as the node publishes them). ``markers`` False skips
    building contact_markers (they dominate the cost with many contacts).
    """
    from collres_ros.ros import messages
    from collres_ros.core.pipeline import Resolver
    from collres_ros.replay import OfflineDiagnostics
    resolver = Resolver(sim.scene)
    node = sim.scene.node
    diagnostics = OfflineDiagnostics(node.diagnostics_period)

    def exchange(stamp: int, msg: Any) -> Any:
        step = resolver.resolve(stamp, messages.inputs_from_array(msg))
        outputs = messages.build_outputs(step, sim.world_frame, per_body=False,
                                         marker_lifetime=node.marker_lifetime,
                                         diagnostics=diagnostics.update(step, resolver),
                                         markers=markers)
        sink(stamp, [(STATES_TOPIC, msg)] + outputs)
        return dict(outputs)[CORRECTED_TOPIC]

    steps, _ = run_loop(sim, exchange, on_step)
    return steps


def run_offline(sim: SimScene, record: Path, storage: str = 'mcap', progress: bool = False,
                topics: Sequence[str] | None = None, compress: bool = False) -> OfflineSummary:
    """Step the scene in-process and record input and outputs to a new bag.

    ``progress``: a progress line on stderr, when stdout and stderr are terminals.
    ``topics``: record only these (relative names; default: all). ``compress``:
    zstd mcap chunks.
    """
    from collres_ros.ros import qos
    from collres_ros.ros.bag import BagWriter, describe
    from collres_ros.ros.console import progress_printer
    contacts: dict[str, int] = {}
    start = time.perf_counter()

    show = progress_printer('collres_sim') if progress else None   # on a terminal only
    depth = sim.scene.node.queue_depth
    with BagWriter(record, storage, compress, qos=lambda topic: [qos.offered(topic, depth)],
                   custom_data=describe(sim.scene)) as writer:
        def sink(stamp: int, outputs: list[tuple[str, Any]]) -> None:
            for topic, msg in outputs:
                if topics is None or topic in topics:
                    writer.write(absolute(topic, sim.namespace), stamp, msg)
                if topic == 'contacts':
                    for contact in msg.contacts:
                        key = STATE_NAMES.get(contact.state, str(contact.state))
                        contacts[key] = contacts.get(key, 0) + 1

        steps = run_core(sim, sink, show,
                         markers=topics is None or 'contact_markers' in topics)
        messages = writer.count
    return OfflineSummary(steps, messages, contacts, time.perf_counter() - start)


STATE_NAMES = {1: 'IMPACT', 2: 'RESTING', 3: 'SLIDING', 4: 'STICKING'}


def absolute(topic: str, namespace: str = '/') -> str:
    """Bag topic name of a relative topic in ``namespace`` (as ros2 bag record names it)."""
    if topic.startswith('/'):
        return topic
    return namespace.rstrip('/') + '/' + topic


# --- live --------------------------------------------------------------------------------------

def run_live(sim: SimScene, args: argparse.Namespace, ros_args: list[str]) -> int:
    """Run the DDS loop: publish, wait for the corrected state, adopt, integrate."""
    import rclpy
    from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
    from rclpy.node import Node
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from rosgraph_msgs.msg import Clock

    from collres_ros.msg import BodyStateArray
    from geometry_msgs.msg import PoseStamped, TwistStamped

    rclpy.init(args=['collres_sim'] + ros_args)
    node = Node('collres_sim')
    qos = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
    clock = node.create_publisher(Clock, '/clock', 10)
    pose_pubs, twist_pubs = {}, {}
    per_body = sim.per_body or args.per_body
    publisher = None if per_body else node.create_publisher(BodyStateArray, STATES_TOPIC, qos)
    if per_body:  # per-body topics instead of the batched one: one node step per stamp
        for i in sim.rows:
            name = sim.names[i]
            pose_pubs[name] = node.create_publisher(PoseStamped, f'bodies/{name}/pose', qos)
            twist_pubs[name] = node.create_publisher(TwistStamped, f'bodies/{name}/twist', qos)
    inputs = list(pose_pubs.values()) + list(twist_pubs.values()) if per_body else [publisher]
    answers: dict[int, Any] = {}
    corrected = node.create_subscription(
        BodyStateArray, CORRECTED_TOPIC,
        lambda m: answers.__setitem__(stamp_ns(m.header.stamp), m), qos)
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    log = node.get_logger()

    def spin_until(predicate: Callable[[], bool], timeout: float) -> bool:
        deadline = time.monotonic() + timeout
        while not predicate():
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                return False
            executor.spin_once(timeout_sec=min(remaining, 0.05))
        return True

    wall_start = time.monotonic()  # reset once the node answered discovery

    def exchange(stamp: int, msg: Any) -> Any | None:
        if args.realtime:
            due = wall_start + (stamp - START_NS) * 1e-9
            spin_until(lambda: time.monotonic() >= due, max(0.0, due - time.monotonic()))
        clock_msg = Clock()
        clock_msg.clock = msg.header.stamp
        clock.publish(clock_msg)
        for body in msg.bodies:
            if body.name in pose_pubs:
                pose_pubs[body.name].publish(PoseStamped(header=msg.header, pose=body.pose))
                twist_pubs[body.name].publish(TwistStamped(header=msg.header, twist=body.twist))
        if publisher is not None:
            publisher.publish(msg)
        if not spin_until(lambda: stamp in answers, args.step_timeout):
            log.warning(f'no corrected state for stamp {stamp} ns within '
                        f'{args.step_timeout} s: step dropped')
            return None
        return answers.pop(stamp)

    def progress(step: int, total: int) -> None:
        if step % 240 == 0 or step == total:
            log.info(f'step {step}/{total}')

    code = 0
    try:
        matched = spin_until(lambda: all(p.get_subscription_count() >= args.subscribers
                                         for p in inputs)
                             and corrected.get_publisher_count() > 0, args.wait)
        if not matched:
            log.error(f'error: no collres_node answered on {STATES_TOPIC} within {args.wait} s')
            code = 1
        else:
            wall_start = time.monotonic()
            steps, dropped = run_loop(sim, exchange, progress)
            log.info(f'done: {steps} steps, {dropped} dropped, '
                     f'{time.monotonic() - wall_start:.2f} s wall time')
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    return code


# --- command line ------------------------------------------------------------------------------

def _split_ros_args(argv: list[str]) -> tuple[list[str], list[str]]:
    """(own arguments, ROS arguments after --ros-args)."""
    if '--ros-args' in argv:
        i = argv.index('--ros-args')
        return argv[:i], argv[i:]
    return argv, []


def _namespace_from_ros_args(ros_args: list[str]) -> str:
    """The namespace a ``-r [collres_sim:]__ns:=NS`` remap in ROS arguments gives ('/')."""
    namespace = '/'
    for flag, rule in zip(ros_args, ros_args[1:]):
        if flag in ('-r', '--remap'):
            target, _, value = rule.partition(':=')
            if target in ('__ns', 'collres_sim:__ns') and value:
                namespace = value
    return namespace


def _params_file_from_ros_args(ros_args: list[str]) -> str | None:
    for i, arg in enumerate(ros_args[:-1]):
        if arg == '--params-file':
            return ros_args[i + 1]
    return None


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog='collres_sim',
        description='Integrate a scene and close the loop through collres_node (live), or '
                    'through the core in-process into a bag (--offline).')
    p.add_argument('--params', help='params file (default: --ros-args --params-file FILE, '
                                    'else the package config/collres.yaml)')
    p.add_argument('--duration', type=float, help='s of simulated time (default: from params)')
    p.add_argument('--rate', type=float, help='steps per s (default: rate_hz from params)')
    p.add_argument('--offline', action='store_true', help='no DDS: run the core in-process')
    p.add_argument('--record', help='offline: output bag directory (must not exist)')
    p.add_argument('--storage', default='mcap', help='offline: mcap (default) or sqlite3')
    p.add_argument('--compress', action='store_true', help='offline: zstd mcap chunks')
    p.add_argument('--per-body', action='store_true',
                   help='live: publish bodies/<name>/pose and bodies/<name>/twist instead of '
                        'body_states (also: publish_per_body in the params file)')
    p.add_argument('--step-timeout', type=float, default=1.0,
                   help='live: s to wait for each corrected state before dropping the step')
    p.add_argument('--wait', type=float, default=20.0,
                   help='live: s to wait for collres_node to appear')
    p.add_argument('--subscribers', type=int, default=1,
                   help='live: wait for this many subscribers of body_states (e.g. 2 with a '
                        'recorder) before the first step')
    p.add_argument('--realtime', action='store_true',
                   help='live: pace the steps to the wall clock')
    return p


def main(argv: Sequence[str] | None = None) -> int:
    own, ros_args = _split_ros_args(list(sys.argv[1:] if argv is None else argv))
    args = parser().parse_args(own)
    path = args.params or _params_file_from_ros_args(ros_args)
    if path is None:
        from collres_ros.ros.resources import config_path
        path = str(config_path())
    try:
        if not Path(path).is_file():
            raise ValueError(f'params file not found: {path}')
        sim = load_sim_scene(path, args.duration, args.rate, _namespace_from_ros_args(ros_args))
        if sim.duration < 0 or sim.rate_hz <= 0:
            raise ValueError('duration must be >= 0 and rate > 0')
        if args.offline:
            if not args.record:
                raise ValueError('--offline needs --record BAG')
            from collres_ros.ros.bag import STORAGES
            if args.storage not in STORAGES:
                raise ValueError(f'unknown storage {args.storage!r} '
                                 f'(supported: {", ".join(STORAGES)})')
            summary = run_offline(sim, Path(args.record), args.storage, progress=True,
                                  compress=args.compress)
            rate = summary.steps / summary.wall_s if summary.wall_s > 0 else float('inf')
            print(f'recorded {summary.steps} steps, {summary.messages} messages to '
                  f'{args.record} in {summary.wall_s:.2f} s ({rate:.0f} steps/s); contacts: '
                  + (', '.join(f'{k} {v}' for k, v in sorted(summary.contacts.items()))
                     or 'none'))
            return 0
    except (ValueError, OSError) as error:
        print(f'error: {error}', file=sys.stderr)
        return 1
    except Exception as error:  # e.g. BagError: still one line, no traceback
        print(f'error: {error}', file=sys.stderr)
        return 1
    return run_live(sim, args, ros_args)


if __name__ == '__main__':
    sys.exit(main())
