"""collres_demo: collres_node + collres_sim over real DDS, recorded, measured, plotted.

The README's main command (``make demo``)::

    collres_demo [--params FILE] [--duration S] [--out DIR] [--domain-id N]

starts ``collres_node`` and ``collres_sim`` as separate processes on the
default scene (config/collres.yaml) over DDS on localhost, in a private
``ROS_DOMAIN_ID``, records every topic to a rosbag2 bag from this process
(an rclpy recorder writing with ``collres_ros.ros.bag``), shows progress, and
ends with a short report: contacts per state, the ball's apex heights
against the e^2 law, energy, momentum drift, dropped steps (must be zero),
the bag and a PNG plot. Exit code 0 when both processes ended cleanly and no
step was dropped, 1 otherwise (``error: ...`` for bad arguments).
"""

from __future__ import annotations

import argparse
import os
import shutil
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Sequence

from collres_ros.ros import cli
from collres_ros.ros.analysis import RunReport, analyse, plot

DEMO_DURATION = 2.5  # s of simulated time by default: four bounces of the default ball
RECORDER_CATCH_UP_S = 20.0   # s: longest wait for the recorder's last messages after the sim
OUTPUT_TOPICS = ('/body_states/corrected', '/contacts', '/contact_markers', '/diagnostics')


class DemoError(cli.CliError):
    """A one-line failure of the demo (printed as ``error: ...``)."""


@dataclass
class DemoResult:
    """What a demo run produced."""

    report: RunReport
    bag: Path
    plot: Path
    node_exit: int | None
    sim_exit: int | None
    wall_s: float
    domain_id: int
    expected_steps: int
    logs: dict[str, Path] = field(default_factory=dict)
    # messages the recorder never got (the publishers' history dropped them first), by topic
    recorder_lost: dict[str, int] = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        return self.node_exit == 0 and self.sim_exit == 0 and self.report.dropped == 0 \
            and self.report.steps_in == self.expected_steps


def _private_domain_id() -> int:
    """An exported ROS_DOMAIN_ID (two users on one host keep apart), else a domain id
    unlikely to collide with other runs on this host (1..100)."""
    exported = os.environ.get('ROS_DOMAIN_ID', '').strip()
    if exported.isdigit() and int(exported) <= cli.DOMAIN_IDS[1]:
        return int(exported)
    return 1 + (os.getpid() + int(time.time())) % 100


