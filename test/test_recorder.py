"""A recorder that stalls loses no step: the publishers keep what it has not acknowledged.

A reader process stopped (SIGSTOP: descheduled, as on a loaded machine) while the sim's
input and the node's answer are published many steps, more than DDS's transport queues
hold (about 500 messages), fewer than the publishers keep; resumed, it records every step.
Publishers that keep fewer (depth 10) lose steps to it, and the recorder counts every one:
recorded + lost = published.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip('rclpy')

from ros_harness import Peer  # noqa: E402

STEPS = 600   # per topic: 1200 messages, beyond the transport's queues
# The recorder of collres_demo in a process of its own, until it has recorded or counted as
# lost every step (or 30 s); it prints the messages it counted as lost, by topic.
CHILD = '''
import json, sys, time
import rclpy
from collres_ros.ros.recorder import Recorder
topics, steps = sys.argv[2].split(','), int(sys.argv[3])
rclpy.init()
node = rclpy.create_node('stalled_recorder')
recorder = Recorder(node, sys.argv[1])
deadline = time.monotonic() + 30.0
while time.monotonic() < deadline and any(
        recorder.counts.get(t, 0) + recorder.losses.lost[t] < steps for t in topics):
    rclpy.spin_once(node, timeout_sec=0.05)
recorder.close()
rclpy.shutdown()
print(json.dumps(dict(recorder.losses.lost)))
'''


@pytest.mark.parametrize('depth', [None, 10])
def test_a_stalled_recorder_receives_every_step_or_counts_it_lost(
        tmp_path: Path, ros_domain: int, depth: int | None) -> None:
    """``depth`` None: the profiles collres_sim and collres_node offer; else keep last
    ``depth``."""
    from geometry_msgs.msg import PoseStamped

    from collres_ros.msg import BodyStateArray
    from collres_ros.ros import qos
    from collres_ros.ros.bag import BagReader
    from rclpy.duration import Duration
    topics = {'/bodies/ball/pose': PoseStamped,            # collres_sim's per-body input
              '/body_states/corrected': BodyStateArray}     # collres_node's answer
    peer = Peer(ros_domain)
    child = None
    try:
        publishers = {topic: peer.node.create_publisher(
            kind, topic, qos.offered(topic, 10) if depth is None else qos.state_qos(depth))
            for topic, kind in topics.items()}
        bag = tmp_path / 'bag'
        child = subprocess.Popen([sys.executable, '-c', CHILD, str(bag), ','.join(topics),
                                  str(STEPS)], stdin=subprocess.DEVNULL,
                                 stdout=subprocess.PIPE, text=True)
        assert peer.wait(lambda: all(p.get_subscription_count() > 0
                                     for p in publishers.values()), 30.0)

        def publish(step: int) -> None:
            for topic, kind in topics.items():
                msg = kind()
                msg.header.stamp.sec = step
                publishers[topic].publish(msg)
        publish(0)   # the recorder has matched both publishers once it acknowledged a step
        assert all(p.wait_for_all_acked(Duration(seconds=30)) for p in publishers.values())
        os.kill(child.pid, signal.SIGSTOP)
        try:
            for step in range(1, STEPS):
                publish(step)
        finally:
            os.kill(child.pid, signal.SIGCONT)
        out, _ = child.communicate(timeout=90)
        assert child.returncode == 0
        lost = json.loads(out.strip().splitlines()[-1])
        with BagReader(bag) as reader:
            counts = {topic: reader.topic_count(topic) for topic in topics}
        print(counts, 'recorded and', lost, 'lost of', STEPS, 'steps; the publishers keep',
              {topic: p.qos_profile.depth for topic, p in publishers.items()})
        if depth is None:
            assert counts == {topic: STEPS for topic in topics} and not any(lost.values())
        else:   # what the shallow history dropped is lost to the bag, and counted
            assert all(counts[t] < STEPS and counts[t] + lost.get(t, 0) == STEPS
                       for t in topics)
    finally:
        if child is not None and child.poll() is None:
            os.kill(child.pid, signal.SIGCONT)
            child.kill()
            child.wait()
        peer.close()
