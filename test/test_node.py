"""collres_node end to end over real DDS: a separate process, a private ROS_DOMAIN_ID."""

from __future__ import annotations

import math
import signal

import pytest
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped, TwistStamped
from ros_harness import Peer, node_and_peer, node_publishers, set_parameter, write_scene

from collres_ros.ros import processes
from collres_ros.ros.messages import stamp_ns, to_stamp
from collres_ros.msg import BodyState, BodyStateArray, ContactArray

pytestmark = pytest.mark.slow
T0 = 1_000 * 10**9
DT = 10**9 // 100    # 10 ms steps


def body(name, z, vz=0.0, x=0.0, q=(0.0, 0.0, 0.0, 1.0)):
    b = BodyState(name=name)
    b.pose.position.x, b.pose.position.z = x, z
    b.pose.orientation.x, b.pose.orientation.y, b.pose.orientation.z, b.pose.orientation.w = q
    b.twist.linear.z = vz
    return b


def states(stamp, bodies, frame='world'):
    msg = BodyStateArray(bodies=bodies)
    msg.header.frame_id = frame
    msg.header.stamp = to_stamp(stamp)
    return msg


@pytest.fixture
def running(ros_domain, tmp_path):
    """(peer, node process) with the node up and connected both ways."""
    scene = write_scene(tmp_path / 'scene.yaml')
    # every batched output's publisher matched; per-body outputs are advertised with the
    # first per-body step
    with node_and_peer(ros_domain, scene, tmp_path / 'node.log', listen=(
            ('body_states/corrected', BodyStateArray), ('contacts', ContactArray),
            ('/diagnostics', DiagnosticArray), ('bodies/ball/pose/corrected', PoseStamped),
            ('bodies/ball/twist/corrected', TwistStamped)),
            answering=('/body_states/corrected', '/contacts', '/diagnostics')) as up:
        yield up


def step(peer, stamp, bodies, frame='world', timeout=10.0):
    """Publish one step and wait for its corrected answer (returned)."""
    peer.publish('body_states', states(stamp, bodies, frame))

    def answered():
        return any(stamp_ns(m.header.stamp) == stamp for m in peer.messages(
            'body_states/corrected'))
    assert peer.wait(answered, timeout), f'no answer for stamp {stamp}'
    return [m for m in peer.messages('body_states/corrected')
            if stamp_ns(m.header.stamp) == stamp][-1]


def diagnostics_values(peer):
    msgs = peer.messages('/diagnostics')
    if not msgs:
        return {}
    return {kv.key: kv.value for kv in msgs[-1].status[0].values}


def test_every_input_step_gets_exactly_one_output(running):
    peer, node = running
    z, vz, n = 0.2, -1.0, 60
    for k in range(n):
        vz -= 9.81 * DT * 1e-9
        z += vz * DT * 1e-9
        out = step(peer, T0 + k * DT, [body('ball', z, vz), body('box', 0.1, x=1.0)])
        ball = next(b for b in out.bodies if b.name == 'ball')
        z, vz = ball.pose.position.z, ball.twist.linear.z
        assert z > 0.1 - 0.01, f'step {k}: ball centre {z} penetrates the floor'
    stamps = [stamp_ns(m.header.stamp) for m in peer.messages('body_states/corrected')
              if stamp_ns(m.header.stamp) >= T0]
    assert peer.wait(lambda: diagnostics_values(peer).get('steps') == str(n), 5.0)
    assert stamps == [T0 + k * DT for k in range(n)]
    contacts = [c for m in peer.messages('contacts') for c in m.contacts
                if {c.body_a, c.body_b} == {'floor', 'ball'}]
    print('ball-floor contacts', len(contacts), 'final z', z, 'vz', vz)
    assert contacts, 'the ball never touched the floor'
    assert vz > -0.5, 'the floor did not stop the fall'


