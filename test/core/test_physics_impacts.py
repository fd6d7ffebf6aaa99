"""Single impacts through World.step with coal detection: the classic impulse laws, no gravity.

Each test states the law, prints measured vs expected, and checks that the
impact really happened (an IMPACT contact with a positive normal impulse).
"""

from __future__ import annotations

import numpy as np
import pytest

from collres_ros.core.config import SolverSettings
from collres_ros.core.rotation import to_matrix
from collres_ros.core.shapes import mass_properties
from collres_ros.core.types import BodySpec, ContactKind, ContactState
from collres_ros.core.world import World

from contacts import box, sphere, states  # noqa: I100


def momentum(world: World, st) -> np.ndarray:
    mass = 1.0 / world.inv_mass
    return (mass[:, None] * st.linear).sum(axis=0)


def kinetic(world: World, st) -> float:
    mass = 1.0 / world.inv_mass
    energy = 0.5 * np.sum(mass * np.sum(st.linear ** 2, axis=1))
    for i, spec in enumerate(world.specs):
        inertia = np.linalg.pinv(world.inv_inertia_body[i])
        rot = to_matrix(st.orientation[i])
        energy += 0.5 * st.angular[i] @ (rot @ inertia @ rot.T) @ st.angular[i]
    return float(energy)


def angular_momentum(world: World, st, about: np.ndarray) -> np.ndarray:
    """Total angular momentum about a fixed point (kg m^2/s), world frame."""
    total = np.zeros(3)
    for i in range(len(world.specs)):
        mass = 1.0 / world.inv_mass[i]
        rot = to_matrix(st.orientation[i])
        inertia = rot @ np.linalg.pinv(world.inv_inertia_body[i]) @ rot.T
        total += np.cross(st.position[i] - about, mass * st.linear[i]) + inertia @ st.angular[i]
    return total


def assert_impact(result) -> None:
    report = result.report
    assert report.contacts.count >= 1, 'no contact found'
    assert np.any(report.state == ContactState.IMPACT), f'no IMPACT: {report.state}'
    assert np.all(report.normal_impulse >= 0.0)
    assert report.normal_impulse.sum() > 0.0
    assert not result.rejected


def head_on(mass_a: float, mass_b: float, e: float, va: float, vb: float,
            rule: str = 'max', ea: float | None = None, start: float = 0.25,
            fall: bool = False):
    """Two spheres on the x axis, r = 0.1 m, at -start and +start, closing in a 0.1 s step
    (``fall``: both falling under gravity along -z over the step, across their line: a
    load that changes no approach)."""
    world = World([sphere('a', 0.1, mass_a, e if ea is None else ea), sphere('b', 0.1, mass_b, e)],
                  SolverSettings(restitution_rule=rule))
    dt = 0.1
    before = states([[-start, 0, 0], [start, 0, 0]], [[va, 0, 0], [vb, 0, 0]])
    after = before.copy()
    if fall:
        after.linear[:, 2] -= 9.81 * dt
    after.position += after.linear * dt
    return world, before, world.step(before, after, dt)


def test_head_on_equal_spheres_elastic_swap_velocities():
    world, before, result = head_on(1.0, 1.0, 1.0, 3.0, -1.0)
    assert_impact(result)
    out = result.states
    print('velocities after', out.linear[:, 0], 'expected [-1, 3]')
    np.testing.assert_allclose(out.linear[:, 0], [-1.0, 3.0], rtol=0, atol=1e-12)
    p0, p1 = momentum(world, before), momentum(world, out)
    k0, k1 = kinetic(world, before), kinetic(world, out)
    print(f'momentum {p0} -> {p1}, energy {k0} -> {k1}')
    assert np.linalg.norm(p1 - p0) <= 1e-9 * np.linalg.norm(p0)
    assert abs(k1 - k0) <= 1e-9 * k0
    # the pair left the step apart: rewound to the time of impact, then separating
    gap = out.position[1, 0] - out.position[0, 0] - 0.2
    assert gap >= -1e-6


def test_unequal_masses_half_restitution():
    world, before, result = head_on(1.0, 3.0, 0.5, 2.0, -1.0)
    assert_impact(result)
    out = result.states
    approach = before.linear[1, 0] - before.linear[0, 0]
    leave = out.linear[1, 0] - out.linear[0, 0]
    print(f'relative normal velocity {approach} -> {leave}, ratio {leave / approach}')
    assert leave == pytest.approx(-0.5 * approach, abs=1e-12)
    p0, p1 = momentum(world, before), momentum(world, out)
    assert np.linalg.norm(p1 - p0) <= 1e-9 * np.linalg.norm(p0)