def run_demo(out_dir: Path, params: Path | None = None, duration: float | None = None,
             domain_id: int | None = None, storage: str = 'mcap', progress: bool = True,
             timeout: float = 60.0, per_body: bool = False) -> DemoResult:
    """Run node + sim over DDS, record, analyse, plot; DemoError on a failure to start.

    ``per_body``: the sim publishes bodies/<name>/{pose,twist} instead of body_states.
    """
    import rclpy
    from rclpy.executors import SingleThreadedExecutor

    from collres_ros.ros.console import interactive
    progress = progress and interactive()   # a line redrawn in place: terminals only

    from collres_ros.ros import processes
    from collres_ros.ros.bag import BagError, describe, read_messages
    from collres_ros.ros.recorder import Recorder
    from collres_ros.ros.resources import config_path
    from collres_ros.ros.simulation import load_sim_scene

    params = Path(params) if params is not None else config_path('collres.yaml')
    if not params.is_file():
        raise DemoError(f'params file not found: {params}')
    sim_scene = load_sim_scene(params, duration)   # ValueError names a bad parameter
    if duration is None and sim_scene.duration > DEMO_DURATION:
        sim_scene = load_sim_scene(params, DEMO_DURATION)
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    bag = out_dir / 'bag'
    if bag.exists():
        if not (bag / 'metadata.yaml').is_file():
            raise DemoError(f'{bag} exists and is not a bag: not overwriting it')
        shutil.rmtree(bag)
    domain_id = _private_domain_id() if domain_id is None else domain_id
    env = processes.ros_env(domain_id)
    logs = {'node': out_dir / 'node.log', 'sim': out_dir / 'sim.log'}
    expected_steps = sim_scene.steps

    start = time.monotonic()
    context = rclpy.Context()
    node_proc = sim_proc = None
    executor = spinner = recorder = None
    with cli.ros_init(context=context, domain_id=domain_id):
        try:
            node = rclpy.create_node('collres_demo_recorder', context=context)
            try:
                recorder = Recorder(node, bag, storage,
                                    custom_data=describe(sim_scene.scene))
            except BagError as error:
                raise DemoError(str(error)) from None
            executor = SingleThreadedExecutor(context=context)
            executor.add_node(node)
            spinner = threading.Thread(target=executor.spin, daemon=True)
            spinner.start()

            def recorded(topic: str) -> int:
                return recorder.counts.get(topic, 0)

            def subscribed(topic: str) -> bool:
                subscription = recorder.subscription(topic)
                return subscription is not None and subscription.get_publisher_count() > 0

            node_proc = processes.start(
                'collres_node', ['--ros-args', '--params-file', str(params)], env=env,
                log=logs['node'])
            node_up = processes.wait_for(lambda: cli.check_terminated()
                                         or all(subscribed(t) for t in OUTPUT_TOPICS)
                                         or node_proc.poll() is not None, 30.0)
            if not node_up:
                raise DemoError(f'collres_node did not come up within 30 s (log: {logs["node"]})')
            if node_proc.poll() is not None:
                raise DemoError(f'collres_node exited with {node_proc.poll()} '
                                f'(log: {logs["node"]})')
            sim_args = ['--duration', str(sim_scene.duration), '--subscribers', '2'] \
                + (['--per-body'] if per_body else []) \
                + ['--ros-args', '--params-file', str(params)]
            sim_proc = processes.start('collres_sim', sim_args, env=env, log=logs['sim'])

            last = 0.0
            deadline = time.monotonic() + timeout
            while not cli.check_terminated() and sim_proc.poll() is None \
                    and time.monotonic() < deadline:
                if progress and time.monotonic() - last > 0.25:
                    last = time.monotonic()
                    done = recorded('/body_states/corrected')
                    print(f'\rdemo: step {done}/{expected_steps}', end='', file=sys.stderr,
                          flush=True)
                time.sleep(0.02)
            if sim_proc.poll() is None:
                if progress:
                    print(file=sys.stderr)   # end the progress line
                raise DemoError(f'collres_sim did not finish within {timeout} s '
                                f'(log: {logs["sim"]})')
            # the last inputs and answers may still be in flight to the recorder (the node
            # answered them, the recorder's copy can come later: on a loaded machine its one
            # Python executor, taking every per-body topic, lags seconds behind the sim)

            def steps_topic(topic: str) -> bool:
                return topic in ('/body_states', '/body_states/corrected') or (
                    topic.startswith('/bodies/') and topic.endswith(('/pose', '/twist')))

            processes.wait_for(lambda: all(
                count >= expected_steps for topic, count in list(recorder.counts.items())
                if steps_topic(topic)) and recorded('/body_states/corrected') >= expected_steps,
                RECORDER_CATCH_UP_S)
            if progress:
                print(f'\rdemo: step {recorded("/body_states/corrected")}/{expected_steps}',
                      file=sys.stderr)
            node_exit = processes.stop(node_proc)
            node_proc = None
            sim_exit = sim_proc.poll()
            recorder.close()
            executor.shutdown()
        finally:
            for proc in (sim_proc, node_proc):
                if proc is not None and proc.poll() is None:
                    processes.stop(proc)
            if recorder is not None:
                recorder.close()   # an interrupted run still leaves a complete bag
            # the spinning thread must stop before the context goes (else: abort, exit 134)
            if executor is not None:
                executor.shutdown(timeout_sec=2.0)
            if spinner is not None:
                spinner.join(5.0)

    messages = read_messages(bag)
    solver = getattr(sim_scene.scene, 'solver', None)
    rule = getattr(solver, 'restitution_rule', 'max')
    report = analyse(messages, sim_scene.scene.bodies, sim_scene.gravity, rule,
                     initial=sim_scene.scene.initial,
                     driven=sim_scene.drive is not None or bool(sim_scene.kinematic.any()))
    picture = plot(report, out_dir / 'demo.png')
    return DemoResult(report, bag, picture, node_exit, sim_exit, time.monotonic() - start,
                      domain_id, expected_steps, logs,
                      {t: n for t, n in sorted(recorder.losses.lost.items()) if n})


