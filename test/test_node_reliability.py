"""collres_node over real DDS: clock restarts, unpaired inputs, a /diagnostics level that
recovers, the expected-rate check, the status name, and inputs lost in a burst counted
exactly."""

from __future__ import annotations

import pytest
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped, TwistStamped
from ros_harness import Peer, node_publishers, write_scene

from collres_ros.msg import BodyState, BodyStateArray
from collres_ros.ros import processes
from collres_ros.ros.stamps import stamp_ns, to_stamp

pytestmark = pytest.mark.slow
S = 10**9
DT = 10**7        # 10 ms
T0 = 1000 * S


def start(ros_domain, tmp_path, extra_node='', args=()):
    scene = write_scene(tmp_path / 'scene.yaml', extra_node=extra_node)
    node = processes.start('collres_node', ['--ros-args', '--params-file', str(scene), *args],
                           env=processes.ros_env(ros_domain), log=tmp_path / 'node.log')
    peer = Peer(ros_domain)
    peer.listen('body_states/corrected', BodyStateArray)
    peer.listen('bodies/ball/pose/corrected', PoseStamped)
    peer.listen('/diagnostics', DiagnosticArray)   # last: see wait_up
    return node, peer


@pytest.fixture
def stopped():
    started = []
    yield started.append
    for node, peer in started:
        peer.close()
        if node.poll() is None:
            processes.stop(node)


def status(peer):
    msgs = peer.messages('/diagnostics')
    return msgs[-1].status[0] if msgs else None


def level(peer):
    s = status(peer)
    return None if s is None else int.from_bytes(s.level, 'little')


def values(peer):
    s = status(peer)
    return {} if s is None else {kv.key: kv.value for kv in s.values}


def state(name, z=0.5, x=0.0):
    b = BodyState(name=name)
    b.pose.position.x, b.pose.position.z, b.pose.orientation.w = x, z, 1.0
    return b


def batch(stamp, bodies):
    msg = BodyStateArray(bodies=bodies)
    msg.header.frame_id = 'world'
    msg.header.stamp = to_stamp(stamp)
    return msg


def part(stamp, kind, x=0.0, z=0.5):
    msg = PoseStamped() if kind == 'pose' else TwistStamped()
    msg.header.stamp = to_stamp(stamp)
    msg.header.frame_id = 'world'
    if kind == 'pose':
        msg.pose.position.x, msg.pose.position.z, msg.pose.orientation.w = x, z, 1.0
    return msg


def wait_up(peer, node, topics):
    """The node subscribes to ``topics`` and a /diagnostics report arrived: on the peer's
    last reader, so the node matched its other readers too, and its ``body_states``
    subscription the peer's publisher (``ros_harness.node_and_peer``)."""
    for topic, kind in topics:
        peer.advertise(topic, kind)
    batched = any(t == 'body_states' for t, _ in topics)
    assert peer.wait(lambda: all(peer.connected(t) for t, _ in topics)
                     and status(peer) is not None
                     and (not batched or node_publishers(peer) >= 1), 30.0), node.output()


def answered(peer, topic, stamp):
    return any(stamp_ns(m.header.stamp) == stamp for m in peer.messages(topic))


def test_a_source_restart_resets_the_per_body_sync_once(ros_domain, tmp_path, stopped):
    node, peer = start(ros_domain, tmp_path)
    stopped((node, peer))
    topics = [(f'bodies/{n}/{k}', PoseStamped if k == 'pose' else TwistStamped)
              for n in ('ball', 'box') for k in ('pose', 'twist')]
    wait_up(peer, node, topics)

    def publish(stamp, silent=()):
        for n in ('ball', 'box'):
            if n not in silent:
                for k in ('pose', 'twist'):
                    peer.publish(f'bodies/{n}/{k}', part(stamp, k, x=1.0 if n == 'box' else 0.0,
                                                         z=0.1 if n == 'box' else 0.5))
        assert peer.wait(lambda: answered(peer, 'bodies/ball/pose/corrected', stamp), 15.0), \
            f'no answer for {stamp}: {node.output()[-2000:]}'
    for k in range(5):
        publish(T0 + k * DT)
    for k in range(1, 6):               # a new run from t = 0.01 s
        publish(k * DT)
    for k in range(6, 40):              # the box goes silent: after 0.2 s the ball goes alone
        for kind in ('pose', 'twist'):
            peer.publish(f'bodies/ball/{kind}', part(k * DT, kind))
    assert peer.wait(lambda: answered(peer, 'bodies/ball/pose/corrected', 39 * DT), 15.0), \
        node.output()[-2000:]
    # (messages the node's queue lost can open a forward gap too: counted, not a reset)
    assert peer.wait(lambda: int(values(peer).get('count.time_jump', 0)) >= 1
                     and values(peer).get('stale_bodies') == 'box', 10.0), \
        (status(peer).message, {kv.key: kv.value for kv in status(peer).values},
         node.output()[-3000:])
    log = node.output()
    print(log[-1500:])
    assert log.count('jumped backwards') == 1 and 'Traceback' not in log


def test_inputs_that_never_pair_warn_with_the_reason(ros_domain, tmp_path, stopped):
    node, peer = start(ros_domain, tmp_path)
    stopped((node, peer))
    topics = [('bodies/ball/pose', PoseStamped), ('bodies/box/pose', PoseStamped)]
    wait_up(peer, node, topics)
    k = 0

    def warned():
        nonlocal k
        k += 1
        for topic, _ in topics:
            peer.publish(topic, part(T0 + k * DT, 'pose'))
        s = status(peer)
        return s is not None and 'poses without twists for: ball, box' in s.message
    assert peer.wait(warned, 20.0), (status(peer), node.output()[-1000:])
    print(status(peer).message)
    assert level(peer) == 1
    assert 'poses without twists for: ball, box' in node.output()