def test_bad_inputs_are_counted_and_the_others_served(running):
    peer, node = running
    good_box = body('box', 0.1, x=1.0)
    t = T0
    step(peer, t, [body('ball', 0.5), good_box])
    bad_steps = [
        ('non_finite', [body('ball', math.nan), good_box], 'world'),
        ('zero_quaternion', [body('ball', 0.5, q=(0.0, 0.0, 0.0, 0.0)), good_box], 'world'),
        ('non_unit_quaternion', [body('ball', 0.5, q=(0.0, 0.0, 0.0, 2.0)), good_box],
         'world'),
        ('unknown_body', [body('ghost', 0.5), body('ball', 0.5), good_box], 'world'),
        ('duplicate_body', [body('ball', 0.5), body('ball', 0.6), good_box], 'world'),
        ('wrong_frame', [body('ball', 0.5), good_box], 'map'),
    ]
    for reason, bodies, frame in bad_steps:
        t += DT
        out = step(peer, t, bodies, frame)
        served = [b.name for b in out.bodies]
        print(reason, 'served', served)
        if frame == 'world':
            assert 'box' in served, reason
        assert all(math.isfinite(b.pose.position.z) for b in out.bodies)
    out = step(peer, t - 5 * DT + DT // 2, [body('ball', 0.5), good_box])   # backwards
    assert list(out.bodies) == []   # refused: a stamp behind changes nothing
    out = step(peer, t + 100 * 10**9, [body('ball', 0.5), good_box])   # huge dt
    assert sorted(b.name for b in out.bodies) == ['ball', 'box']
    expected = {r for r, _, _ in bad_steps} | {'time_backwards', 'large_gap'}
    assert peer.wait(lambda: expected <= {k[len('count.'):] for k in diagnostics_values(peer)
                                          if k.startswith('count.')}, 5.0), \
        diagnostics_values(peer)
    values = diagnostics_values(peer)
    print({k: v for k, v in values.items() if k.startswith('count.')})
    assert values['count.duplicate_body'] == '2' and values['count.wrong_frame'] == '2'
    assert node.poll() is None
    assert 'Traceback' not in node.output()


def per_body_up(peer, node, bodies=('ball', 'box')):
    """Advertise ``bodies``' pose and twist and wait until the node subscribed to them (it
    does once they have a publisher: a message published before that match is lost) and
    the peer's per-body answer readers matched the node's answers' publishers."""
    topics = [f'bodies/{n}/{k}' for n in bodies for k in ('pose', 'twist')]
    for topic in topics:
        peer.advertise(topic, PoseStamped if topic.endswith('pose') else TwistStamped)
    answers = [s for s in peer.node.subscriptions if s.topic_name.startswith('/bodies/')
               and s.topic_name.split('/')[2] in bodies]
    assert peer.wait(lambda: all(peer.connected(t) for t in topics)
                     and all(s.get_publisher_count() > 0 for s in answers), 30.0), \
        node.output()
    # the node says when it subscribed
    assert peer.wait(lambda: 'per-body inputs: ' in node.output(), 10.0)


def per_body_step(peer, stamp, bodies=(('ball', 0.5), ('box', 0.1))):
    """``bodies``' ((name, z)) pose and twist at ``stamp``, at rest."""
    for name, z in bodies:
        pose, twist = PoseStamped(), TwistStamped()
        pose.header.stamp = twist.header.stamp = to_stamp(stamp)
        pose.header.frame_id = twist.header.frame_id = 'world'
        pose.pose.position.x = 1.0 if name == 'box' else 0.0
        pose.pose.position.z, pose.pose.orientation.w = z, 1.0
        peer.publish(f'bodies/{name}/pose', pose)
        peer.publish(f'bodies/{name}/twist', twist)


def test_per_body_inputs_exist_only_for_bodies_published_to(running):
    """With no per-body publisher the node has no per-body subscription (nothing to wait
    on, nothing for the DDS to match); a peer that then advertises and publishes the ball's
    and the box's pose and twist gets its per-body answers, the floor's topics stay
    unsubscribed, and the batched path answers before, between and after."""
    peer, node = running
    inputs = [f'/bodies/{n}/{k}' for n in ('floor', 'ball', 'box') for k in ('pose', 'twist')]
    bodies = [body('ball', 0.5), body('box', 0.1, x=1.0)]
    for k in range(5):   # batched steps: the node is serving, its start is over
        step(peer, T0 + k * DT, bodies)
    assert peer.wait(lambda: diagnostics_values(peer).get('steps') == '5', 10.0)
    assert [peer.node.count_subscribers(t) for t in inputs] == [0] * 6
    assert diagnostics_values(peer)['per_body_inputs_subscribed'] == '0'
    per_body_up(peer, node)
    for k in range(5, 10):   # per-body steps, each followed by a batched one
        stamp = T0 + 2 * k * DT
        per_body_step(peer, stamp)
        assert peer.wait(lambda: any(stamp_ns(m.header.stamp) == stamp for m in
                                     peer.messages('bodies/ball/pose/corrected')), 10.0), \
            f'no per-body answer for {stamp}'
        out = step(peer, stamp + DT, bodies)
        assert {b.name for b in out.bodies} == {'ball', 'box'}
    assert [peer.node.count_subscribers(t) for t in inputs[:2]] == [0, 0]   # the floor's
    assert peer.wait(lambda: diagnostics_values(peer).get('per_body_inputs_subscribed') == '4',
                     10.0)
    step(peer, T0 + 30 * DT, bodies)
    assert 'Traceback' not in node.output()


def test_per_body_topics_body_frame_twist_and_stale(running):
    peer, node = running
    per_body_up(peer, node)
    half = math.sqrt(0.5)
    for k in range(3):
        stamp = T0 + k * DT
        for name, x, frame in (('ball', 0.0, 'ball'), ('box', 1.0, 'world')):
            pose, twist = PoseStamped(), TwistStamped()
            pose.header.stamp = twist.header.stamp = to_stamp(stamp)
            pose.header.frame_id, twist.header.frame_id = 'world', frame
            pose.pose.position.x, pose.pose.position.z = x, 0.5 if name == 'ball' else 0.1
            pose.pose.orientation.z, pose.pose.orientation.w = half, half
            twist.twist.linear.x = 1.0 if name == 'ball' else 0.0
            if k == 2 and name == 'box':
                continue   # the box goes silent
            peer.publish(f'bodies/{name}/pose', pose)
            peer.publish(f'bodies/{name}/twist', twist)
        if k < 2:
            assert peer.wait(lambda: any(stamp_ns(m.header.stamp) == stamp for m in
                                         peer.messages('bodies/ball/twist/corrected')), 10.0)
    out = [m for m in peer.messages('bodies/ball/twist/corrected')][-1]
    print('body-frame twist out', out.header.frame_id, out.twist.linear)
    assert out.header.frame_id == 'ball'
    assert out.twist.linear.x == pytest.approx(1.0, abs=1e-9)
    world = [m for m in peer.messages('body_states/corrected')][-1].bodies
    ball = next(b for b in world if b.name == 'ball')
    assert ball.twist.linear.y == pytest.approx(1.0, abs=1e-9)   # world frame: rotated
    # the box is silent: after the stale timeout (0.2 s of stamps) the ball is served alone
    for k in range(3, 40):
        stamp = T0 + k * DT
        pose, twist = PoseStamped(), TwistStamped()
        pose.header.stamp = twist.header.stamp = to_stamp(stamp)
        pose.header.frame_id = twist.header.frame_id = 'world'
        pose.pose.position.z, pose.pose.orientation.w = 0.5, 1.0
        peer.publish('bodies/ball/pose', pose)
        peer.publish('bodies/ball/twist', twist)
    last = T0 + 39 * DT
    assert peer.wait(lambda: any(stamp_ns(m.header.stamp) == last for m in
                                 peer.messages('bodies/ball/pose/corrected')), 10.0)
    assert peer.wait(lambda: diagnostics_values(peer).get('stale_bodies') == 'box', 5.0)


def test_bad_params_file_exits_1_with_one_line(ros_domain, tmp_path):
    scene = write_scene(tmp_path / 'bad.yaml', ball=', restitution: 1.5')
    scene.write_text(scene.read_text().replace('restitution: 0.8, ', ''))
    node = processes.start('collres_node', ['--ros-args', '--params-file', str(scene)],
                           env=processes.ros_env(ros_domain), log=tmp_path / 'node.log')
    assert processes.wait_for(lambda: node.poll() is not None, 30.0)
    out = node.output().strip()
    print(out)
    assert node.returncode == 1
    assert out == 'error: body.ball.restitution: allowed range [0.0, 1.0] (got 1.5)'


def test_missing_params_file_exits_1(ros_domain, tmp_path):
    node = processes.start('collres_node', ['--ros-args', '--params-file',
                                            str(tmp_path / 'nope.yaml')],
                           env=processes.ros_env(ros_domain))
    assert processes.wait_for(lambda: node.poll() is not None, 30.0)
    assert node.returncode == 1 and node.output().startswith('error: params file not found')


def _bounce(peer, start):
    """Drop the ball onto the floor at 2 m/s over one step; its corrected vz."""
    dt = 1 / 60
    step(peer, start, [body('ball', 0.13, -2.0)])
    out = step(peer, start + int(dt * 1e9), [body('ball', 0.13 - 2.0 * dt, -2.0)])
    return next(b for b in out.bodies if b.name == 'ball').twist.linear.z


def test_runtime_parameters_refused_with_reason_and_applied(running):
    peer, node = running
    before = _bounce(peer, T0)
    refused = {
        ('body.ball.restitution', 1.5): 'body.ball.restitution',
        ('body.ball.kinetic_friction', 0.9): 'must be <= static_friction',
        ('solver.restitution_rule', 'bogus'): 'allowed values',
        ('body.ball.shape', 'box'): 'read-only',
        ('solver.velocity_iterations', 0): 'solver.velocity_iterations',
    }
    for (name, value), text in refused.items():
        result = set_parameter(peer, name, value)
        print(name, value, '->', result.reason)
        assert not result.successful and text in result.reason
        assert '\n' not in result.reason
    assert set_parameter(peer, 'body.ball.restitution', 0.2).successful
    assert set_parameter(peer, 'body.floor.restitution', 0.2).successful
    after = _bounce(peer, T0 + 100 * 10**9)
    print('rebound speed: e 0.8 ->', before, ' e 0.2 ->', after)
    assert before == pytest.approx(1.6, rel=0.05)
    assert after == pytest.approx(0.4, rel=0.1)


@pytest.mark.parametrize('sig', [signal.SIGINT, signal.SIGTERM])
def test_signal_exits_0(running, sig):
    peer, node = running
    step(peer, T0, [body('ball', 0.5)])
    node.send_signal(sig)
    assert processes.wait_for(lambda: node.poll() is not None, 15.0)
    print(node.output())
    assert node.returncode == 0 and 'Traceback' not in node.output()


def test_oversized_and_badly_stamped_inputs_are_refused_and_counted(running):
    """A 12 MB message of 100,000 bodies is refused on its count
    before it is read (the next step is served), negative and unnormalised stamps with a
    reason; each is counted in /diagnostics, and nothing is stamped 0."""
    import struct

    import numpy as np

    from collres_ros.ros.codec import StatesCodec
    peer, node = running
    huge = StatesCodec().encode(T0, 'world', [f'b{k}' for k in range(100_000)],
                                np.zeros((100_000, 13)))
    assert len(huge) > 11_000_000
    good = StatesCodec().encode(T0 + DT, 'world', ['ball'],
                                np.array([[0.0, 0.0, 0.5, 0.0, 0.0, 0.0, 1.0] + [0.0] * 6]))
    negative = good[:4] + struct.pack('<iI', -1, 0) + good[12:]
    unnormalised = good[:4] + struct.pack('<iI', 1000, 1_000_000_000) + good[12:]
    publisher = peer.publishers['body_states']
    for data in (huge, negative, unnormalised):
        publisher.publish(data)
    step(peer, T0 + 2 * DT, [body('ball', 0.5)])
    expected = {'count.too_many_bodies': '1', 'count.negative_stamp': '1',
                'count.invalid_nanosec': '1'}
    assert peer.wait(lambda: expected.items() <= diagnostics_values(peer).items(), 10.0), \
        diagnostics_values(peer)
    stamps = [stamp_ns(m.header.stamp) for m in peer.messages('body_states/corrected')]
    assert 0 not in stamps and T0 + 2 * DT in stamps
    assert node.poll() is None and 'Traceback' not in node.output()
    assert 'too_many_bodies' in node.output()


def test_a_message_with_unknown_bodies_serves_the_known_ones(running):
    """An estimator publishes every object it tracks, more than the scene's three bodies:
    the known ones are resolved and answered, each unknown one refused and counted."""
    peer, node = running
    ghosts = [body(f'tracked{k}', 0.5 + k, x=3.0 + k) for k in range(5)]
    out = step(peer, T0, ghosts[:2] + [body('ball', 0.5), body('box', 0.1, x=1.0)] + ghosts[2:])
    assert sorted(b.name for b in out.bodies) == ['ball', 'box']
    assert peer.wait(lambda: diagnostics_values(peer).get('count.unknown_body') == '5', 10.0), \
        diagnostics_values(peer)
    values = diagnostics_values(peer)
    print({k: v for k, v in values.items() if k.startswith(('count.', 'messages_refused'))})
    assert 'count.too_many_bodies' not in values
    assert 'unknown_body' in node.output()


def test_a_step_over_the_budget_warns_once_and_is_counted(ros_domain, tmp_path):
    scene = write_scene(tmp_path / 'scene.yaml',
                        '    solver: {max_pairs: 1, max_contacts: 1}\n')
    with node_and_peer(ros_domain, scene, tmp_path / 'node.log', listen=(
            ('body_states/corrected', BodyStateArray),)) as (peer, node):
        for k in range(3):   # ball and box both resting on the floor: two pairs, budget one
            out = step(peer, T0 + k * DT, [body('ball', 0.05), body('box', 0.1, x=1.0)])
            assert sorted(b.name for b in out.bodies) == ['ball', 'box']
        assert peer.wait(lambda: diagnostics_values(peer).get('count.contact_budget') == '3',
                         5.0), diagnostics_values(peer)
        assert peer.messages('/diagnostics')[-1].status[0].level == b'\x01'
        assert node.output().count('over the contact budget') == 1, node.output()


def test_two_publishers_on_body_states_report_no_phantom_loss(running, ros_domain):
    peer, node = running
    other = Peer(ros_domain, 'collres_test_second_publisher')
    try:
        other.advertise('body_states', BodyStateArray)
        # the node's side of the match too: a step sent before it could be lost
        assert peer.wait(lambda: other.connected('body_states')
                         and node_publishers(peer) == 2, 30.0), diagnostics_values(peer)
        t = T0
        for k in range(60):   # one publisher at twice the other's rate, every step answered
            t += DT
            source = other if k % 3 == 2 else peer
            pair = [body('ball', 0.5), body('box', 0.1, x=1.0)]
            source.publish('body_states', states(t, pair))
            assert peer.wait(lambda: any(stamp_ns(m.header.stamp) == t for m in
                                         peer.messages('body_states/corrected')), 10.0)
        assert peer.wait(lambda: diagnostics_values(peer).get('inputs_received') == '60', 5.0)
        values = diagnostics_values(peer)
        print({k: v for k, v in values.items() if 'input' in k or 'loss' in k})
        assert values['inputs_lost'] == '0'
        assert values['loss_counting'].startswith('not inferred while several publishers')
        assert int(values['inputs_uncounted']) > 0
    finally:
        other.close()
