"""robot_description over DDS: collres_node started with the test arm's URDF poses its links
from body_states by link name, or from /tf and /tf_static; a crate resting on the arm's base
plate gets contacts that name the link and its piece, carrying the crate's weight."""

from __future__ import annotations

import time

import pytest
from test_robot import MESHES, arm_urdf

pytest.importorskip('rclpy')

G, DT_S = 9.81, 0.01
# stamps of our own (not test_node's T0): a node of another suite that shares a domain on
# this host answers only the stamps it is sent, never ours
T_ROBOT = 4_321 * 10**9
T_TF = 5_321 * 10**9


@pytest.mark.slow
@pytest.mark.parametrize('source', ['parameter', 'topic'])
def test_links_posed_by_name_and_contacts_name_their_pieces(ros_domain, tmp_path,
                                                            source) -> None:
    """The URDF as the robot_description parameter, or (robot_description_topic) from the
    robot_description topic, published transient local before the node starts."""
    import yaml
    from ros_harness import Peer, node_and_peer
    from std_msgs.msg import String
    from test_node import body, step

    from collres_ros.msg import BodyStateArray, ContactArray
    from collres_ros.ros import qos
    from collres_ros.ros.robot import link_poses

    urdf = arm_urdf(f'file://{MESHES}')
    scene = tmp_path / 'scene.yaml'
    robot = {'robot_description': urdf} if source == 'parameter' else \
        {'robot_description_topic': True}
    scene.write_text(yaml.safe_dump({'/**': {'ros__parameters': {
        'bodies': ['crate'], **robot,
        'body': {'crate': {'shape': 'box', 'size': [0.03, 0.03, 0.03], 'mass': 0.5}}}}}))
    describer = Peer(ros_domain, 'collres_test_describer')   # as robot_state_publisher
    try:
        if source == 'topic':   # latched, before the node exists
            publisher = describer.node.create_publisher(String, 'robot_description',
                                                        qos.latched_qos())
            publisher.publish(String(data=urdf))
        with node_and_peer(ros_domain, scene, tmp_path / 'node.log', listen=(
                ('body_states/corrected', BodyStateArray), ('contacts', ContactArray)),
                answering=('/body_states/corrected', '/contacts')) as (peer, node):
            links = []
            for name, (p, q) in link_poses(urdf).items():
                if name != 'tool0':
                    state = body(name, float(p[2]), x=float(p[0]),
                                 q=tuple(float(c) for c in q))
                    state.pose.position.y = float(p[1])
                    links.append(state)
            # the crate on the base plate (top at z = 0.01, out to x = 0.15) beside the
            # pedestal (r 0.1): x from 0.115 to 0.145
            z, vz = 0.01 + 0.015, 0.0
            for k in range(20):
                vz -= G * DT_S
                crate = body('crate', z + vz * DT_S, vz, x=0.13)
                out = step(peer, T_ROBOT + k * 10**7, links + [crate])
                crate = [b for b in out.bodies if b.name == 'crate'][0]
                z, vz = crate.pose.position.z, crate.twist.linear.z
            assert z == pytest.approx(0.025, abs=1e-3)           # held by the plate
            stamp = (T_ROBOT + 19 * 10**7) // 10**9, (T_ROBOT + 19 * 10**7) % 10**9
            assert peer.wait(lambda: any((m.header.stamp.sec, m.header.stamp.nanosec) == stamp
                                         for m in peer.messages('contacts')), 10.0)
            last = [m for m in peer.messages('contacts')
                    if (m.header.stamp.sec, m.header.stamp.nanosec) == stamp][-1].contacts
            # the plate carries it (the pedestal beside it is within the speculative margin)
            assert {(c.body_a, c.piece_a, c.body_b, c.piece_b) for c in last
                    if c.normal_impulse > 0.0} == {('crate', '', 'base_link', 'plate')}
            assert sum(c.normal_impulse for c in last) == pytest.approx(0.5 * G * DT_S,
                                                                        rel=0.01)
            if source == 'topic':
                assert 'characters from /robot_description' in node.output()
    finally:
        describer.close()