def test_the_level_returns_to_ok_after_a_refused_input(ros_domain, tmp_path, stopped):
    node, peer = start(ros_domain, tmp_path)
    stopped((node, peer))
    wait_up(peer, node, [('body_states', BodyStateArray)])
    box = state('box', z=0.1, x=1.0)
    k = 0

    def publish(ball):
        nonlocal k
        k += 1
        peer.publish('body_states', batch(T0 + k * DT, [ball, box]))
    publish(state('ball'))
    publish(state('ball', z=float('nan')))
    assert peer.wait(lambda: (publish(state('ball')), level(peer) == 1)[1], 20.0)
    print('after the NaN:', status(peer).message)
    assert peer.wait(lambda: (publish(state('ball')), level(peer) == 0)[1], 20.0), \
        status(peer).message
    assert values(peer)['count.non_finite'] == '1'          # the total stays
    assert status(peer).name == '/collres_node: resolver'


def test_rate_below_min_rate_warns_and_silence_is_an_error(ros_domain, tmp_path, stopped):
    node, peer = start(ros_domain, tmp_path, args=['-r', '__ns:=/r1', '-p', 'min_rate:=1000.0'])
    stopped((node, peer))
    wait_up(peer, node, [('/r1/body_states', BodyStateArray)])
    assert peer.wait(lambda: level(peer) == 2, 10.0), status(peer)
    print(status(peer).name, status(peer).message)
    assert status(peer).name == '/r1/collres_node: resolver'
    assert 'min_rate 1000 Hz' in status(peer).message
    k = 0

    def slow():
        nonlocal k
        k += 1
        peer.publish('/r1/body_states', batch(T0 + k * DT, [state('ball')]))
        return level(peer) == 1 and 'below min_rate' in status(peer).message
    assert peer.wait(slow, 20.0), status(peer).message


def test_a_burst_above_the_throughput_counts_every_lost_input(ros_domain, tmp_path, stopped):
    node, peer = start(ros_domain, tmp_path)
    stopped((node, peer))
    wait_up(peer, node, [('body_states', BodyStateArray)])
    sent = 2001
    msg = batch(T0, [state('ball'), state('box', z=0.1, x=1.0)])
    peer.publish('body_states', msg)
    # the first message opens the publisher's stream: losses before it cannot be told from
    # messages published before the node subscribed (see ros/losses.py)
    assert peer.wait(lambda: answered(peer, 'body_states/corrected', T0), 15.0)
    for k in range(1, sent):
        msg.header.stamp = to_stamp(T0 + k * DT)
        peer.publish('body_states', msg)
    last = T0 + (sent - 1) * DT
    assert peer.wait(lambda: answered(peer, 'body_states/corrected', last), 60.0)

    def settled():
        v = values(peer)
        return v.get('steps') and int(v['inputs_received']) == int(v['steps']) and \
            int(v['inputs_received']) + int(v['inputs_lost']) == sent
    assert peer.wait(settled, 30.0), [(kv.key, kv.value) for kv in status(peer).values]
    v = values(peer)
    print({k: v[k] for k in ('steps', 'inputs_received', 'inputs_lost')}, status(peer).message)
    assert int(v['inputs_lost']) > 0, 'the burst did not overflow the queue'
    answers = len({stamp_ns(m.header.stamp) for m in peer.messages('body_states/corrected')})
    assert answers <= int(v['steps'])
    assert 'lost before taken' in status(peer).message or level(peer) == 1


def test_log_lines_stay_short_and_say_what_happened(ros_domain, tmp_path, stopped):
    names = [f'body_{i:03d}' for i in range(300)]
    scene = tmp_path / 'many.yaml'
    scene.write_text('/**:\n  ros__parameters:\n    bodies: [floor, ' + ', '.join(names) + ']\n'
                     '    body:\n      floor: {shape: box, size: [100.0, 100.0, 0.2], '
                     'static: true, position: [0.0, 0.0, -0.1]}\n')
    node = processes.start('collres_node', ['--ros-args', '--params-file', str(scene)],
                           env=processes.ros_env(ros_domain), log=tmp_path / 'node.log')
    peer = Peer(ros_domain)
    peer.listen('body_states/corrected', BodyStateArray)
    peer.listen('/diagnostics', DiagnosticArray)   # last: see wait_up
    stopped((node, peer))
    wait_up(peer, node, [('body_states', BodyStateArray)])
    for stamp in (T0, T0 + DT, T0 + 100 * S):            # the last one: a large gap
        peer.publish('body_states', batch(stamp, [state('body_000'), state('u' * 200)]))
        assert peer.wait(lambda: answered(peer, 'body_states/corrected', stamp), 15.0)
    peer.publish('body_states', batch(T0 + 101 * S, [state('u' * 10_000)]))   # refused whole
    assert peer.wait(lambda: 'large_gap' in node.output() and 'unknown_body' in node.output()
                     and 'too_large' in node.output(), 10.0), node.output()[-2000:]
    log = node.output()
    print(log[:3000])
    assert max(len(line) for line in log.splitlines()) < 300
    assert 'resolving 301 bodies (floor, body_000, body_001, body_002, body_003 +296 more)' in log
    assert 'fresh start [large_gap]' in log and 'input refused [large_gap]' not in log
    assert 'input refused [unknown_body]' in log
