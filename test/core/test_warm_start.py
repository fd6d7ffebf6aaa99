"""Warm start and the timing of the inputs: no step length can launch a resting body.

Last step's impulses warm start this step's only while dt / last dt stays near 1, and
never from a fresh step (the resolver's nominal dt after a start or a pause): a body's
answer does not depend on how its inputs happened to be spaced.
"""

from __future__ import annotations

import numpy as np
import pytest

from collres_ros.core.config import SolverSettings
from collres_ros.core.pipeline import Resolver
from collres_ros.core.types import BodyInput, ContactKind
from collres_ros.core.world import World
from collres_ros.ros.params import scene_from_values

from contacts import box as contacts_box, contact_set, FixedContacts, states  # noqa: I100

NS = 1
MS = 1_000_000 * NS
T0 = 5_000 * MS
HALF = 0.1       # m, half edge of the box


def floor_and_box(restitution=0.0):
    return scene_from_values({
        'bodies': ['floor', 'box'],
        'body.floor.shape': 'box', 'body.floor.size': [10.0, 10.0, 0.2],
        'body.floor.static': True, 'body.floor.position': [0.0, 0.0, -0.1],
        'body.floor.restitution': restitution,
        'body.box.shape': 'box', 'body.box.size': [2 * HALF] * 3, 'body.box.mass': 1.0,
        'body.box.restitution': restitution, 'body.box.static_friction': 0.5,
        'body.box.kinetic_friction': 0.3})


def box(z, velocity):
    return BodyInput('box', (0.0, 0.0, z), (0.0, 0.0, 0.0, 1.0), tuple(velocity),
                     (0.0, 0.0, 0.0), 'world', 'world')


@pytest.mark.parametrize('restitution', [0.0, 0.5])
@pytest.mark.parametrize('gap_ms', [10, 100, 500])
def test_touchdown_twice_1ns_apart_then_a_long_gap_does_not_launch_the_box(gap_ms, restitution):
    """A box touching down while sliding, whose state arrives twice 1 ns apart, then on
    the floor sliding at 0.1 m/s `gap_ms` later: it stays on the floor, does not spin up
    and gains no energy (last step's impulses are not scaled by dt / last dt = 1e7); with
    restitution 0 and with the default 0.5."""
    resolver = Resolver.for_scene(floor_and_box(restitution))
    landing = box(HALF - 2e-4, (0.1, 0.0, -0.3))   # 0.2 mm into the floor
    resolver.resolve(T0, [landing])
    resolver.resolve(T0 + 1 * NS, [landing])
    sliding = box(HALF - 2e-4, (0.1, 0.0, 0.0))
    out = resolver.resolve(T0 + 1 * NS + gap_ms * MS, [sliding])
    linear, angular = out.states.linear[0], out.states.angular[0]
    print(gap_ms, 'ms: v', linear, 'w', angular, 'z', out.states.position[0, 2])
    assert out.report.contacts.count > 0
    assert linear[2] < 1e-3                     # m/s: not leaving the floor
    assert np.linalg.norm(angular) < 1e-2       # rad/s: not spun up
    assert np.linalg.norm(linear) <= 0.1 * (1 + 1e-9)   # no energy from nowhere
    assert out.states.position[0, 2] < HALF + 1e-4


def test_a_fresh_step_does_not_warm_start_the_next_and_a_step_of_like_length_does():
    """A box resting on a floor (hand-made contacts): after a fresh step, the next step of
    the same length starts cold (the most sweeps); after a normal step it is warm started
    (fewer sweeps), as is a step ten times as long (a node that dropped nine inputs); and
    a step ten and a half times as long as the last starts cold again. Sweeps are
    counted per substep of the resting solve (240 Hz: one; ten periods: several, each after
    the first warm started from the one before)."""
    floor = contacts_box('floor', (2.0, 2.0, 0.2), 1.0, static=True)
    cube = contacts_box('cube', (0.2, 0.2, 0.2), 1.0, mu_s=0.5, mu_k=0.5)
    corners = [[x, y, 0.0] for x in (-0.1, 0.1) for y in (-0.1, 0.1)]
    dt = 1 / 240
    detector = FixedContacts(contact_set(0, 1, corners, [0, 0, 1], 0.0))
    world = World([floor, cube], SolverSettings(velocity_iterations=4), detector)
    rest = states([[0, 0, -0.1], [0, 0, 0.1]], np.zeros((2, 3)))

    def sweeps(step_dt, fresh=False):
        # the contacts of the box fallen for step_dt from rest on the floor
        detector.contacts = contact_set(0, 1, corners, [0, 0, 1], -9.81 * step_dt ** 2,
                                        kind=ContactKind.PERSISTENT)
        fall = rest.copy()
        fall.linear[1, 2] = -9.81 * step_dt
        fall.position[1, 2] += fall.linear[1, 2] * step_dt
        world.step(rest, fall, step_dt, fresh=fresh)
        return world.timing['iterations'] / world.timing['substeps']
    cold = sweeps(dt, fresh=True)
    after_fresh = sweeps(dt)
    warm = sweeps(dt)
    long = sweeps(10 * dt)
    sweeps(dt)
    stretched = sweeps(10.5 * dt)
    print('sweeps: fresh', cold, 'after fresh', after_fresh, 'warm', warm,
          'after 10 dt', long, 'after 10.5 dt', stretched)
    assert after_fresh == cold
    assert warm < cold and long < cold
    # its first substep starts cold (the others warm from the one before): more sweeps than
    # the warm started step ten periods long
    assert stretched > long


@pytest.mark.parametrize('down', [0.0, 0.05])
@pytest.mark.parametrize('gap_ms', [10, 100, 500])
def test_a_box_that_bounced_and_is_put_back_on_its_floor_rests_there(gap_ms, down):
    """A box lands at 1 m/s (e 0.5) at the end of a 100 Hz step and is answered leaving its
    floor at 0.62 m/s; the next input, `gap_ms` later, puts it back on the floor, at rest or
    moving down at `down` m/s. Nothing holds it from the step's start (it was leaving its
    floor): it is not carried on by its bounce, but meets the floor as its input says and
    rests there, its pose its last one advanced by its answered twist (within the slop it
    closed). On 7ed1f81 the step's external change, spread over the substeps, carried the
    bounce on: at rest 1.6 / 27 / 136 mm above the floor, moving down 1.2 / 24 / 122 mm."""
    resolver = Resolver.for_scene(floor_and_box(restitution=0.5))
    dt = 0.01
    fall = -1.0 - 9.81 * dt
    start = HALF - 0.999 * fall * dt   # touches the floor at the end of the step
    resolver.resolve(T0, [box(start, (0.0, 0.0, -1.0))])
    bounced = resolver.resolve(T0 + 10 * MS, [box(start + fall * dt, (0.0, 0.0, fall))])
    leaving = bounced.states.linear[0, 2]
    assert leaving > 0.5                          # m/s: it bounced
    was = bounced.states.position[0].copy()
    out = resolver.resolve(T0 + (10 + gap_ms) * MS, [box(HALF, (0.0, 0.0, -down))])
    position, linear = out.states.position[0], out.states.linear[0]
    print(f'{gap_ms} ms: bounced at {leaving:.3f} m/s, answered '
          f'{(position[2] - HALF) * 1e3:.4f} mm above the floor at {linear} m/s')
    assert out.report.contacts.count > 0
    assert np.linalg.norm(linear) < 1e-6                       # at rest on the floor
    assert abs(position[2] - HALF) < 1e-4                      # on its floor (the slop)
    np.testing.assert_allclose(position, was + linear * gap_ms * 1e-3, atol=1e-4)
