"""collres_sim: the integrator, offline recording, and that replay reproduces the recording."""

from __future__ import annotations

import re
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from collres_ros.core.types import BodyStates
from collres_ros.ros.integrator import euler_step

SCENES = Path(__file__).resolve().parent.parent / 'config' / 'scenes'


def test_semi_implicit_euler_free_fall_matches_its_closed_form() -> None:
    """v_n = v0 + g n dt, z_n = z0 + dt sum v_k = z0 + g dt^2 n (n + 1) / 2 (exact to 1e-12)."""
    states = BodyStates.zeros(2)
    states.position[:, 2] = 1.0
    states.angular[0] = (0.0, 0.0, np.pi)   # half a turn per second about z
    dynamic = np.array([True, False])
    g, dt, n = np.array([0.0, 0.0, -9.81]), 0.01, 50
    for _ in range(n):
        states = euler_step(states, dynamic, g, dt)
    assert states.linear[0, 2] == pytest.approx(-9.81 * n * dt, abs=1e-12)
    assert states.position[0, 2] == pytest.approx(1.0 - 9.81 * dt * dt * n * (n + 1) / 2,
                                                  abs=1e-12)
    # a quarter turn about z after 0.5 s: q = (0, 0, sin(pi/4), cos(pi/4))
    assert states.orientation[0] == pytest.approx([0, 0, np.sin(np.pi / 4),
                                                   np.cos(np.pi / 4)], abs=1e-12)
    # the static body did not move
    assert states.position[1, 2] == 1.0 and not states.linear[1].any()


def test_every_scene_loads_and_its_stamps_cover_the_duration() -> None:
    pytest.importorskip('yaml')
    from collres_ros.ros.simulation import load_sim_scene, stamps
    names = sorted(p.stem for p in SCENES.glob('*.yaml'))
    assert {'bouncing_ball', 'billiard_break', 'box_slide', 'slope_hold', 'slope_slide',
            'box_stack', 'fast_sphere_wall', 'pile'} <= set(names)
    for name in names:
        sim = load_sim_scene(SCENES / f'{name}.yaml')
        all_stamps = stamps(sim.rate_hz, sim.duration)
        assert len(all_stamps) == round(sim.duration * sim.rate_hz) + 1, name
        assert (all_stamps[-1] - all_stamps[0]) * 1e-9 == pytest.approx(sim.duration, abs=1e-9)
        assert sim.dynamic.any(), name
    pile = load_sim_scene(SCENES / 'pile.yaml')
    assert int(pile.dynamic.sum()) == 100
    assert {b.shape for b in pile.scene.bodies} >= {'sphere', 'box', 'capsule', 'cylinder',
                                                    'cone', 'convex'}


def test_offline_records_inputs_and_every_output(tmp_path: Path) -> None:
    pytest.importorskip('rclpy')
    from collres_ros.ros.bag import BagReader
    from collres_ros.sim import main
    bag = tmp_path / 'ball'
    assert main(['--offline', '--params', str(SCENES / 'bouncing_ball.yaml'),
                 '--duration', '0.5', '--record', str(bag), '--storage', 'sqlite3']) == 0
    with BagReader(bag) as reader:
        assert reader.storage == 'sqlite3'
        for topic in ('/body_states', '/body_states/corrected', '/contacts',
                      '/contact_markers', '/diagnostics'):
            assert topic in reader.topics, reader.topics
        assert reader.topic_count('/body_states') == 121
        assert reader.topic_count('/body_states/corrected') == 121