@pytest.mark.slow
def test_the_demo_runs_the_arm_scene_and_says_what_touched_what(tmp_path, capsys) -> None:
    """collres_demo --scene arm: node and sim over DDS, the arm's swing knocks the stack
    over; the report lists which link pieces touched which boxes."""
    from conftest import next_domain_id

    from collres_ros.demo import main
    code = main(['--scene', 'arm', '--duration', '0.8', '--out', str(tmp_path),
                 '--domain-id', str(next_domain_id())])
    out = capsys.readouterr().out
    print(out)
    assert code == 0   # both processes exit 0, every step answered and recorded
    assert 'collres_node exit 0, collres_sim exit 0' in out
    assert 'dropped 0' in out and 'what touched what' in out
    # the stack starts at rest and is meant to be pushed: the report says so
    assert 'box at rest at the start, box2: moved' in out
    assert '(driven bodies may push it)' in out and 'nothing should move it' not in out
    listed = out.split('what touched what')[1]
    assert any(f'{link}/' in listed for link in ('upper_arm', 'forearm', 'hand'))
    assert main(['--scene', 'arm', '--params', 'x.yaml', '--out', str(tmp_path)]) == 1
    assert main(['--scene', 'nope', '--out', str(tmp_path)]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ['error: --scene and --params: give one',
                   'error: config file scenes/nope.yaml not found']


@pytest.mark.slow
def test_links_posed_from_tf_static_and_tf(ros_domain, tmp_path) -> None:
    """/tf_static puts the robot's root link 1 m along x in the world and /tf its upper arm
    in the root link (turned 90 deg about z, 0.3 m up): the answer holds both at their
    chained poses, and a crate dropped on the plate there rests on it (where the params put
    the plate, at the origin, nothing holds it)."""
    import math

    import yaml
    from geometry_msgs.msg import TransformStamped
    from ros_harness import node_and_peer
    from test_node import body, step
    from tf2_msgs.msg import TFMessage

    from collres_ros.msg import BodyStateArray, ContactArray
    from collres_ros.ros import qos

    urdf = arm_urdf(f'file://{MESHES}')
    scene = tmp_path / 'scene.yaml'
    scene.write_text(yaml.safe_dump({'/**': {'ros__parameters': {
        'bodies': ['crate'], 'robot_description': urdf,
        'body': {'crate': {'shape': 'box', 'size': [0.03, 0.03, 0.03], 'mass': 0.5}}}}}))
    half = math.sqrt(0.5)

    def transform(parent, child, xyz, q=(0.0, 0.0, 0.0, 1.0)) -> TFMessage:
        t = TransformStamped()
        t.header.frame_id, t.child_frame_id = parent, child
        t.header.stamp.sec = T_TF // 10**9
        t.transform.translation.x, t.transform.translation.y, t.transform.translation.z = xyz
        r = t.transform.rotation
        r.x, r.y, r.z, r.w = q
        return TFMessage(transforms=[t])

    with node_and_peer(ros_domain, scene, tmp_path / 'node.log', listen=(
            ('body_states/corrected', BodyStateArray), ('contacts', ContactArray)),
            answering=('/body_states/corrected', '/contacts')) as (peer, node):
        static = peer.node.create_publisher(TFMessage, '/tf_static', qos.tf_static_qos())
        moving = peer.node.create_publisher(TFMessage, '/tf', qos.state_qos(100))
        static.publish(transform('world', 'base_link', (1.0, 0.0, 0.0)))
        held = body('crate', 0.5, x=1.13)   # above it all until both links are posed
        stamp, posed = T_TF, {}

        def chained() -> bool:   # /tf travels beside body_states: no order between them,
            # and before /tf the upper arm is at its URDF pose (0, 0, 0.3), turned 0 deg
            return (set(posed) == {'base_link', 'upper_arm'}
                    and posed['base_link'].position.x == pytest.approx(1.0)
                    and posed['upper_arm'].position.x == pytest.approx(1.0)
                    and posed['upper_arm'].orientation.z == pytest.approx(half))

        deadline = time.monotonic() + 10.0
        while not chained() and time.monotonic() < deadline:
            moving.publish(transform('base_link', 'upper_arm', (0.0, 0.0, 0.3),
                                     (0.0, 0.0, half, half)))
            out = step(peer, stamp, [held])
            posed = {b.name: b.pose for b in out.bodies if b.name != 'crate'}
            stamp += 10**7
        assert set(posed) == {'base_link', 'upper_arm'}
        base, arm = posed['base_link'], posed['upper_arm']
        assert (base.position.x, base.position.y, base.position.z) == pytest.approx((1, 0, 0))
        assert (arm.position.x, arm.position.y, arm.position.z) == pytest.approx((1, 0, 0.3))
        assert (arm.orientation.z, arm.orientation.w) == pytest.approx((half, half))
        z, vz = 0.01 + 0.015, 0.0
        for k in range(20):
            vz -= G * DT_S
            crate = body('crate', z + vz * DT_S, vz, x=1.13)
            out = step(peer, stamp + k * 10**7, [crate])
            crate = [b for b in out.bodies if b.name == 'crate'][0]
            z, vz = crate.pose.position.z, crate.twist.linear.z
        assert z == pytest.approx(0.025, abs=1e-3)           # held by the plate at x = 1
        assert 'input refused' not in node.output()


@pytest.mark.slow
def test_sim_and_replay_take_the_urdf_from_the_topic(ros_domain, tmp_path, capsys) -> None:
    """robot_description_topic: collres_sim and collres_replay wait for the URDF on
    robot_description as the node does, up to --wait, then stop with one line; with it
    published (latched, as robot_state_publisher), the sim records the links as bodies and
    the replay of that bag with the same params resolves."""
    import yaml
    from ros_harness import Peer
    from std_msgs.msg import String

    from collres_ros import replay, sim
    from collres_ros.ros import params, qos
    from collres_ros.ros.bag import PARAMS_KEY, BagReader

    urdf = arm_urdf(f'file://{MESHES}')
    scene = tmp_path / 'scene.yaml'
    scene.write_text(yaml.safe_dump({
        '/**': {'ros__parameters': {
            'bodies': ['crate'], 'robot_description_topic': True,
            'body': {'crate': {'shape': 'box', 'size': [0.03, 0.03, 0.03], 'mass': 0.5,
                               'position': [0.13, 0.0, 0.03]}}}},
        'collres_sim': {'ros__parameters': {'duration': 0.05, 'rate_hz': 100.0}}}))
    run = ['--params', str(scene), '--offline', '--record']
    missing = 'robot_description_topic: no URDF on /robot_description within 0.5 s'
    assert sim.main([*run, str(tmp_path / 'none'), '--wait', '0.5']) == 1
    assert f'error: {missing}' in capsys.readouterr().err
    describer = Peer(ros_domain, 'collres_test_describer')
    try:
        publisher = describer.node.create_publisher(String, 'robot_description',
                                                    qos.latched_qos())
        publisher.publish(String(data=urdf))
        assert sim.main([*run, str(tmp_path / 'bag'), '--wait', '10']) == 0
        with BagReader(tmp_path / 'bag') as reader:
            recorded = params.load_recorded_scene(reader.custom_data[PARAMS_KEY], 'bag')
        assert {'crate', 'base_link', 'upper_arm'} <= set(recorded.names)
        assert replay.main([str(tmp_path / 'bag'), str(tmp_path / 'out'), '--params',
                            str(scene), '--wait', '10', '--quiet']) == 0
    finally:
        describer.close()
    assert replay.main([str(tmp_path / 'bag'), str(tmp_path / 'out2'), '--params', str(scene),
                        '--wait', '0.5', '--quiet']) == 1
    assert f'error: {missing}' in capsys.readouterr().err
