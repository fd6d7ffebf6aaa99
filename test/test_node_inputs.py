"""The node in this process: its inputs are taken by threads of its own, not by the executor,
and what its start built is out of the garbage collector's passes (``ros/inputs.py``)."""

from __future__ import annotations

import gc
import time

import pytest
import rclpy
from geometry_msgs.msg import PoseStamped, TwistStamped
from ros_harness import Peer, write_scene

from collres_ros.msg import BodyState, BodyStateArray
from collres_ros.ros.messages import stamp_ns, to_stamp
from collres_ros.ros.node import CollresNode

pytestmark = pytest.mark.slow
T0 = 2_000 * 10**9
DT = 10**9 // 100


@pytest.fixture
def node(ros_domain, tmp_path):
    """A CollresNode on the floor + ball + box scene whose executor never spins."""
    scene = write_scene(tmp_path / 'scene.yaml')
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=ros_domain,
               args=['collres_node', '--ros-args', '--params-file', str(scene)])
    created = CollresNode(tmp_path, context=context)
    created.start_inputs()   # what the executable's main does once its executor exists
    try:
        yield created
    finally:
        created.destroy_node()
        rclpy.try_shutdown(context=context)
        gc.unfreeze()


def at_rest(stamp):
    msg = BodyStateArray(bodies=[BodyState(name='ball'), BodyState(name='box')])
    msg.header.frame_id, msg.header.stamp = 'world', to_stamp(stamp)
    msg.bodies[0].pose.position.z, msg.bodies[1].pose.position.x = 1.0, 1.0
    msg.bodies[1].pose.position.z = 0.1
    for b in msg.bodies:
        b.pose.orientation.w = 1.0
    return msg


def both_sides_matched(node, peer):
    """Every input matched on both sides (the peer's publisher has the node's subscription
    and the node's subscription has the peer's publisher: a message sent before the reader
    matched the writer can be lost), the node's answer matched both ways, and the node's
    per-body answer's publisher has matched the peer's reader (an answer goes only to a
    topic with a subscriber)."""
    return (all(peer.connected(t) for t in peer.publishers)
            and node._inputs[0].get_publisher_count() > 0
            and per_body_matched(node.per_body_inputs)
            and node._publisher('body_states/corrected',
                                BodyStateArray).get_subscription_count() > 0
            and all(s.get_publisher_count() > 0 for s in peer.node.subscriptions
                    if s.topic_name == '/body_states/corrected'))


def per_body_matched(per_body, answered=(('ball', 0),)):
    """The node subscribes to the four per-body inputs of ball and box (made once a peer
    publishes on them), each has matched its publisher, and each answer of ``answered``
    ((body, 0 pose / 1 twist)) has matched its subscriber."""
    subscriptions = [s for s in per_body.node.subscriptions
                     if s.topic_name.split('/')[2] in ('ball', 'box')]
    return (len(subscriptions) == 4 and all(s.get_publisher_count() > 0 for s in subscriptions)
            and all(name in per_body.publishers
                    and per_body.publishers[name][kind].get_subscription_count() > 0
                    for name, kind in answered))


def test_inputs_are_answered_while_the_executor_never_spins(node, ros_domain):
    """No executor spins this node (as when it is busy with a parameter change or a
    service): every body_states step and every per-body step is still answered."""
    peer = Peer(ros_domain)
    try:
        peer.listen('body_states/corrected', BodyStateArray)
        peer.listen('bodies/ball/pose/corrected', PoseStamped)
        peer.advertise('body_states', BodyStateArray)
        for name in ('ball', 'box'):
            peer.advertise(f'bodies/{name}/pose', PoseStamped)
            peer.advertise(f'bodies/{name}/twist', TwistStamped)
        assert peer.wait(lambda: both_sides_matched(node, peer), 30.0)
        stamps = [T0 + k * DT for k in range(5)]
        for stamp in stamps:
            peer.publish('body_states', at_rest(stamp))
        assert peer.wait(lambda: {stamp_ns(m.header.stamp) for m in
                                  peer.messages('body_states/corrected')} >= set(stamps), 20.0)
        per_body = T0 + 10 * DT
        per_body_step(peer, per_body)
        assert peer.wait(lambda: any(stamp_ns(m.header.stamp) == per_body for m in
                                     peer.messages('bodies/ball/pose/corrected')), 20.0)
    finally:
        peer.close()


def per_body_step(peer, stamp):
    """Both bodies' pose and twist at ``stamp``, at rest (one per-body step)."""
    for body in at_rest(stamp).bodies:
        pose, twist = PoseStamped(pose=body.pose), TwistStamped(twist=body.twist)
        for message in (pose, twist):
            message.header.frame_id, message.header.stamp = 'world', to_stamp(stamp)
        peer.publish(f'bodies/{body.name}/pose', pose)
        peer.publish(f'bodies/{body.name}/twist', twist)


