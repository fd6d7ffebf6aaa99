"""Net contact wrench (``contact_wrench: true``): a box at rest on the floor feels m g.

At rest the contacts must carry the box's weight: the net contact force is
m g upwards (within 1 %), the floor feels the opposite (action = reaction),
and the torque about the box's centre of mass is zero (the box does not
start turning). Checked offline through the core (as ``collres_sim
--offline``) and once over DDS with the real node process.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

pytest.importorskip('rclpy')

from geometry_msgs.msg import WrenchStamped  # noqa: E402
from rclpy.serialization import deserialize_message  # noqa: E402

from collres_ros.msg import ContactArray  # noqa: E402

G = 9.81
MASS = 2.0
SCENE = '''/**:
  ros__parameters:
    world_frame: world
    bodies: [floor, box]
    body:
      floor: {shape: box, size: [10.0, 10.0, 0.2], static: true, position: [0.0, 0.0, -0.1]}
      box: {shape: box, size: [0.2, 0.3, 0.4], mass: %(mass)s, restitution: 0.0,
            position: [0.5, -0.2, 0.2]}
collres_node:
  ros__parameters:
    contact_wrench: true
    diagnostics_period: 0.1
collres_sim:
  ros__parameters:
    rate_hz: 240.0
    duration: 1.0
''' % {'mass': MASS}


def wrench_values(msg: WrenchStamped) -> np.ndarray:
    f, t = msg.wrench.force, msg.wrench.torque
    return np.array([f.x, f.y, f.z, t.x, t.y, t.z])


def test_a_box_at_rest_feels_its_weight_and_no_torque(tmp_path: Path) -> None:
    from collres_ros.ros.offline import run_core
    from collres_ros.ros.simulation import load_sim_scene
    path = tmp_path / 'rest.yaml'
    path.write_text(SCENE)
    sim = load_sim_scene(path)
    wrenches: dict[str, list[np.ndarray]] = {'box': [], 'floor': []}
    contacts: list[int] = []

    def sink(stamp: int, outputs: list) -> None:
        for topic, kind, data in outputs:
            if topic.endswith('/contact_wrench'):
                assert kind == 'geometry_msgs/msg/WrenchStamped'
                msg = deserialize_message(data, WrenchStamped)
                assert msg.header.frame_id == 'world'
                wrenches[topic.split('/')[1]].append(wrench_values(msg))
            if topic == 'contacts':
                contacts.append(len(deserialize_message(data, ContactArray).contacts))

    steps = run_core(sim, sink, markers=False)
    assert len(wrenches['box']) == steps == len(wrenches['floor'])
    box, floor = np.array(wrenches['box'][-60:]), np.array(wrenches['floor'][-60:])
    assert min(contacts[-60:]) > 0, 'the box is not in contact with the floor'
    weight = MASS * G
    print(f'box force {box[:, 0:3].mean(0)} N (m g = {weight} N), '
          f'torque max {np.abs(box[:, 3:6]).max():.3g} N m, floor {floor[:, 0:3].mean(0)} N')
    assert box[:, 2] == pytest.approx(weight, rel=0.01)
    assert np.abs(box[:, 0:2]).max() < 0.01 * weight
    # torque about the centre of mass: zero, against the weight times the half-size
    assert np.abs(box[:, 3:6]).max() < 1e-3 * weight * 0.2
    assert floor[:, 0:3] == pytest.approx(-box[:, 0:3], abs=1e-9 * weight)


def test_wrenches_are_off_by_default(tmp_path: Path) -> None:
    from collres_ros.ros.offline import run_core
    from collres_ros.ros.simulation import load_sim_scene
    path = tmp_path / 'rest.yaml'
    path.write_text(SCENE.replace('contact_wrench: true', 'contact_wrench: false')
                    .replace('duration: 1.0', 'duration: 0.05'))
    topics: set[str] = set()
    run_core(load_sim_scene(path), lambda stamp, out: topics.update(t for t, _, _ in out),
             markers=False)
    assert 'contacts' in topics
    assert not [t for t in topics if t.endswith('contact_wrench')]


@pytest.mark.slow
def test_the_node_publishes_the_wrench_over_dds(ros_domain, tmp_path: Path) -> None:
    from ros_harness import node_and_peer
    from collres_ros.msg import BodyStateArray
    from collres_ros.ros.messages import stamp_ns
    from test_node import T0, body, states
    path = tmp_path / 'rest.yaml'
    path.write_text(SCENE)
    with node_and_peer(ros_domain, path, tmp_path / 'node.log', listen=(
            ('body_states/corrected', BodyStateArray),
            ('bodies/box/contact_wrench', WrenchStamped))) as (peer, node):

        def publishing(topic):
            return any(s.get_publisher_count() for s in peer.node.subscriptions
                       if s.topic_name == topic)
        dt_ns = 10**9 // 100
        z, vz = 0.2, 0.0
        for k in range(20):   # the peer integrates gravity, the node holds the box up
            stamp = T0 + k * dt_ns
            vz -= G * dt_ns * 1e-9
            z += vz * dt_ns * 1e-9
            peer.publish('body_states', states(stamp, [body('box', z, vz, x=0.5)]))

            def answered():
                return [m for m in peer.messages('body_states/corrected')
                        if stamp_ns(m.header.stamp) == stamp]
            assert peer.wait(answered, 10.0), f'no answer at step {k}: {node.output()}'
            out = answered()[-1].bodies[0]
            z, vz = out.pose.position.z, out.twist.linear.z
            if k == 0:   # the node creates the wrench publishers with their first message
                assert peer.wait(lambda: publishing('/bodies/box/contact_wrench'), 30.0)
        last = T0 + 19 * dt_ns
        assert peer.wait(lambda: any(stamp_ns(m.header.stamp) == last for m in peer.messages(
            'bodies/box/contact_wrench')), 10.0)
        msg = [m for m in peer.messages('bodies/box/contact_wrench')
               if stamp_ns(m.header.stamp) == last][-1]
        got = wrench_values(msg)
        print('wrench over DDS', got, 'm g', MASS * G)
        assert got[2] == pytest.approx(MASS * G, rel=0.01)
        assert np.abs(got[3:6]).max() < 1e-3 * MASS * G * 0.2