def test_offline_closes_the_loop_and_replay_reproduces_it(tmp_path: Path) -> None:
    """The sim adopts the corrected state: the ball bounces (and replay gives the same outputs)."""
    pytest.importorskip('rclpy')
    from collres_ros.ros.bag import message_fields, read_messages
    from collres_ros.ros.offline import replay
    from collres_ros.ros.offline import run_offline
    from collres_ros.ros.simulation import load_sim_scene
    params = SCENES / 'bouncing_ball.yaml'
    run_offline(load_sim_scene(params, 0.8), tmp_path / 'rec')
    recorded = read_messages(tmp_path / 'rec')
    inputs = [m.msg.bodies[0] for m in recorded if m.topic == '/body_states']
    heights = np.array([b.pose.position.z for b in inputs])
    assert heights.min() > 0.1 - 0.005, 'the ball went through the floor'
    assert heights[-1] > heights.min() + 0.05, 'the ball did not bounce back up'
    replay(tmp_path / 'rec', tmp_path / 'out', params)
    topics = ('/body_states/corrected', '/contacts')
    expected = [(m.log_time, message_fields(m.msg)) for m in recorded if m.topic in topics]
    got = [(m.log_time, message_fields(m.msg)) for m in read_messages(tmp_path / 'out')
           if m.topic in topics]
    assert got == expected


def test_offline_errors_are_one_line(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    from collres_ros.sim import main
    assert main(['--offline', '--params', str(tmp_path / 'none.yaml'),
                 '--record', str(tmp_path / 'b')]) == 1
    assert capsys.readouterr().err.startswith('error: params file not found')
    assert main(['--offline', '--params', str(SCENES / 'bouncing_ball.yaml')]) == 1
    assert 'needs --record' in capsys.readouterr().err
    assert main(['--offline', '--params', str(SCENES / 'bouncing_ball.yaml'),
                 '--record', str(tmp_path / 'b'), '--storage', 'hdf5']) == 1
    assert "unknown storage 'hdf5'" in capsys.readouterr().err


def test_pile_scene_is_what_its_generator_writes(tmp_path: Path) -> None:
    """config/scenes/pile.yaml is generated: edit tools/make_pile_scene.py, not the yaml."""
    import subprocess
    import sys
    tool = Path(__file__).resolve().parent.parent / 'tools' / 'make_pile_scene.py'
    subprocess.run([sys.executable, str(tool), str(tmp_path / 'pile.yaml')], check=True,
                   capture_output=True)
    assert (tmp_path / 'pile.yaml').read_text() == (SCENES / 'pile.yaml').read_text()


def against_a_fake_node(tmp_path: Path, sim_args: list[str], respond: Any, raw: bool = False,
                        depth: int = 10, between: Any = None, matched: Any = None,
                        domain: int | None = None) -> tuple[int, str]:
    """``collres_sim`` on the bouncing ball (``sim_args`` added) over DDS against a fake
    collres_node in this process: each ``body_states`` message goes to ``respond(message,
    answer)`` (``answer``: the fake's ``body_states/corrected`` publisher; ``raw``: the
    message as bytes), ``between(answer, sim)`` runs after each spin (``sim``: the sim's
    process). Every 0.05 s the fake
    reports on ``/diagnostics``, as collres_node does, the ``body_states`` publishers it has
    matched: ``matched(count)`` of its subscription's count (default: that count).
    (exit code, sim's log)."""
    pytest.importorskip('rclpy')
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import QoSProfile, ReliabilityPolicy

    from collres_ros.msg import BodyStateArray
    from collres_ros.ros import processes
    from conftest import next_domain_id
    domain = next_domain_id() if domain is None else domain
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=domain)
    try:
        node = rclpy.create_node('fake_collres_node', context=context)
        qos = QoSProfile(depth=depth, reliability=ReliabilityPolicy.RELIABLE)
        answer = node.create_publisher(BodyStateArray, 'body_states/corrected', qos)
        inputs = node.create_subscription(BodyStateArray, 'body_states',
                                          lambda message: respond(message, answer), qos,
                                          raw=raw)
        diagnostics = node.create_publisher(DiagnosticArray, '/diagnostics', 10)

        def report() -> None:
            count = inputs.get_publisher_count()
            count = count if matched is None else matched(count)
            diagnostics.publish(DiagnosticArray(status=[DiagnosticStatus(
                name='/fake_collres_node: resolver',
                values=[KeyValue(key='body_states_publishers', value=str(count))])]))
        node.create_timer(0.05, report)
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(node)
        sim = processes.start('collres_sim', ['--params', str(SCENES / 'bouncing_ball.yaml'),
                                              *sim_args],
                              env=processes.ros_env(domain), log=tmp_path / 'sim.log')

        def serve() -> bool:
            executor.spin_once(timeout_sec=0.002)
            if between is not None:
                between(answer, sim)
            return sim.poll() is not None
        assert processes.wait_for(serve, 60.0), 'sim did not finish'
        code = sim.wait()
    finally:
        rclpy.try_shutdown(context=context)
    log = sim.output()
    print(log[-600:])
    return code, log