def test_a_per_body_answer_goes_only_to_a_topic_with_a_subscriber(node, ros_domain):
    """Of the four per-body answer topics (ball, box; pose, twist) a peer subscribes to one:
    it gets every step's answer and nothing else is published. Then it subscribes to a
    second: from the step after its match on, that one is answered too."""
    per_body = node.per_body_inputs
    peer = Peer(ros_domain)
    try:
        peer.listen('bodies/ball/pose/corrected', PoseStamped)
        for name in ('ball', 'box'):
            peer.advertise(f'bodies/{name}/pose', PoseStamped)
            peer.advertise(f'bodies/{name}/twist', TwistStamped)
        assert peer.wait(lambda: all(peer.connected(t) for t in peer.publishers)
                         and per_body_matched(per_body), 30.0)
        first = [T0 + k * DT for k in range(5)]
        for stamp in first:
            per_body_step(peer, stamp)
        assert peer.wait(lambda: {stamp_ns(m.header.stamp) for m in
                                  peer.messages('bodies/ball/pose/corrected')} >= set(first),
                         20.0)
        assert peer.wait(lambda: per_body.published >= len(first), 5.0)
        assert per_body.published == len(first)   # 4 x 5 when every topic is published
        peer.listen('bodies/box/twist/corrected', TwistStamped)
        assert peer.wait(lambda: per_body.publishers['box'][1].get_subscription_count() > 0
                         and all(s.get_publisher_count() > 0 for s in peer.node.subscriptions),
                         30.0)
        then = [T0 + k * DT for k in range(5, 8)]
        for stamp in then:
            per_body_step(peer, stamp)
        assert peer.wait(lambda: {stamp_ns(m.header.stamp) for m in
                                  peer.messages('bodies/box/twist/corrected')} == set(then),
                         20.0)
        assert peer.wait(lambda: per_body.published >= len(first) + 2 * len(then), 5.0)
        assert per_body.published == len(first) + 2 * len(then)
    finally:
        peer.close()


def test_tf_is_taken_while_the_executor_never_spins(ros_domain, tmp_path):
    """/tf and /tf_static are served by the input thread, as body_states is: with no executor
    spinning, a /tf_static transform still poses the robot's root link."""
    import yaml
    from geometry_msgs.msg import TransformStamped
    from test_robot import MESHES, arm_urdf
    from tf2_msgs.msg import TFMessage

    from collres_ros.ros import qos
    scene = tmp_path / 'robot.yaml'
    scene.write_text(yaml.safe_dump({'/**': {'ros__parameters': {
        'bodies': ['crate'], 'robot_description': arm_urdf(f'file://{MESHES}'),
        'body': {'crate': {'shape': 'box', 'size': [0.03, 0.03, 0.03], 'mass': 0.5}}}}}))
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=ros_domain,
               args=['collres_node', '--ros-args', '--params-file', str(scene)])
    created = CollresNode(tmp_path, context=context)
    created.start_inputs()
    peer = Peer(ros_domain)
    try:
        static = peer.node.create_publisher(TFMessage, '/tf_static', qos.tf_static_qos())
        t = TransformStamped()
        t.header.frame_id, t.child_frame_id = 'world', 'base_link'
        t.header.stamp.sec = 5_000
        t.transform.translation.x, t.transform.rotation.w = 1.0, 1.0
        static.publish(TFMessage(transforms=[t]))

        def posed() -> bool:
            with created._lock:
                found = created.tf_links.world_pose('base_link')
            return found is not None and found[0][0] == pytest.approx(1.0)
        assert peer.wait(posed, 20.0)
    finally:
        peer.close()
        created.destroy_node()
        rclpy.try_shutdown(context=context)
        gc.unfreeze()


def test_what_the_start_built_is_out_of_the_collectors_passes(node):
    """A full collection walks only what the steps left: the node, its resolver and its
    codecs are frozen (gc.freeze) once it is configured."""
    tracked = gc.get_objects()   # generations 0 to 2: the frozen objects are not in them
    for kept in (node, node.resolver, node.states_codec, node.encoder, node.scene):
        assert not any(o is kept for o in tracked), type(kept).__name__
    assert gc.get_freeze_count() > 0


def test_the_scene_parameters_are_described_and_checked_as_declared_ones(node):
    """What ``ros2 param describe`` and ``set`` see of the scene's parameters, whose
    descriptors are built when first read: each its own name, range and read-only flag; a
    set is checked against them by rclpy (range, read-only) and by the node."""
    from rclpy.parameter import Parameter
    restitution, mass = node.describe_parameters(['body.ball.restitution', 'body.ball.mass'])
    assert (restitution.name, restitution.read_only) == ('body.ball.restitution', False)
    assert (restitution.floating_point_range[0].from_value,
            restitution.floating_point_range[0].to_value) == (0.0, 1.0)
    assert (mass.name, mass.read_only) == ('body.ball.mass', True)
    assert node.describe_parameter('body.box.restitution').name == 'body.box.restitution'
    results = node.set_parameters([Parameter('body.ball.restitution', value=1.5)]
                                  + [Parameter('body.ball.mass', value=2.0)]
                                  + [Parameter('body.box.restitution', value=0.25)])
    assert [r.successful for r in results] == [False, False, True], results
    assert node.get_parameter('body.box.restitution').value == 0.25
    assert node.scene.bodies[node.scene.names.index('box')].restitution == 0.25
    assert node.describe_parameter('body.box.restitution').floating_point_range


