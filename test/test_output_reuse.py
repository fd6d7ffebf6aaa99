"""A step whose contacts are those of the last step (a sleeping pile's held contacts) has its
``contacts`` and ``contact_markers`` bytes restamped, not encoded again, and they are the bytes
a fresh encoding of that step gives: header stamps, each contact's time of impact (its span
changes when an input is lost), every field.

Two boxes stacked on a floor at 100 Hz, inputs as a simulator sends them (the last answer plus
gravity dt): they fall asleep, steps are lost (dt 20 ms), a push wakes them, they fall asleep
again while nobody subscribes (those steps are not encoded). Every step's outputs from the
node's one ``OutputEncoder`` equal those of an encoder that never saw a step before.
"""

from __future__ import annotations

import copy

import numpy as np

from collres_ros.core.pipeline import Resolver
from collres_ros.core.types import BodySpec, BodyStates, ContactState, InputBatch
from collres_ros.ros import codec, messages

RATE = 100.0
SIZE = 0.2
GRAVITY = np.array([0.0, 0.0, -9.81])


def stack() -> tuple[list[BodySpec], BodyStates]:
    bodies = [BodySpec('floor', 'plane', (0.0, 0.0, 1.0, 0.0), static=True),
              BodySpec('lower', 'box', (SIZE,) * 3, mass=1.0),
              BodySpec('upper', 'box', (SIZE,) * 3, mass=1.0)]
    state = BodyStates.zeros(3)
    state.position[1:, 2] = [SIZE / 2, 1.5 * SIZE]
    return bodies, state


def test_restamped_outputs_are_the_fresh_encoding(monkeypatch) -> None:
    built = {'contacts': 0, 'markers': 0}
    contacts_message, markers_message = codec.ContactsEncoder.message, codec.markers_message

    def counting(kind, build):
        def wrapped(*args, **kwargs):
            built[kind] += 1
            return build(*args, **kwargs)
        return wrapped
    monkeypatch.setattr(codec.ContactsEncoder, 'message', counting('contacts', contacts_message))
    monkeypatch.setattr(codec, 'markers_message', counting('markers', markers_message))

    bodies, state = stack()
    resolver = Resolver(bodies, initial=state)
    names = [b.name for b in bodies]
    encoder = messages.OutputEncoder(names, 'world')
    stamp, period = 5 * 10**9, int(1e9 / RATE)
    lost = {150, 153, 156, 159}              # inputs lost on the way: dt 20 ms
    push = 200                               # the upper box pushed sideways: it wakes
    unseen = range(push, push + 70)          # asleep again, not encoded (no subscriber)
    reused, asleep = {}, {}   # step -> outputs restamped; every contact held asleep
    values = np.concatenate([state.position[1:], state.orientation[1:],
                             state.linear[1:], state.angular[1:]], axis=1)
    for k in range(320):
        stamp += period
        values[:, 9] += GRAVITY[2] / RATE    # semi-implicit Euler: v += g dt, x += v dt
        values[:, 0:3] += values[:, 7:10] / RATE
        if k == push:
            values[1, 7] = 0.5
        if k in lost:
            continue
        step = resolver.resolve(stamp, InputBatch(names[1:], values.copy(), 'world', 'world'))
        held = step.report.state == ContactState.SLEEPING
        asleep[k] = bool(len(held) and held.all())
        values = messages.state_values(step.states)
        if k in unseen:   # nobody subscribed: not built
            continue
        before = dict(built)
        ours = (encoder.contacts(step), encoder.markers(step, 0.5))
        reused[k] = built == before
        fresh = messages.OutputEncoder(names, 'world')
        assert ours == (fresh.contacts(step), fresh.markers(step, 0.5)), f'step {k}'
    # asleep before the losses, through them, woken by the push, asleep again
    assert asleep[140] and asleep[199] and not asleep[push] and asleep[319]
    # restamped exactly when nothing changed: asleep, the step before asleep too; after a
    # lost input the same held contacts, their times of impact restamped with the new span
    assert sum(reused.values()) > 150
    assert all(asleep[k] for k, again in reused.items() if again)
    assert reused[160]
    # the first step built after steps it did not see: asleep in the same held contacts as
    # the step before, which are not those the last message was built from (before the push)
    assert asleep[push + 69] and asleep[push + 70] and not reused[push + 70]


def test_a_zero_that_changes_sign_is_encoded_again() -> None:
    """-0.0 equals 0.0 as a value but not as bytes: a step whose contacts differ from the last
    only by the sign of a zero gets the bytes of a fresh encoding, not the last message
    restamped (which would send the old sign)."""
    bodies, state = stack()
    resolver = Resolver(bodies, initial=state)
    names = [b.name for b in bodies]
    values = messages.state_values(state)[1:]
    period = int(1e9 / RATE)
    step = resolver.resolve(5 * 10**9, InputBatch(names[1:], values, 'world', 'world'))
    assert step.report.contacts.count
    encoder = messages.OutputEncoder(names, 'world')
    for k, zero in enumerate((0.0, -0.0)):
        now = copy.deepcopy(step)
        now.stamp_ns += k * period   # toi_ns, read first below, follows the stamp
        now.report.friction_impulse[0, 0] = zero
        now.report.contacts.point[0, 0] = zero
        fresh = messages.OutputEncoder(names, 'world')
        assert encoder.contacts(now) == fresh.contacts(now), zero
        assert encoder.markers(now, 0.5) == fresh.markers(now, 0.5), zero