def summary_lines(result: DemoResult) -> list[str]:
    """Return the ten-second report, line by line."""
    lines = [f'collres demo: node + sim over DDS (ROS_DOMAIN_ID {result.domain_id}), '
             f'{result.wall_s:.1f} s']
    lines += result.report.lines()
    lines += [f'dropped steps: {result.report.dropped}'
              + ('' if result.report.dropped == 0 else '  <-- must be zero'),
              f'processes: collres_node exit {result.node_exit}, '
              f'collres_sim exit {result.sim_exit}']
    if result.recorder_lost:
        lines.append(f'recorder lost {sum(result.recorder_lost.values())} messages before '
                     'taking them: ' + ', '.join(f'{t} {n}'
                                                 for t, n in result.recorder_lost.items()))
    lines += [f'bag:  {result.bag.resolve()}', f'plot: {result.plot.resolve()}']
    return lines


def parser() -> argparse.ArgumentParser:
    p = cli.ArgumentParser(
        prog='collres_demo',
        description='Run collres_node and collres_sim over DDS, record a bag, report and plot.')
    p.add_argument('--params', help='scene params file (default: the package collres.yaml)')
    p.add_argument('--scene', help='a shipped scene instead: config/scenes/SCENE.yaml '
                                   '(e.g. arm, the robot scene)')
    p.add_argument('--duration', type=cli.number(0.0, 86400.0, above=True),
                   help=f's of simulated time (default: the scene\'s, at most {DEMO_DURATION})')
    p.add_argument('--out', default='demo_out', help='output directory (default: ./demo_out)')
    p.add_argument('--domain-id', type=cli.domain_id_type,
                   help='ROS_DOMAIN_ID, 0 to 232 (default: an exported ROS_DOMAIN_ID, else a '
                        'private one)')
    p.add_argument('--storage', default='mcap', help='bag storage: mcap or sqlite3')
    p.add_argument('--timeout', type=cli.number(0.0, 86400.0, above=True), default=60.0,
                   help='s allowed for the sim to run')
    p.add_argument('--per-body', action='store_true',
                   help='the sim publishes bodies/<name>/{pose,twist} instead of body_states')
    return p


def _run(args: argparse.Namespace) -> int:
    if args.scene and args.params:
        raise cli.CliError('--scene and --params: give one')
    params = Path(args.params) if args.params else None
    if args.scene:
        from collres_ros.ros.resources import config_path
        params = config_path(f'scenes/{args.scene}.yaml')   # FileNotFoundError: one line
    result = run_demo(Path(args.out), params,
                      args.duration, args.domain_id, args.storage,
                      timeout=args.timeout, per_body=args.per_body)
    for line in summary_lines(result):
        print(line)
    return 0 if result.ok else 1


def main(argv: Sequence[str] | None = None) -> int:
    """Console script ``collres_demo``: 0 when the run was clean, 1 otherwise."""
    args = parser().parse_args(argv)
    cli.terminate_as_interrupt()   # SIGTERM stops the children and finishes the bag, as Ctrl-C
    return cli.run(lambda: _run(args))


if __name__ == '__main__':
    sys.exit(main())
