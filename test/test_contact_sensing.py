"""What touches what: the debounced per-body in_contact state and the get_contacts service.

The state law (``core/contact_state.py``): a body is in contact from the step whose normal
impulses on it sum to more than ``contact_on_impulse``, and out of contact only after
``contact_off_steps`` steps in a row without such a step. Checked on hand-made reports, on
a ball driven in-process as a simulator drives the node, then over DDS against the real node
process with the same driver: the topic carries false (at start), true (resting), nothing
for a hop shorter than the hysteresis, false in a jump, true at landing; the service answers
the last step's contacts by body, with the weight the floor carries.
"""

from __future__ import annotations

import numpy as np
import pytest

from collres_ros.core.contact_state import ContactStates, body_normal_impulses
from collres_ros.core.types import ContactReport, ContactSet, pair_manifolds


def report(pairs: list[tuple[int, int, float]]) -> ContactReport:
    """Contacts (body_a, body_b, normal impulse N s) at the origin, normal +z."""
    m = len(pairs)
    contacts = ContactSet(np.array([p[0] for p in pairs], np.int64),
                          np.array([p[1] for p in pairs], np.int64), np.zeros((m, 3)),
                          np.tile([0.0, 0.0, 1.0], (m, 1)), np.zeros(m), np.zeros(m),
                          np.zeros(m, np.int8), np.zeros(m, np.int64),
                          pair_manifolds(np.array([p[0] for p in pairs], np.int64),
                                         np.array([p[1] for p in pairs], np.int64)))
    return ContactReport(contacts, np.array([p[2] for p in pairs], float), np.zeros((m, 3)),
                         np.full(m, 2, np.uint8))


def test_impulses_are_summed_over_both_sides_of_every_contact() -> None:
    got = body_normal_impulses(report([(0, 1, 0.5), (1, 2, 0.25), (0, 2, 1.0)]), 4)
    assert got.tolist() == [1.5, 0.75, 1.25, 0.0]
    assert body_normal_impulses(ContactReport.empty(), 3).tolist() == [0.0, 0.0, 0.0]


def test_on_at_the_first_touch_and_off_only_after_the_quiet_steps() -> None:
    states = ContactStates(3, on_impulse=1e-3, off_steps=3)
    touch, quiet = report([(0, 1, 0.1)]), report([(0, 1, 0.0)])   # floor 0, ball 1
    history = []
    for r in (quiet, touch, quiet, quiet, touch, quiet, quiet, quiet, quiet):
        changed = states.update(r)
        history.append((bool(states.in_contact[1]), changed.tolist()))
    # a contact that carries no impulse (speculative) is no touch; on in the step of touch;
    # two quiet steps (fewer than off_steps) change nothing; off at the third quiet step
    assert history == [(False, []), (True, [0, 1]), (True, []), (True, []), (True, []),
                       (True, []), (True, []), (False, [0, 1]), (False, [])]
    assert not states.in_contact[2]


def test_the_threshold_is_strict_and_thresholds_are_checked() -> None:
    states = ContactStates(2, on_impulse=0.5, off_steps=1)
    states.update(report([(0, 1, 0.5)]))
    assert not states.in_contact.any()
    states.update(report([(0, 1, 0.5000001)]))
    assert states.in_contact.all()
    assert states.update(report([])).tolist() == [0, 1]
    for on, off in ((0.0, 1), (-1.0, 1), (1e-3, 0)):
        with pytest.raises(ValueError):
            ContactStates(2, on, off)


SCENE = """/**:
  ros__parameters:
    world_frame: world
    bodies: [floor, ball]
    body:
      floor: {shape: box, size: [10.0, 10.0, 0.2], static: true, restitution: 0.0,
              position: [0.0, 0.0, -0.1]}
      ball: {shape: sphere, size: [0.1], mass: 1.0, restitution: 0.0,
             position: [0.0, 0.0, 0.1]}
collres_node:
  ros__parameters:
    contact_state: true
    contact_off_steps: 3
"""
G, DT = 9.81, 0.01
# upward kicks (m/s) the driver adds at these steps: a hop of about one step in the air (fewer
# than contact_off_steps: no change), then a jump of about ten steps (off, then on at landing)
KICKS = {5: 0.2, 12: 0.6}
STEPS = 30


def drive(resolve) -> None:
    """A ball resting on the floor driven as a simulator drives the node: each input
    integrated with gravity (semi-implicit Euler) from the last answer, plus KICKS;
    ``resolve(k, z, vz)`` -> the answer (z, vz) of step k."""
    z, vz = 0.1, 0.0
    for k in range(STEPS):
        vz += -G * DT + KICKS.get(k, 0.0)
        z, vz = resolve(k, z + vz * DT, vz)