def test_off_centre_hit_spins_free_box_and_conserves_momenta():
    """Sphere hits the +x face of a free unit box 0.3 m off centre (n from box to sphere)."""
    bodies = [box('box', (1.0, 1.0, 1.0), 2.0, e=0.5), sphere('ball', 0.1, 1.0, e=0.5)]
    world = World(bodies, SolverSettings())
    dt = 0.05
    before = states([[0, 0, 0], [0.7, 0.3, 0]], [[0, 0, 0], [-2.0, 0, 0]])
    after = before.copy()
    after.position += after.linear * dt
    result = world.step(before, after, dt)
    assert_impact(result)
    out = result.states
    about = np.array([1.0, -2.0, 0.5])
    p0, p1 = momentum(world, before), momentum(world, out)
    l0, l1 = angular_momentum(world, before, about), angular_momentum(world, out, about)
    print(f'momentum {p0} -> {p1}; angular momentum {l0} -> {l1}; spin {out.angular[0]}')
    assert np.linalg.norm(p1 - p0) <= 1e-9 * np.linalg.norm(p0)
    assert np.linalg.norm(l1 - l0) <= 1e-9 * np.linalg.norm(l0)
    # impulse law: w_A+ = w_A- + I_A^-1 (r_A x (j n)), j = -(1 + e)(v_A - v_B).n / (...)
    c = result.report.contacts
    n, point, toi = c.normal[0], c.point[0], c.toi[0]
    assert c.kind[0] == ContactKind.IMPACT and n[0] > 0.99
    r_a = point - (before.position[0] + toi * (after.position[0] - before.position[0]))
    r_b = point - (before.position[1] + toi * (after.position[1] - before.position[1]))
    inv_ia, inv_ib = world.inv_inertia_body[0], world.inv_inertia_body[1]
    k = 1 / 2.0 + 1 / 1.0 + np.cross(inv_ia @ np.cross(r_a, n), r_a) @ n \
        + np.cross(inv_ib @ np.cross(r_b, n), r_b) @ n
    j = -(1 + 0.5) * (before.linear[0] - before.linear[1]) @ n / k
    spin = inv_ia @ np.cross(r_a, j * n)
    print(f'spin measured {out.angular[0]} expected {spin}')
    assert spin[2] > 0.0 and out.angular[0, 2] > 0.0
    np.testing.assert_allclose(out.angular[0], spin, rtol=1e-9, atol=1e-12)


def test_oblique_frictionless_impact_on_plane():
    floor = BodySpec('floor', 'plane', (0.0, 0.0, 1.0, 0.0), static=True, restitution=0.5,
                     static_friction=0.0, kinetic_friction=0.0)
    ball = sphere('ball', 0.1, 1.0, e=0.5)
    world = World([floor, ball], SolverSettings())
    dt = 0.02
    before = states([[0, 0, 0], [0, 0, 0.15]], [[0, 0, 0], [3.0, 0.0, -4.0]])
    after = before.copy()
    after.position += after.linear * dt
    result = world.step(before, after, dt)
    assert_impact(result)
    v = result.states.linear[1]
    print(f'velocity after {v}, expected [3, 0, 2]')
    np.testing.assert_allclose(v, [3.0, 0.0, 2.0], atol=1e-9)
    assert np.allclose(result.report.friction_impulse, 0.0)
    assert result.states.position[1, 2] >= 0.1 - 1e-6


def test_per_object_rule_is_the_textbook_model_and_breaks_momentum():
    """Per object: j_A uses e_A and j_B uses e_B: momentum changes by (e_A - e_B) j0."""
    world, before, result = head_on(1.0, 1.0, 0.0, 2.0, -2.0, rule='per_object', ea=1.0)
    assert_impact(result)
    out = result.states
    j0 = (before.linear[0, 0] - before.linear[1, 0]) / (1 / 1.0 + 1 / 1.0)   # inelastic, N s
    expected_a = before.linear[0, 0] - (1 + 1.0) * j0      # v_A+ = v_A- + j_A n / m_A
    expected_b = before.linear[1, 0] + (1 + 0.0) * j0
    print(f'per_object: v_A {out.linear[0, 0]} (expected {expected_a}), '
          f'v_B {out.linear[1, 0]} (expected {expected_b})')
    assert out.linear[0, 0] == pytest.approx(expected_a, abs=1e-12)
    assert out.linear[1, 0] == pytest.approx(expected_b, abs=1e-12)
    drift = momentum(world, out)[0] - momentum(world, before)[0]
    assert drift == pytest.approx(-(1.0 - 0.0) * j0, abs=1e-12)
    # the default rule conserves momentum for the same bodies
    world, before, result = head_on(1.0, 1.0, 0.0, 2.0, -2.0, ea=1.0)
    assert_impact(result)
    assert momentum(world, result.states)[0] == pytest.approx(momentum(world, before)[0],
                                                              abs=1e-12)