@pytest.mark.slow
def test_live_sim_counts_unanswered_steps_as_dropped(tmp_path: Path) -> None:
    """A responder that ignores every 5th state: the sim waits its deadline, drops, goes on."""
    received: list[int] = []

    def respond(msg: Any, answer: Any) -> None:
        received.append(msg.header.stamp.nanosec)
        if len(received) % 5 != 0:
            answer.publish(msg)
    code, log = against_a_fake_node(tmp_path, ['--duration', '0.1', '--step-timeout', '0.2'],
                                    respond)
    assert code == 0
    assert len(received) == 25            # 0.1 s at 240 Hz: 25 states, each published once
    assert 'done: 25 steps, 5 dropped' in log


def test_realtime_pace_warns_behind_the_clock_and_with_the_rate_reached() -> None:
    from collres_ros.ros.simulation import RealtimePace
    pace = RealtimePace(100.0, start=10.0)
    assert pace.late(100, 11.0) is None              # step 100 due at 11 s: on time
    assert pace.late(100, 11.4) is None              # within the lag allowed
    text = pace.late(100, 12.0)                      # 1 s behind
    assert text is not None and '1.0 s behind' in text and '50 steps/s' in text
    assert pace.late(150, 14.0) is None              # warned less than a period ago
    assert pace.summary(101, 11.0) is None           # step 100 published at 11 s: 100 Hz
    assert pace.summary(21, 10.2128) is None         # 0.2 s run, its last step 13 ms late
    short = pace.summary(101, 12.0)
    assert short is not None and 'reached 50 steps/s of the 100 Hz asked' in short


@pytest.mark.slow
def test_live_realtime_sim_warns_with_the_rate_it_reached(tmp_path: Path) -> None:
    """50 kHz cannot be kept (a step waits for an answer over DDS): the sim says so."""
    code, log = against_a_fake_node(
        tmp_path, ['--rate', '50000', '--duration', '0.004', '--realtime'],
        lambda data, answer: answer.publish(data), raw=True)
    assert code == 0 and 'done: 201 steps' in log
    found = re.search(r'realtime: reached (\d+) steps/s of the 50000 Hz asked', log)
    assert found, log
    assert int(found.group(1)) < 0.95 * 50000


@pytest.mark.slow
def test_live_realtime_sim_keeps_its_rate_and_counts_the_late_answers(tmp_path: Path) -> None:
    """A node whose answers come 3 steps late: the realtime sim does not wait for them (it
    would step at a third of the rate): each step goes on with the sim's own state, and the
    sim says how many answers came after the next step was due."""
    held: list[tuple[float, bytes]] = []
    delay = 0.03   # s: 3 steps at 100 Hz

    def release(answer: Any, sim: Any) -> None:
        while held and time.monotonic() - held[0][0] >= delay:
            answer.publish(held.pop(0)[1])
    code, log = against_a_fake_node(
        tmp_path, ['--rate', '100', '--duration', '0.2', '--realtime'],
        lambda data, answer: held.append((time.monotonic(), data)), raw=True, depth=100,
        between=release)
    # every answer is late, but the first step's may arrive while its delivery is confirmed
    found = re.search(r'done: 21 steps, (\d+) dropped', log)
    assert code == 0 and found and int(found.group(1)) >= 20, log
    assert (f'realtime: {found.group(1)} of 21 answers came after the next step was due'
            in log)
    assert 'reached' not in log and 'behind' not in log


