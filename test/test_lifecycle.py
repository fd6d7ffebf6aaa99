"""collres_node --lifecycle over real DDS: driven by the lifecycle services from a test peer.

Unconfigured, the node has no topics; configured (inactive) it has them but
answers nothing; active it answers; deactivated it is silent again; cleanup
frees its topics; configured and activated again it answers. "Answers
nothing" is checked without waiting for silence: DDS delivers one writer's
samples in order, so a later step's answer arriving first proves the earlier
step, sent while inactive, was not answered.
"""

from __future__ import annotations

import time

import pytest
from lifecycle_msgs.msg import State, Transition
from lifecycle_msgs.srv import ChangeState, GetState
from diagnostic_msgs.msg import DiagnosticArray
from ros_harness import Peer, answered as service_answer, node_publishers, write_scene

from collres_ros.msg import BodyStateArray
from collres_ros.ros import processes
from collres_ros.ros.messages import stamp_ns
from test_node import DT, T0, body, states

pytestmark = pytest.mark.slow


# The state each transition leads to from the state before it.
GOAL = {Transition.TRANSITION_CONFIGURE: State.PRIMARY_STATE_INACTIVE,
        Transition.TRANSITION_ACTIVATE: State.PRIMARY_STATE_ACTIVE,
        Transition.TRANSITION_DEACTIVATE: State.PRIMARY_STATE_INACTIVE,
        Transition.TRANSITION_CLEANUP: State.PRIMARY_STATE_UNCONFIGURED}


def ready(peer, client, timeout=20.0):
    assert peer.wait(client.service_is_ready, timeout), f'{client.srv_name} not available'


def test_the_managed_node_answers_only_while_active(ros_domain, tmp_path):
    scene = write_scene(tmp_path / 'scene.yaml')
    node = processes.start('collres_node', ['--lifecycle', '--ros-args', '--params-file',
                                            str(scene)],
                           env=processes.ros_env(ros_domain), log=tmp_path / 'node.log')
    peer = Peer(ros_domain)
    try:
        change = peer.node.create_client(ChangeState, '/collres_node/change_state')
        get = peer.node.create_client(GetState, '/collres_node/get_state')

        ready(peer, get)
        ready(peer, change)

        def state():
            """The node's state; asked again until answered (a loaded server drops the
            response to a client its writer has not matched yet: see ``answered``)."""
            return service_answer(peer, lambda: get.call_async(GetState.Request())
                                  ).current_state.id

        def transition(kind):
            """Request the transition; if no response comes, the node's state says whether
            it was made (its response lost: done) or not yet (the request sent again). A
            refusal counts only if the node does not reach the transition's goal state: a
            request sent again while the first is being made is refused."""
            deadline = time.monotonic() + 30.0
            sent = []
            while True:
                sent.append(change.call_async(
                    ChangeState.Request(transition=Transition(id=kind))))
                if peer.wait(lambda: any(f.done() for f in sent), 2.0):
                    if any(f.done() and f.result().success for f in sent):
                        return
                    assert peer.wait(lambda: state() == GOAL[kind], 10.0), \
                        f'transition {kind} refused: {node.output()}'
                    return
                if state() == GOAL[kind]:
                    return
                assert time.monotonic() < deadline, f'transition {kind} never answered'

        def answered(stamp):
            return any(stamp_ns(m.header.stamp) == stamp
                       for m in peer.messages('body_states/corrected'))

        def publishers(topic):
            return peer.node.count_publishers(topic)

        def step(stamp):
            peer.publish('body_states', states(stamp, [body('ball', 0.5),
                                                       body('box', 0.1, x=1.0)]))

        assert state() == State.PRIMARY_STATE_UNCONFIGURED
        assert publishers('/body_states/corrected') == 0
        peer.listen('body_states/corrected', BodyStateArray)
        peer.listen('/diagnostics', DiagnosticArray)   # last: see ros_harness.node_and_peer
        peer.advertise('body_states', BodyStateArray)

        def matched(active=True):
            """Both sides of every match: the peer's publisher has the node's subscription,
            the peer's reader the node's answer, and (``active``: an inactive node reports
            nothing) the node's subscription the peer's publisher (its last /diagnostics
            report; a step sent before can be lost)."""
            return peer.connected('body_states') and any(
                s.get_publisher_count() for s in peer.node.subscriptions
                if s.topic_name == '/body_states/corrected') and (
                    not active or node_publishers(peer) >= 1)

        transition(Transition.TRANSITION_CONFIGURE)
        assert state() == State.PRIMARY_STATE_INACTIVE
        assert peer.wait(lambda: matched(active=False), 30.0), node.output()
        step(T0)                                   # inactive: dropped
        transition(Transition.TRANSITION_ACTIVATE)
        assert state() == State.PRIMARY_STATE_ACTIVE
        assert peer.wait(matched, 30.0), node.output()
        step(T0 + DT)
        assert peer.wait(lambda: answered(T0 + DT), 10.0), f'no answer while active: ' \
                                                           f'{node.output()}'
        assert not answered(T0), 'answered a step sent while inactive'

        transition(Transition.TRANSITION_DEACTIVATE)
        step(T0 + 2 * DT)                          # inactive again: dropped
        transition(Transition.TRANSITION_ACTIVATE)
        step(T0 + 3 * DT)
        assert peer.wait(lambda: answered(T0 + 3 * DT), 10.0), node.output()
        assert not answered(T0 + 2 * DT), 'answered a step sent after deactivate'

        transition(Transition.TRANSITION_DEACTIVATE)
        transition(Transition.TRANSITION_CLEANUP)
        assert state() == State.PRIMARY_STATE_UNCONFIGURED
        assert peer.wait(lambda: publishers('/body_states/corrected') == 0
                         and not peer.connected('body_states'), 20.0), 'cleanup kept topics'

        with peer.lock:   # the reports of the first configuration
            peer.received.pop('/diagnostics', None)
        transition(Transition.TRANSITION_CONFIGURE)
        transition(Transition.TRANSITION_ACTIVATE)
        assert peer.wait(matched, 30.0), node.output()
        step(T0 + 4 * DT)
        assert peer.wait(lambda: answered(T0 + 4 * DT), 10.0), node.output()
        print('answered', sorted((stamp_ns(m.header.stamp) - T0) // DT
                                 for m in peer.messages('body_states/corrected')))
        assert node.poll() is None
    finally:
        peer.close()
        if node.poll() is None:
            assert processes.stop(node) == 0, node.output()