def test_a_hop_shorter_than_the_hysteresis_does_not_chatter_a_jump_does_switch(tmp_path):
    """In-process, the same driver as over DDS: the state's every change, by step."""
    from collres_ros.core.pipeline import Resolver
    from collres_ros.core.types import BodyInput
    from collres_ros.ros.params import load_scene
    path = tmp_path / 'scene.yaml'
    path.write_text(SCENE)
    scene = load_scene(path)
    resolver = Resolver.for_scene(scene)
    states = ContactStates(2, scene.node.contact_on_impulse, scene.node.contact_off_steps)
    changes, touched = [], []

    def resolve(k, z, vz):
        step = resolver.resolve(10**12 + k * 10**7, [BodyInput(
            'ball', (0.0, 0.0, z), (0.0, 0.0, 0.0, 1.0), (0.0, 0.0, vz), (0.0, 0.0, 0.0))])
        touched.append(body_normal_impulses(step.report, 2)[1] > 1e-6)
        if 1 in states.update(step.report):
            changes.append((k, bool(states.in_contact[1])))
        return step.states.position[0, 2], step.states.linear[0, 2]
    drive(resolve)
    off, on = changes[1][0], changes[2][0]
    print('touched by step', [int(t) for t in touched], 'changes', changes)
    assert [state for _, state in changes] == [True, False, True]
    assert changes[0][0] == 0 and not all(touched[5:12])   # the hop left the floor ...
    assert not any(touched[off - 2:off + 1]) and touched[off - 3]   # ... off at the 3rd
    assert touched[on] and not any(touched[off:on])                 # on again at landing


@pytest.mark.slow
def test_in_contact_and_get_contacts_over_dds(ros_domain, tmp_path) -> None:
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
    from std_msgs.msg import Bool
    from ros_harness import Peer, answered, node_and_peer, set_parameter
    from test_node import T0, body, step

    from collres_ros.msg import BodyStateArray
    from collres_ros.srv import GetContacts

    scene = tmp_path / 'scene.yaml'
    scene.write_text(SCENE)
    latched = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)
    with node_and_peer(ros_domain, scene, tmp_path / 'node.log', listen=(
            ('bodies/ball/in_contact', Bool, latched),
            ('body_states/corrected', BodyStateArray))) as (peer, node):
        client = peer.node.create_client(GetContacts, 'get_contacts')

        def ask(*bodies: str):
            return answered(peer, lambda: client.call_async(
                GetContacts.Request(bodies=list(bodies))))

        def seen():
            return [m.data for m in peer.messages('bodies/ball/in_contact')]
        assert peer.wait(lambda: client.service_is_ready() and seen() == [False], 30.0), \
            node.output()
        before = ask()
        assert not before.stepped and list(before.contacts) == []

        answers = []

        def resolve(k, z, vz):
            out = step(peer, T0 + k * 10**7, [body('ball', z, vz)]).bodies[0]
            answers.append((out.pose.position.z, out.twist.linear.z))
            if k == 11:    # resting: what touches the ball, by the service
                answer = ask('ball', 'nope')
                assert answer.stepped and list(answer.unknown_bodies) == ['nope']
                assert answer.header.frame_id == 'world' and len(answer.contacts) >= 1
                assert all(c.body_a == 'floor' and c.body_b == 'ball' and c.normal.z > 0.999
                           for c in answer.contacts)
                # at rest the floor carries the ball's weight over the step: m g dt
                assert sum(c.normal_impulse for c in answer.contacts) == pytest.approx(
                    G * DT, rel=0.01)
                assert len(ask().contacts) == len(answer.contacts)
            return out.pose.position.z, out.twist.linear.z
        drive(resolve)
        # on at the first step, no chatter over the hop, off in the jump, on at landing
        assert peer.wait(lambda: seen() == [False, True, False, True], 10.0), seen()
        # a runtime change of the thresholds starts every body out of contact again; the
        # ball, still resting, is in contact from its next step
        assert set_parameter(peer, 'contact_off_steps', 5).successful
        assert peer.wait(lambda: seen() == [False, True, False, True, False], 10.0), seen()
        z, vz = answers[-1]
        vz -= G * DT
        step(peer, T0 + STEPS * 10**7, [body('ball', z + vz * DT, vz)])
        assert peer.wait(lambda: seen() == [False, True, False, True, False, True], 10.0), \
            seen()
        # a subscriber that joins now still gets the current state (transient local)
        late = Peer(ros_domain, 'collres_late_peer')
        try:
            late.listen('bodies/ball/in_contact', Bool, latched)
            assert late.wait(lambda: [m.data for m in late.messages(
                'bodies/ball/in_contact')] == [True], 20.0)
        finally:
            late.close()