@pytest.mark.slow
def test_live_sim_steps_only_once_the_node_reports_it_matched_the_inputs(
        tmp_path: Path) -> None:
    """A subscriber may have been matched by the sim's publisher before it matched the sim
    (each side discovers the other on its own): the sim's own count says nothing of the
    node's side, and a step sent before the node's side matched is lost to it. The sim
    sends its first step only after the node's /diagnostics counts the sim's publisher
    among the ones it matched: here the fake reports 0 for 1 s after it saw the sim."""
    seen: list[float] = []       # when the fake first saw the sim's publisher
    released: list[float] = []   # when it first reported it matched
    received: list[float] = []

    def matched(count: int) -> int:
        if count and not seen:
            seen.append(time.monotonic())
        if not seen or time.monotonic() < seen[0] + 1.0:
            return 0
        if not released:
            released.append(time.monotonic())
        return count

    def respond(data: bytes, answer: Any) -> None:
        received.append(time.monotonic())
        answer.publish(data)
    code, log = against_a_fake_node(tmp_path, ['--duration', '0.02'], respond, raw=True,
                                    matched=matched)
    assert code == 0 and 'done: 6 steps, 0 dropped' in log, log
    assert released and received[0] > released[0], (released, received[:1])


@pytest.mark.slow
def test_live_sim_leaves_once_every_subscriber_has_every_step(tmp_path: Path) -> None:
    """A subscriber counted with --subscribers (a recorder) that has not acknowledged the
    last steps when the node answered them: the sim waits for its acknowledgement before it
    leaves (a writer that leaves takes its unacknowledged steps with it: a busy reader
    missed the last steps of one run in 20 without this). The recorder here stops itself
    (SIGSTOP) on the second step and is let go once the sim is done stepping."""
    import os
    import signal
    import sys

    from collres_ros.ros import processes
    from conftest import next_domain_id
    domain = next_domain_id()
    recorder_code = (
        'import os, signal, sys, rclpy\n'
        'from rclpy.qos import QoSProfile, ReliabilityPolicy\n'
        'from collres_ros.msg import BodyStateArray\n'
        'rclpy.init()\n'
        "node = rclpy.create_node('recorder')\n"
        'got = []\n'
        'def take(msg):\n'
        '    got.append(msg.header.stamp.nanosec)\n'
        "    print('got', msg.header.stamp.sec, msg.header.stamp.nanosec, flush=True)\n"
        '    if len(got) == 2:\n'
        '        os.kill(os.getpid(), signal.SIGSTOP)\n'
        "node.create_subscription(BodyStateArray, 'body_states', take,\n"
        '    QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE))\n'
        'rclpy.spin(node)\n')
    recorder = processes.start(sys.executable, ['-c', recorder_code],
                               env=processes.ros_env(domain), log=tmp_path / 'recorder.log')
    stopped, left_early = [], []

    def between(answer: Any, sim: Any) -> None:
        if stopped or 'step 6/6' not in sim.output():
            return
        # the sim has its last answer: while the recorder is stopped, it must not leave
        left_early.append(processes.wait_for(lambda: sim.poll() is not None, 2.0))
        stopped.append(True)
        os.kill(recorder.pid, signal.SIGCONT)
    try:
        code, log = against_a_fake_node(
            tmp_path, ['--duration', '0.02', '--subscribers', '2', '--wait', '30'],
            lambda data, answer: answer.publish(data), raw=True, between=between,
            domain=domain)
    finally:
        os.kill(recorder.pid, signal.SIGCONT)
        processes.stop(recorder)
    got = [line for line in recorder.output().splitlines() if line.startswith('got')]
    assert code == 0 and 'done: 6 steps, 0 dropped' in log, log
    assert stopped == [True] and left_early == [False]
    assert len(got) == 6, got
