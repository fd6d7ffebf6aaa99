"""Collision filtering at runtime over real DDS: a test peer sets collres_node's parameters
through rclpy's parameter service client, and a filtered pair stops producing contacts."""

from __future__ import annotations

import pytest
from ros_harness import set_parameter
from test_node import DT, T0, body, running, step  # noqa: F401 (the node's fixture)

from collres_ros.msg import ContactArray
from collres_ros.ros.messages import stamp_ns

pytestmark = pytest.mark.slow


def _contacts(peer, stamp):
    """The contacts message of the step at ``stamp``: {(body_a, body_b) names}."""
    assert peer.wait(lambda: any(stamp_ns(m.header.stamp) == stamp
                                 for m in peer.messages('contacts')), 10.0)
    msg = [m for m in peer.messages('contacts') if stamp_ns(m.header.stamp) == stamp][-1]
    assert isinstance(msg, ContactArray)
    return {(c.body_a, c.body_b) for c in msg.contacts}


def _falling_onto_the_floor(peer, start):
    """Two 10 ms steps of the ball and the box, 1 mm into the floor and falling at 1 m/s:
    the pairs in contact and the corrected vertical speeds (ball, box) at the second."""
    for k, z in enumerate((0.099, 0.089)):
        out = step(peer, start + k * DT, [body('ball', z, -1.0), body('box', z, -1.0, x=1.0)])
    speeds = {b.name: b.twist.linear.z for b in out.bodies}
    return _contacts(peer, start + DT), speeds['ball'], speeds['box']


def test_filters_set_at_runtime_stop_the_contacts_of_their_pairs(request):
    peer, _ = request.getfixturevalue('running')   # collres_node on floor, ball, box
    before, ball, box = _falling_onto_the_floor(peer, T0)
    print('unfiltered: contacts', sorted(before), 'vz ball', ball, 'box', box)
    assert before == {('floor', 'ball'), ('floor', 'box')}
    assert ball > -0.5 and box > -0.5        # both stopped by the floor

    from rclpy.parameter import Parameter
    refused = {('ignore_pairs', ('ball:flor',)): "ignore_pairs: body 'flor' is not in bodies",
               ('ignore_pairs', ('ballfloor',)): 'ignore_pairs: each entry must be "a:b"',
               ('body.box.collision_mask', 70000): 'body.box.collision_mask',
               ('body.box.collision_group', -1): 'body.box.collision_group'}
    for (name, value), text in refused.items():
        result = set_parameter(peer, name, list(value) if isinstance(value, tuple) else value,
                               Parameter.Type.STRING_ARRAY if isinstance(value, tuple) else None)
        print(name, value, '->', result.reason)
        assert not result.successful and text in result.reason and '\n' not in result.reason

    assert set_parameter(peer, 'ignore_pairs', ['ball:floor'],
                         Parameter.Type.STRING_ARRAY).successful
    after, ball, box = _falling_onto_the_floor(peer, T0 + 10 * 10**9)
    print('ball:floor ignored: contacts', sorted(after), 'vz ball', ball, 'box', box)
    assert after == {('floor', 'box')}
    assert ball == -1.0 and box > -0.5       # the ball keeps its velocity, the box does not

    assert set_parameter(peer, 'body.box.collision_mask', 0).successful   # accepts no other body
    masked, ball, box = _falling_onto_the_floor(peer, T0 + 20 * 10**9)
    print('box mask 0: contacts', sorted(masked), 'vz ball', ball, 'box', box)
    assert masked == set() and ball == -1.0 and box == -1.0

    assert set_parameter(peer, 'ignore_pairs', [], Parameter.Type.STRING_ARRAY).successful
    assert set_parameter(peer, 'body.box.collision_mask', 0xFFFF).successful
    again, ball, box = _falling_onto_the_floor(peer, T0 + 30 * 10**9)
    print('filters cleared: contacts', sorted(again))
    assert again == before
