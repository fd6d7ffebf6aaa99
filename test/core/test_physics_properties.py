"""Property tests (hypothesis) over random pairs and hand-made contacts.

For any two bodies (spheres or boxes, one possibly static), random poses,
twists, masses, materials and 1-4 contact points with a shared normal:
the step never emits NaN, every impulse conserves linear and angular
momentum (equal and opposite at the same point), and with e <= 1 the
kinetic energy never grows.
"""

from __future__ import annotations

import numpy as np
from hypothesis import given, HealthCheck, settings, strategies as st

from collres_ros.core.config import SolverSettings
from collres_ros.core.rotation import normalize, to_matrix
from collres_ros.core.types import BodySpec, ContactKind
from collres_ros.core.world import World

from contacts import contact_set, FixedContacts, states  # noqa: I100

finite = st.floats(-5.0, 5.0, allow_nan=False)
vec3 = st.tuples(finite, finite, finite)
unit_ish = st.tuples(finite, finite, finite).filter(lambda v: np.linalg.norm(v) > 0.1)


@st.composite
def body(draw, name: str, static: bool = False) -> BodySpec:
    shape = draw(st.sampled_from(['sphere', 'box']))
    size = (draw(st.floats(0.05, 1.0)),) if shape == 'sphere' else \
        tuple(draw(st.floats(0.05, 1.0)) for _ in range(3))
    return BodySpec(name, shape, size, static=static, mass=draw(st.floats(0.01, 100.0)),
                    restitution=draw(st.floats(0.0, 1.0)),
                    static_friction=draw(st.floats(0.0, 1.5)),
                    kinetic_friction=draw(st.floats(0.0, 1.5)))


@st.composite
def scene(draw):
    static_b = draw(st.booleans())
    bodies = [draw(body('a')), draw(body('b', static=static_b))]
    position = np.array([draw(vec3), draw(vec3)]) * 0.2
    orientation = normalize(np.array([draw(unit_ish) + (draw(st.floats(0.1, 1.0)),)
                                      for _ in range(2)]))
    linear = np.array([draw(vec3), draw(vec3)])
    angular = np.array([draw(vec3), draw(vec3)])
    normal = np.array(draw(unit_ish))
    points = draw(st.integers(1, 4))
    centre = 0.5 * (position[0] + position[1])
    point = centre + np.array([draw(vec3) for _ in range(points)]) * 0.05
    separation = draw(st.floats(-0.002, 0.002))
    kind = draw(st.sampled_from([ContactKind.PERSISTENT, ContactKind.IMPACT]))
    rule = draw(st.sampled_from(['average', 'min', 'max', 'multiply']))
    friction = draw(st.sampled_from(['geometric', 'average', 'min', 'max', 'multiply']))
    return bodies, position, orientation, linear, angular, normal, point, separation, kind, \
        rule, friction


def totals(world: World, s, about: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """(linear momentum, angular momentum about ``about``, kinetic energy) of dynamic bodies."""
    p, l, k = np.zeros(3), np.zeros(3), 0.0
    for i in range(len(world.specs)):
        if not world.dynamic[i]:
            continue
        m = 1.0 / world.inv_mass[i]
        rot = to_matrix(s.orientation[i])
        inertia = rot @ np.linalg.inv(world.inv_inertia_body[i]) @ rot.T
        p += m * s.linear[i]
        l += np.cross(s.position[i] - about, m * s.linear[i]) + inertia @ s.angular[i]
        k += 0.5 * m * s.linear[i] @ s.linear[i] + 0.5 * s.angular[i] @ inertia @ s.angular[i]
    return p, l, k


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(scene())
def test_random_pair_no_nan_momentum_conserved_no_energy_gain(case):
    bodies, position, orientation, linear, angular, normal, point, separation, kind, rule, \
        friction = case
    dt = 0.01
    before = states(position, linear, angular, orientation)
    # the current state equals the previous one: every change comes from the impulses
    contacts = contact_set(0, 1, point, normal, separation, toi=0.0, kind=kind)
    config = SolverSettings(restitution_rule=rule, friction_rule=friction,
                            restitution_threshold=0.0)
    world = World(bodies, config, FixedContacts(contacts, config))
    result = world.step(before, before.copy(), dt)
    out = result.states
    for array in (out.position, out.orientation, out.linear, out.angular):
        assert np.all(np.isfinite(array))
    report = result.report
    assert np.all(np.isfinite(report.normal_impulse)) and np.all(report.normal_impulse >= 0)
    assert np.all(np.isfinite(report.friction_impulse))
    assert not result.rejected
    if bodies[1].static:
        return   # a static body takes any impulse: momentum of the pair is not conserved
    about = point[0]
    p0, l0, k0 = totals(world, before, about)
    # the poses moved (advanced by the new twist); measure L at the solve configuration
    solved = out.copy()
    solved.position = before.position
    solved.orientation = before.orientation
    p1, l1, k1 = totals(world, solved, about)
    scale_p = max(np.abs(p0).max(), 1e-12)
    scale_l = max(np.abs(l0).max(), 1e-12)
    assert np.abs(p1 - p0).max() <= 1e-9 * scale_p + 1e-12
    assert np.abs(l1 - l0).max() <= 1e-9 * scale_l + 1e-12
    assert k1 <= k0 * (1 + 1e-9) + 1e-12


@settings(max_examples=60, deadline=None)
@given(scene())
def test_random_pair_with_static_body_gains_no_energy(case):
    bodies, position, orientation, linear, angular, normal, point, separation, kind, rule, \
        friction = case
    bodies = [bodies[0], BodySpec('wall', bodies[1].shape, bodies[1].size, static=True)]
    before = states(position, linear, angular, orientation)
    before.linear[1] = before.angular[1] = 0.0     # a resting static body
    contacts = contact_set(0, 1, point, normal, separation, toi=0.0, kind=kind)
    config = SolverSettings(restitution_rule=rule, friction_rule=friction,
                            restitution_threshold=0.0)
    world = World(bodies, config, FixedContacts(contacts, config))
    result = world.step(before, before.copy(), 0.01)
    out = result.states
    assert np.all(np.isfinite(out.linear)) and np.all(np.isfinite(out.angular))
    solved = out.copy()
    solved.orientation = before.orientation
    k0 = totals(world, before, point[0])[2]
    k1 = totals(world, solved, point[0])[2]
    assert k1 <= k0 * (1 + 1e-9) + 1e-12
