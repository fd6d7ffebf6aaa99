"""robot_description over DDS: collres_node started with the test arm's URDF poses its links
from body_states by link name; a crate resting on the arm's base plate gets contacts that
name the link and its piece, carrying the crate's weight."""

from __future__ import annotations

from pathlib import Path

import pytest

pytest.importorskip('rclpy')

DATA = Path(__file__).resolve().parent / 'data' / 'robots'
G, DT_S = 9.81, 0.01


@pytest.mark.slow
@pytest.mark.parametrize('source', ['parameter', 'topic'])
def test_links_posed_by_name_and_contacts_name_their_pieces(ros_domain, tmp_path,
                                                            source) -> None:
    """The URDF as the robot_description parameter, or (robot_description_topic) from the
    robot_description topic, published transient local before the node starts."""
    import yaml
    from ros_harness import Peer, node_and_peer
    from std_msgs.msg import String
    from test_node import T0, body, step

    from collres_ros.msg import BodyStateArray, ContactArray
    from collres_ros.ros import qos
    from collres_ros.ros.robot import link_poses

    urdf = (DATA / 'arm.urdf').read_text().replace(
        'package://collres_test_robot', f'file://{DATA}')
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
                out = step(peer, T0 + k * 10**7, links + [body('crate', z + vz * DT_S, vz,
                                                               x=0.13)])
                crate = [b for b in out.bodies if b.name == 'crate'][0]
                z, vz = crate.pose.position.z, crate.twist.linear.z
            assert z == pytest.approx(0.025, abs=1e-3)           # held by the plate
            last = peer.messages('contacts')[-1].contacts
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
    main(['--scene', 'arm', '--duration', '0.8', '--out', str(tmp_path),
          '--domain-id', str(next_domain_id())])   # exit 0 needs every step recorded too
    out = capsys.readouterr().out
    print(out)
    assert 'collres_node exit 0, collres_sim exit 0' in out
    assert 'dropped 0' in out and 'what touched what' in out
    listed = out.split('what touched what')[1]
    assert any(f'{link}/' in listed for link in ('upper_arm', 'forearm', 'hand'))
    assert main(['--scene', 'arm', '--params', 'x.yaml', '--out', str(tmp_path)]) == 1
    assert main(['--scene', 'nope', '--out', str(tmp_path)]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ['error: --scene and --params: give one',
                   'error: config file scenes/nope.yaml not found']
