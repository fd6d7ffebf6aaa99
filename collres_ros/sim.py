"""collres_sim: the launchable test simulator, live over DDS or offline into a bag.

Live (default)::

    collres_sim --ros-args --params-file config/scenes/bouncing_ball.yaml

integrates the scene of the params file (semi-implicit Euler with gravity,
``collres_ros.ros.simulation``) at ``rate_hz`` for ``duration`` s of simulated time.
Each step it publishes ``body_states`` (BodyStateArray of the dynamic and kinematic bodies,
stamped with simulated time; or, with ``--per-body``/``publish_per_body``,
``bodies/<name>/pose`` and ``bodies/<name>/twist`` instead) and ``/clock``,
waits for ``body_states/corrected`` of the same stamp and adopts it
(closing the loop). The first step waits until the node's ``/diagnostics`` report counts
the sim's publisher (the node's side of the match); the sim leaves once every subscriber has
acknowledged every step. A step whose answer does
not arrive within ``--step-timeout`` s is counted as dropped and the sim goes
on with its own uncorrected state. The run is lock-step, as fast as the node
answers; ``--realtime`` paces it to the wall clock and keeps the rate: an answer is
awaited only until the next step is due, a later one is not adopted (that step goes on
with the sim's own state; the count is reported at the end). Exit code 0 at the end.

Single parameters on the command line win over the file, live or offline::

    collres_sim --offline --params FILE --record BAG --ros-args -p rate_hz:=100.0

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
from pathlib import Path
from typing import Any, Callable, Sequence

from collres_ros.ros import cli, names
from collres_ros.ros.simulation import (
    START_NS, RealtimePace, SimScene, load_sim_scene, rows_of, run_loop)
from collres_ros.ros.stamps import to_stamp


# --- live -------------------------------------------------------------------------------------

def full_name(info: Any) -> str:
    """The full name (``/ns/name``) of the node of a graph ``TopicEndpointInfo``."""
    return f'{info.node_namespace.rstrip("/")}/{info.node_name}'


def reported(msg: Any) -> dict[str, int]:
    """{node full name: body_states publishers it has matched} of a collres_node's
    ``/diagnostics`` report (DiagnosticArray); other statuses are left out."""
    from collres_ros.ros.diagnostics import STATUS_TASK
    suffix = f': {STATUS_TASK}'
    found = {}
    for status in msg.status:
        values = {kv.key: kv.value for kv in status.values}
        count = values.get('body_states_publishers', '')
        if status.name.endswith(suffix) and count.lstrip('-').isdigit():
            found[status.name[:-len(suffix)]] = int(count)
    return found


def run_live(sim: SimScene, args: argparse.Namespace, ros_args: list[str]) -> int:
    """Run the DDS loop: publish, wait for the corrected state, adopt, integrate."""
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.duration import Duration
    from rclpy.event_handler import PublisherEventCallbacks
    from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
    from rclpy.node import Node
    from rosgraph_msgs.msg import Clock

    from collres_ros.msg import BodyStateArray
    from collres_ros.ros import codec, messages
    from collres_ros.ros import qos as qos_profiles
    from geometry_msgs.msg import PoseStamped, TwistStamped

    code = 0
    try:
        with cli.ros_init(args=['collres_sim'] + ros_args):
            node = Node('collres_sim')
            # every publisher keeps the steps a reliable reader (a recorder) has not yet
            # acknowledged, up to STEPS_DEPTH: a reader that falls behind loses none
            qos = qos_profiles.state_qos(qos_profiles.STEPS_DEPTH)
            clock = node.create_publisher(Clock, names.CLOCK, qos)
            pose_pubs, twist_pubs = {}, {}
            per_body = sim.per_body or args.per_body
            publisher = None if per_body else node.create_publisher(BodyStateArray,
                                                                    names.STATES, qos)
            if per_body:  # per-body topics instead of the batched one: one node step per stamp
                # without rclpy's default QoS-event handler each (one waitable per publisher,
                # which the executor walks at every wake-up: quadratic in the bodies)
                quiet = PublisherEventCallbacks(use_default_callbacks=False)
                for i in sim.rows:
                    name = sim.names[i]
                    pose_pubs[name] = node.create_publisher(
                        PoseStamped, names.pose_topic(name), qos, event_callbacks=quiet)
                    twist_pubs[name] = node.create_publisher(
                        TwistStamped, names.twist_topic(name), qos, event_callbacks=quiet)
            inputs = list(pose_pubs.values()) + list(twist_pubs.values()) if per_body \
                else [publisher]
            states_codec = codec.StatesCodec(max_bodies=len(sim.names))
            answers: dict[int, Any] = {}

            def answer(data: bytes) -> None:
                try:
                    decoded = states_codec.decode(data)
                except codec.DecodeError as refusal:
                    node.get_logger().warning(f'corrected state refused: {refusal}')
                    return
                answers[decoded.stamp_ns] = decoded

            corrected = node.create_subscription(
                BodyStateArray, names.CORRECTED_STATES, answer,
                qos_profiles.state_qos(sim.scene.node.queue_depth), raw=True)
            # last: the node learns of our readers in the order they were created, so its
            # report received here says it has matched the answers' reader too
            matches: dict[str, int] = {}   # node full name -> its body_states publishers
            node.create_subscription(DiagnosticArray, names.DIAGNOSTICS,
                                     lambda msg: matches.update(reported(msg)), 10)
            executor = SingleThreadedExecutor()
            executor.add_node(node)
            log = node.get_logger()
            published = [sim.names[i] for i in sim.rows]

            def spin_until(predicate: Callable[[], bool], timeout: float) -> bool:
                deadline = time.monotonic() + timeout
                while not predicate():
                    remaining = deadline - time.monotonic()
                    if remaining <= 0:
                        return False
                    executor.spin_once(timeout_sec=min(remaining, 0.05))
                return True

            wall_start = time.monotonic()  # reset once the node answered discovery
            delivered: list[bool] = []

            def deliver_first_step() -> None:
                # Every subscriber counted before the run (the node, a recorder) acknowledges
                # the first step: a reader our publisher matched may not have matched us yet,
                # and would lose the steps published until it does.
                acked = all(p.wait_for_all_acked(Duration(seconds=min(args.wait, 10.0)))
                            for p in inputs)
                if not acked:
                    log.warning('a subscriber of the inputs did not acknowledge the first step')
                delivered.append(True)

            pace: list[RealtimePace] = []   # the run's, once it starts
            late_answers: list[int] = []   # realtime: stamps answered after the next was due
            published_at = [0.0]   # when the last step was published (monotonic, s)

            def exchange(stamp: int, states: Any) -> Any:
                nonlocal wall_start
                if args.realtime:
                    due = wall_start + (stamp - START_NS) * 1e-9
                    spin_until(lambda: time.monotonic() >= due,
                               max(0.0, due - time.monotonic()))
                    late = pace[0].late(int(round((stamp - START_NS) * 1e-9 * sim.rate_hz)),
                                        time.monotonic())
                    if late:
                        log.warning(late)
                values = messages.state_values(rows_of(states, sim.rows))
                clock.publish(Clock(clock=to_stamp(stamp)))
                if per_body:
                    poses = codec.encode_stamped(stamp, sim.world_frame, values[:, 0:7])
                    twists = codec.encode_stamped(stamp, sim.world_frame, values[:, 7:13])
                    for name, pose, twist in zip(published, poses, twists):
                        pose_pubs[name].publish(pose)
                        twist_pubs[name].publish(twist)
                else:
                    publisher.publish(states_codec.encode(stamp, sim.world_frame, published,
                                                          values))
                published_at[:] = [time.monotonic()]
                if not delivered:
                    deliver_first_step()
                    # the clock starts once the first step is delivered (discovery is done)
                    wall_start = time.monotonic() - (stamp - START_NS) * 1e-9
                    pace[0].start = published_at[0] = wall_start
                timeout = args.step_timeout
                if args.realtime:   # the answer is of use until the next step is due
                    due_next = wall_start + (stamp - START_NS) * 1e-9 + 1.0 / sim.rate_hz
                    timeout = min(timeout, max(0.0, due_next - time.monotonic()))
                answered = spin_until(lambda: stamp in answers, timeout)
                for old in [s for s in answers if s < stamp]:   # came after their step
                    del answers[old]
                if not answered:
                    if timeout < args.step_timeout:
                        late_answers.append(stamp)   # the step goes on with its own state
                    else:
                        log.warning(f'no corrected state for stamp {stamp} ns within '
                                    f'{args.step_timeout} s: step dropped')
                    return None
                decoded = answers.pop(stamp)
                return decoded.names, messages.states_of(decoded.values)

            def progress(step: int, total: int) -> None:
                if step % 240 == 0 or step == total:
                    log.info(f'step {step}/{total}')

            def node_matched() -> bool:
                # The answering node's own side of the match: its /diagnostics report counts
                # the body_states publishers its subscription has matched (every one we see,
                # ourselves included); with per-body inputs, that it reports at all (its
                # report's reader was matched after the answers' one). A step published
                # before the node matched us is lost to it.
                answering = node.get_publishers_info_by_topic(corrected.topic_name)
                needed = 0 if per_body else node.count_publishers(publisher.topic_name)
                return any(matches.get(full_name(info), -1) >= needed for info in answering)

            try:
                start_wait = time.monotonic()
                matched = spin_until(
                    lambda: all(p.get_subscription_count() >= args.subscribers
                                for p in inputs) and corrected.get_publisher_count() > 0,
                    args.wait)
                if matched and not spin_until(
                        node_matched, args.wait - (time.monotonic() - start_wait)):
                    log.warning(f'collres_node has not reported on {names.DIAGNOSTICS} that it '
                                f'matched our {names.STATES} within {args.wait} s: its first '
                                'steps can be lost')
                if not matched:
                    log.error(f'error: no collres_node answered on {names.STATES} within '
                              f'{args.wait} s')
                    code = 1
                else:
                    wall_start = time.monotonic()
                    pace.append(RealtimePace(sim.rate_hz, wall_start))
                    steps, dropped = run_loop(sim, exchange, progress)
                    wall = time.monotonic() - wall_start
                    # every subscriber (a recorder) has every step before we leave: a step
                    # sent but not yet acknowledged is lost with its writer (under load, one
                    # run in 20 of a busy reader missed the last steps of a writer that left)
                    if not all(p.wait_for_all_acked(Duration(seconds=min(args.wait, 10.0)))
                               for p in [*inputs, clock]):
                        log.warning('a subscriber of the inputs did not acknowledge the last '
                                    f'steps within {min(args.wait, 10.0)} s')
                    log.info(f'done: {steps} steps, {dropped} dropped, {wall:.2f} s wall time')
                    short = pace[0].summary(steps, published_at[0]) if args.realtime else None
                    if short:
                        log.warning(short)
                    if late_answers:
                        log.warning(f'realtime: {len(late_answers)} of {steps} answers came '
                                    'after the next step was due; those steps went on with '
                                    "the simulator's own state")
            finally:
                node.destroy_node()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    return code


# --- command line -----------------------------------------------------------------------------

def _spec(name: str) -> Any:
    from collres_ros.core.config import SIM_PARAMS
    return next(s for s in SIM_PARAMS if s.name == name)


def parser() -> argparse.ArgumentParser:
    duration = _spec('duration')
    rate = _spec('rate_hz')
    p = cli.ArgumentParser(
        prog='collres_sim',
        description='Integrate a scene and close the loop through collres_node (live), or '
                    'through the core in-process into a bag (--offline).',
        epilog='Parameters: a params file, and single ones on the command line with '
               '--ros-args -p NAME:=VALUE (e.g. -p rate_hz:=100.0), which win over the file.')
    p.add_argument('--params', help='params file (default: --ros-args --params-file FILE, '
                                    'else the package config/collres.yaml)')
    p.add_argument('--duration', type=cli.number(duration.minimum, duration.maximum),
                   help='s of simulated time (default: from params)')
    p.add_argument('--rate', type=cli.number(rate.minimum, rate.maximum),
                   help='steps per s (default: rate_hz from params)')
    p.add_argument('--offline', action='store_true', help='no DDS: run the core in-process')
    p.add_argument('--record', help='offline: output bag directory (must not exist)')
    p.add_argument('--storage', default='mcap', help='offline: mcap (default) or sqlite3')
    p.add_argument('--compress', action='store_true', help='offline: zstd mcap chunks')
    p.add_argument('--per-body', action='store_true',
                   help='live: publish bodies/<name>/pose and bodies/<name>/twist instead of '
                        'body_states (also: publish_per_body in the params file)')
    p.add_argument('--step-timeout', type=cli.number(0.0, 3600.0, above=True), default=1.0,
                   help='live: s to wait for each corrected state before dropping the step')
    p.add_argument('--wait', type=cli.number(0.0, 3600.0), default=20.0,
                   help='live: s to wait for collres_node to appear; with '
                        'robot_description_topic, s to wait for the URDF on '
                        'robot_description (offline too)')
    p.add_argument('--subscribers', type=cli.number(0, 1000, integer=True), default=1,
                   help='live: wait for this many subscribers of body_states (e.g. 2 with a '
                        'recorder) before the first step')
    p.add_argument('--realtime', action='store_true',
                   help='live: pace the steps to the wall clock and keep the rate: an answer '
                        'later than the next step is not adopted (counted at the end); warns '
                        'when publishing itself falls behind, with the rate it reached')
    return p


def _run(args: argparse.Namespace, ros_args: list[str]) -> int:
    path = args.params or cli.last_params_file(ros_args)
    if path is None:
        from collres_ros.ros.resources import config_path
        path = config_path()
    if not Path(path).is_file():
        raise cli.CliError(f'params file not found: {path}')
    namespace = cli.namespace_from_ros_args(ros_args, 'collres_sim')
    overrides = cli.param_overrides(ros_args, 'collres_sim')
    sim = load_sim_scene(path, args.duration, args.rate, namespace, overrides)
    values = sim.scene.values
    if values['robot_description_topic'] and not values['robot_description']:
        from collres_ros.ros import description   # the URDF from the topic, as the node
        urdf = description.fetch('collres_sim', ros_args, args.wait)
        sim = load_sim_scene(path, args.duration, args.rate, namespace,
                             {**overrides, 'robot_description': urdf})
    if sim.duration < 0 or sim.rate_hz <= 0:
        raise cli.CliError('duration must be >= 0 and rate > 0')
    if not args.offline:
        return run_live(sim, args, ros_args)
    if not args.record:
        raise cli.CliError('--offline needs --record BAG')
    from collres_ros.ros.bag import STORAGES, BagError
    from collres_ros.ros.offline import run_offline
    if args.storage not in STORAGES:
        raise cli.CliError(f'--storage: unknown storage {args.storage!r} '
                           f'(supported: {", ".join(STORAGES)})')
    cli.terminate_as_interrupt()   # SIGTERM finishes the bag as Ctrl-C does
    try:
        summary = run_offline(sim, Path(args.record), args.storage, progress=True,
                              compress=args.compress)
    except BagError as failure:
        raise cli.CliError(str(failure)) from None
    rate = summary.steps / summary.wall_s if summary.wall_s > 0 else float('inf')
    print(f'recorded {summary.steps} steps, {summary.messages} messages to '
          f'{args.record} in {summary.wall_s:.2f} s ({rate:.0f} steps/s); contacts: '
          + (', '.join(f'{k} {v}' for k, v in sorted(summary.contacts.items()))
             or 'none'))
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    """Console script ``collres_sim``: 0 at the end of the run, 1 with ``error: ...``."""
    own, ros_args = cli.split_ros_args(sys.argv[1:] if argv is None else argv)
    args = parser().parse_args(own)
    return cli.run(lambda: _run(args, ros_args))


if __name__ == '__main__':
    sys.exit(main())
