"""collres_node over real DDS with sleeping on (the default): a resting ball and box are
answered every step, flagged ``sleeping`` with zero twist once asleep, counted in
/diagnostics; given their rest after a gap longer than max_dt they resume asleep (and the log
says so: no fresh start); a message of one of them wakes neither; a push wakes the ball in
the step; the awake ball left out of a message and back in the next (a fresh restart) wakes
only what it touches, not the box."""

from __future__ import annotations

import pytest
from test_node import DT, T0, body, diagnostics_values, running, step  # noqa: F401

from collres_ros.ros.messages import stamp_ns

pytestmark = pytest.mark.slow
G = 9.81


def test_the_node_flags_sleeping_bodies_and_keeps_answering(running):  # noqa: F811
    peer, node = running
    dt = DT * 1e-9
    state = {'ball': (0.1, 0.0, 0.0), 'box': (0.1, 0.0, 1.0)}   # z, vz, x: at rest
    flags = []
    n = 100                                                      # 1 s of 10 ms steps
    for k in range(n):
        inputs = []
        for name, (z, vz, x) in state.items():   # the simulator's semi-implicit Euler
            vz -= G * dt
            inputs.append(body(name, z + vz * dt, vz, x=x))
        out = step(peer, T0 + k * DT, inputs)
        answers = {b.name: b for b in out.bodies}
        flags.append({name: b.sleeping for name, b in answers.items()})
        for name, b in answers.items():
            state[name] = (b.pose.position.z, b.twist.linear.z, b.pose.position.x)
            if b.sleeping:
                assert (b.twist.linear.x, b.twist.linear.y, b.twist.linear.z) == (0, 0, 0)
    stamps = [stamp_ns(m.header.stamp) for m in peer.messages('body_states/corrected')]
    assert stamps == [T0 + k * DT for k in range(n)], 'a step was not answered once'
    first = min(k for k, f in enumerate(flags) if f['ball'] and f['box'])
    print(f'both asleep from step {first} ({(first + 1) * dt:.2f} s)')
    assert 45 <= first <= 60          # time_to_sleep 0.5 s of still answers
    assert all(f['ball'] and f['box'] for f in flags[first:])
    assert peer.wait(lambda: diagnostics_values(peer).get('sleeping_bodies') == '2', 5.0), \
        diagnostics_values(peer)
    values = diagnostics_values(peer)
    assert (values['sleeping'], values['awake_bodies'], values['sleeping_islands']) == \
        ('on', '0', '2')
    # 1 s later (> max_dt 0.5 s), their rest advanced one period as a simulator that kept
    # integrating it sends it: both resume asleep, held where they rest
    resume = T0 + n * DT + 10**9
    out = step(peer, resume, [body(name, z - G * dt * dt, -G * dt, x=x)
                              for name, (z, vz, x) in state.items()])
    assert all(b.sleeping and b.pose.position.z == state[b.name][0] and b.twist.linear.z == 0
               for b in out.bodies), out.bodies
    assert peer.wait(lambda: '[large_gap]' in node.output(), 5.0), \
        node.output()[-2000:]
    print(node.output()[-400:])
    # (one line per reason per second: the ball's)
    assert 'resumed asleep [large_gap]: ball: 1.01 s since its last state' in node.output()
    assert 'fresh start' not in node.output()
    # a message of the box alone holds the ball, asleep, where it is: nothing wakes, and the
    # next message of both finds both asleep (7039d81 woke both: the box answered awake)
    rest = {name: body(name, z - G * dt * dt, -G * dt, x=x)
            for name, (z, vz, x) in state.items()}
    out = step(peer, resume + DT, [rest['box']])
    assert [(b.name, b.sleeping) for b in out.bodies] == [('box', True)], out.bodies
    out = step(peer, resume + 2 * DT, list(rest.values()))
    assert all(b.sleeping and b.pose.position.z == state[b.name][0] for b in out.bodies), \
        out.bodies
    # a push (1 m/s along x) wakes the ball in its step; the box sleeps on
    z, vz, x = state['ball']
    pushed = body('ball', z + (vz - G * dt) * dt, vz - G * dt, x=x + 1.0 * dt)
    pushed.twist.linear.x = 1.0
    out = step(peer, resume + 3 * DT, [pushed, body('box', state['box'][0] - G * dt * dt,
                                                    -G * dt, x=1.0)])
    answers = {b.name: b for b in out.bodies}
    assert not answers['ball'].sleeping and answers['box'].sleeping
    assert answers['ball'].twist.linear.x > 0.5
    # the ball, awake, left out of one message (held where it is) and back in the next
    # restarts fresh: it wakes only what it touches, the box 0.8 m away sleeps on (59f1d0c
    # woke every island on a fresh restart: the box answered awake)
    box_rest = body('box', state['box'][0] - G * dt * dt, -G * dt, x=1.0)
    out = step(peer, resume + 4 * DT, [box_rest])
    assert [(b.name, b.sleeping) for b in out.bodies] == [('box', True)], out.bodies
    ball = answers['ball']
    vx = ball.twist.linear.x
    back = body('ball', ball.pose.position.z, 0.0, x=ball.pose.position.x + 2 * vx * dt)
    back.twist.linear.x = vx
    out = step(peer, resume + 5 * DT, [back, box_rest])
    answers = {b.name: b for b in out.bodies}
    assert not answers['ball'].sleeping and answers['box'].sleeping, out.bodies
    assert answers['box'].pose.position.z == state['box'][0]
    assert node.poll() is None and 'Traceback' not in node.output()
