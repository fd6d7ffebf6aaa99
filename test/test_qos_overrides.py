"""QoS overrides of collres_node over real DDS: a best-effort estimator connects with one line.

The node's topics are reliable by default; a params file may override the
policies of any of its publishers and subscriptions (rclpy's
``qos_overrides./<topic>.<publisher|subscription>.<policy>``). Each check here
is a positive event: an answer received, or DDS reporting an incompatible QoS
(a best-effort writer never matches a reliable reader, and the reverse).
"""

from __future__ import annotations

import pytest
from geometry_msgs.msg import PoseStamped, TwistStamped
from rclpy.event_handler import PublisherEventCallbacks, SubscriptionEventCallbacks
from rclpy.qos import QoSProfile, ReliabilityPolicy
from ros_harness import Peer, answered, write_scene

from collres_ros.msg import BodyStateArray, ContactArray
from collres_ros.ros import processes
from collres_ros.ros.messages import stamp_ns
from test_node import T0, body, states

pytestmark = pytest.mark.slow

OVERRIDES = '''    qos_overrides:
      /body_states:
        subscription:
          reliability: best_effort
      /contacts:
        publisher:
          reliability: best_effort
'''
BEST_EFFORT = QoSProfile(depth=10, reliability=ReliabilityPolicy.BEST_EFFORT)
RELIABLE = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)


def test_overrides_let_a_best_effort_publisher_connect(ros_domain, tmp_path):
    scene = write_scene(tmp_path / 'scene.yaml', extra_node=OVERRIDES)
    node = processes.start('collres_node', ['--ros-args', '--params-file', str(scene)],
                           env=processes.ros_env(ros_domain), log=tmp_path / 'node.log')
    peer = Peer(ros_domain)
    incompatible: list[str] = []
    try:
        peer.listen('body_states/corrected', BodyStateArray)
        # overridden: best effort in, answers out
        states_pub = peer.node.create_publisher(BodyStateArray, 'body_states', BEST_EFFORT)
        # not overridden: a best-effort pose writer does not match the reliable subscription
        pose_pub = peer.node.create_publisher(
            PoseStamped, 'bodies/ball/pose', BEST_EFFORT, event_callbacks=PublisherEventCallbacks(
                incompatible_qos=lambda event: incompatible.append('pose')))
        # overridden publisher: best-effort contacts do not serve a reliable reader
        peer.node.create_subscription(
            ContactArray, 'contacts', lambda msg: None, RELIABLE,
            event_callbacks=SubscriptionEventCallbacks(
                incompatible_qos=lambda event: incompatible.append('contacts')))
        up = peer.wait(lambda: states_pub.get_subscription_count() > 0, 30.0)
        assert up, f'the best-effort body_states publisher did not match: {node.output()}'

        stamp = T0
        msg = states(stamp, [body('ball', 0.5), body('box', 0.1, x=1.0)])

        def answered():
            return any(stamp_ns(m.header.stamp) == stamp
                       for m in peer.messages('body_states/corrected'))
        # best effort may drop a sample while discovery settles: publish until answered
        for _ in range(40):
            states_pub.publish(msg)
            if peer.wait(answered, 0.5):
                break
        assert answered(), f'no answer to a best-effort body_states: {node.output()}'

        assert peer.wait(lambda: {'pose', 'contacts'} <= set(incompatible), 20.0), \
            f'incompatible QoS events seen: {sorted(set(incompatible))}'
        print('answered a best-effort input; incompatible QoS reported on',
              sorted(set(incompatible)))
        assert pose_pub.get_subscription_count() == 0
    finally:
        peer.close()
        if node.poll() is None:
            processes.stop(node)


PER_BODY = '''    qos_overrides:
      /bodies/ball/pose:
        subscription:
          reliability: best_effort
'''


def test_per_body_overrides_apply_and_only_those_set_are_declared(ros_domain, tmp_path):
    """A per-body topic takes its override as any topic does (a best-effort pose writer
    matches), and ``ros2 param`` shows it; per-body topics without one declare nothing
    (four declared per topic made a 1000-body scene declare 16,000 parameters)."""
    from rclpy.parameter_client import AsyncParameterClient
    scene = write_scene(tmp_path / 'scene.yaml', extra_node=PER_BODY)
    node = processes.start('collres_node', ['--ros-args', '--params-file', str(scene)],
                           env=processes.ros_env(ros_domain), log=tmp_path / 'node.log')
    peer = Peer(ros_domain)
    try:
        ball = peer.node.create_publisher(PoseStamped, 'bodies/ball/pose', BEST_EFFORT)
        assert peer.wait(lambda: ball.get_subscription_count() > 0, 30.0), node.output()
        client = AsyncParameterClient(peer.node, 'collres_node')
        assert client.wait_for_services(10.0)
        listed = answered(peer, lambda: client.list_parameters(['qos_overrides'], 0))
        names = sorted(n for n in listed.result.names if '/bodies/' in n)
        print('per-body QoS parameters:', names)
        assert names == ['qos_overrides./bodies/ball/pose.subscription.reliability']
        got = answered(peer, lambda: client.get_parameters(names))
        assert got.values[0].string_value == 'best_effort'
        reliable = peer.node.create_publisher(PoseStamped, 'bodies/box/pose', BEST_EFFORT)
        box = peer.node.create_publisher(TwistStamped, 'bodies/box/twist', RELIABLE)
        assert peer.wait(lambda: box.get_subscription_count() > 0, 30.0), node.output()
        assert reliable.get_subscription_count() == 0   # not overridden: still reliable
    finally:
        peer.close()
        if node.poll() is None:
            processes.stop(node)