def test_slow_approach_rests_without_bounce():
    """Below restitution_threshold a contact that a load acts on is RESTING: no bounce (the
    resting rule; the two balls fall together across their line).

    The pair is 1 cm apart at the previous state (a speculative contact): it
    may close that gap during the step, then stops with zero relative speed in that
    same step (no approach is left for the next step to bounce on), and stays.
    """
    world, before, result = head_on(1.0, 1.0, 1.0, 0.2, -0.2, start=0.105, fall=True)
    first = result.states
    gap = first.position[1, 0] - first.position[0, 0] - 0.2
    print(f'after step 1: gap {gap}, relative velocity {first.linear[1, 0] - first.linear[0, 0]}')
    assert abs(gap) <= 1e-9
    assert result.report.contacts.count >= 1 and result.report.normal_impulse.sum() > 0.0
    assert np.all(result.report.state == ContactState.RESTING)
    assert abs(first.linear[1, 0] - first.linear[0, 0]) < 1e-9
    second = first.copy()
    second.position += second.linear * 0.1
    out = world.step(first, second, 0.1).states
    print('relative velocity after step 2', out.linear[1, 0] - out.linear[0, 0])
    assert abs(out.linear[1, 0] - out.linear[0, 0]) < 1e-9
    assert out.position[1, 0] - out.position[0, 0] - 0.2 == pytest.approx(gap, abs=1e-9)


def test_tunnelling_sphere_bounces_back_from_thin_wall():
    """2 cm sphere at 200 m/s, 1 cm wall, 100 Hz: separated at both ends, still caught."""
    wall = box('wall', (0.01, 1.0, 1.0), 1.0, e=1.0, static=True)
    ball = sphere('ball', 0.01, 0.1, e=1.0)
    world = World([wall, ball], SolverSettings())
    dt = 0.01
    before = states([[0, 0, 0], [-1.0, 0, 0]], [[0, 0, 0], [200.0, 0, 0]])
    after = before.copy()
    after.position += after.linear * dt
    assert after.position[1, 0] > 0.5     # the naive step ends far behind the wall
    result = world.step(before, after, dt)
    assert_impact(result)
    assert result.report.contacts.kind[0] == ContactKind.TUNNELLED
    out = result.states
    print(f'ball after: x {out.position[1, 0]}, v {out.linear[1]}')
    assert out.linear[1, 0] == pytest.approx(-200.0, rel=1e-9)
    assert out.position[1, 0] < -0.005 - 0.01 + 1e-6   # on the side it came from


def test_static_and_inactive_bodies_do_not_move():
    floor = box('floor', (4.0, 4.0, 0.2), 1.0, static=True)
    bodies = [floor, sphere('a', 0.1, 1.0, e=0.5), sphere('b', 0.1, 1.0, e=0.5)]
    world = World(bodies, SolverSettings())
    dt = 0.1
    before = states([[0, 0, -0.1], [-0.25, 0, 0.1], [0.25, 0, 0.1]],
                    [[0, 0, 0], [2.0, 0, 0], [-2.0, 0, 0]])
    after = before.copy()
    after.position += after.linear * dt
    active = np.array([True, True, False])
    result = world.step(before, after, dt, active)
    assert_impact(result)
    out = result.states
    np.testing.assert_array_equal(out.position[0], after.position[0])
    np.testing.assert_array_equal(out.position[2], after.position[2])
    np.testing.assert_array_equal(out.linear[2], after.linear[2])
    # the active sphere bounced off the held one as off a fixed wall: -e times its speed
    print('active sphere velocity', out.linear[1])
    assert out.linear[1, 0] == pytest.approx(-0.5 * 2.0, abs=1e-9)


def test_mass_properties_used_are_the_shapes():
    inv_mass, inv_inertia = mass_properties(sphere('s', 0.1, 2.0))
    assert inv_mass == pytest.approx(0.5)
    assert np.allclose(np.diag(inv_inertia), 1.0 / (0.4 * 2.0 * 0.01))


@pytest.mark.parametrize('gravity', [True, False])
def test_an_approach_gathered_from_gravity_rests_and_the_same_one_weightless_bounces(gravity):
    """A ball (e 1) meets a floor at 0.4 m/s in a step of 1/30 s, restitution_threshold
    0.05 m/s. Under gravity the step's external change brought g dt = 0.33 m/s of that
    approach (previous twist -0.07 m/s): below 1.5 g dt the contact is RESTING, and the
    ball lands without a bounce. The same approach with no external change (a weightless
    ball, previous twist -0.4 m/s) bounces at e (with a fixed resting speed of 0.05 m/s both
    bounced: a resting body bounced on what gravity gave it in one step)."""
    dt, v = 1.0 / 30.0, -0.4
    floor = BodySpec('floor', 'plane', (0.0, 0.0, 1.0, 0.0), static=True)
    world = World([floor, sphere('ball', 0.1, 1.0, e=1.0)],
                  SolverSettings(restitution_threshold=0.05, sleeping=False))
    before = states([[0, 0, 0], [0, 0, 0.105]],
                    [[0, 0, 0], [0, 0, v + 9.81 * dt if gravity else v]])
    after = before.copy()
    after.linear[1, 2] = v
    after.position[1, 2] += v * dt
    result = world.step(before, after, dt)
    leaving = result.states.linear[1, 2]
    print(f'gravity {gravity}: leaves at {leaving:.6f} m/s')
    if gravity:
        assert abs(leaving) < 1e-6
        assert np.all(result.report.state[result.report.contacts.body_b == 1] !=
                      ContactState.IMPACT)
    else:
        assert leaving == pytest.approx(-v, rel=1e-6)