def test_what_a_cleanup_releases_is_freed(node):
    """A managed node's cleanup (release_resolution) unfreezes what its configure froze: an
    object it drops is freed by the collector even in a reference cycle (a frozen cycle is
    never collected: refcounts alone free the resolver today, a cycle in it would keep it
    for good), and a configure after it freezes the new objects."""
    import weakref
    dropped = weakref.ref(node.resolver)
    node.resolver.world.owner = node.resolver   # a cycle: resolver -> world -> resolver
    node.release_resolution()
    gc.collect()
    assert dropped() is None
    node.configure_resolution()
    assert gc.get_freeze_count() > 0 and node.resolver is not None


def test_steps_answered_while_a_newer_input_waits_skip_only_their_markers(node, ros_domain):
    """Behind (a newer body_states input waits when a step is answered), the node answers
    every input and publishes every step's contacts (an impact is an event a user must not
    lose) but skips its markers, counting those steps in /diagnostics
    (``outputs_skipped_behind``): ten inputs queued while the node is busy get ten answers,
    ten contacts messages and one contact_markers message, the last step's."""
    from rclpy.duration import Duration

    from collres_ros.msg import ContactArray
    from visualization_msgs.msg import MarkerArray
    peer = Peer(ros_domain)
    try:
        peer.listen('body_states/corrected', BodyStateArray)
        peer.listen('contacts', ContactArray)
        peer.listen('contact_markers', MarkerArray)
        peer.advertise('body_states', BodyStateArray)
        assert peer.wait(lambda: peer.connected('body_states') and node._publisher(
            'contacts', ContactArray).get_subscription_count() > 0 and node._publisher(
            'contact_markers', MarkerArray).get_subscription_count() > 0, 30.0)
        stamps = [T0 + k * DT for k in range(10)]
        with node._lock:   # busy: the inputs queue up (keep last 10: all of them)
            for stamp in stamps:
                peer.publish('body_states', at_rest(stamp))
            assert peer.publishers['body_states'].wait_for_all_acked(Duration(seconds=20))
            acked = time.time_ns()   # every input was received by the node's DDS before this
            released = time.time_ns()   # and taken after this
        assert peer.wait(lambda: {stamp_ns(m.header.stamp) for m in
                                  peer.messages('body_states/corrected')} >= set(stamps), 20.0)
        assert peer.wait(lambda: len(peer.messages('contacts')) >= 10, 20.0)
        assert peer.wait(lambda: len(peer.messages('contact_markers')) >= 1, 20.0)
        with node._lock:
            assert node.skipped_behind == 9
            extra = node.snapshot().extra
            assert extra['outputs_skipped_behind'] == 9
        # every input waited from its reception (before ``acked``) past the lock's release
        assert float(extra['queued_max_ms']) >= (released - acked) / 1e6
        assert float(extra['queued_max_ms']) >= float(extra['time.queued_ms']) > 0.0
        assert [stamp_ns(m.header.stamp) for m in peer.messages('contacts')] == stamps
        markers = peer.messages('contact_markers')
        assert len(markers) == 1 and markers[0].markers
        assert {stamp_ns(m.header.stamp) for m in markers[0].markers} == {stamps[-1]}
    finally:
        peer.close()


def test_the_node_sends_through_a_large_shared_memory_segment_unless_told_otherwise(
        tmp_path, monkeypatch):
    """A step's outputs outgrow Fast DDS's 512 KB shared-memory segment from a few hundred
    bodies in contact on: the node's process takes the shipped profile (a 16 MB segment,
    Fast DDS's two transports) unless the rmw is another or the user configured Fast DDS."""
    import xml.etree.ElementTree as ElementTree

    from collres_ros.ros.node import FASTDDS_SETTINGS, large_outputs_profile
    monkeypatch.chdir(tmp_path)
    environ: dict[str, str] = {}
    path = large_outputs_profile(environ)
    assert path is not None and environ == {'FASTRTPS_DEFAULT_PROFILES_FILE': path}
    space = '{http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles}'
    shm = [d for d in ElementTree.parse(path).getroot().iter(f'{space}transport_descriptor')
           if d.findtext(f'{space}type') == 'SHM']
    assert [int(d.findtext(f'{space}segment_size')) for d in shm] == [16 * 2**20]
    for setting in FASTDDS_SETTINGS:
        assert large_outputs_profile({setting: 'mine.xml'}) is None
    assert large_outputs_profile({'RMW_IMPLEMENTATION': 'rmw_cyclonedds_cpp'}) is None
    (tmp_path / 'DEFAULT_FASTRTPS_PROFILES.xml').write_text('<profiles/>')
    assert large_outputs_profile({}) is None
