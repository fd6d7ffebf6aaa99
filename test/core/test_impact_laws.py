"""Impacts through touching bodies, simultaneous impacts and manifolds: the energy laws.

With e = 1 an impact keeps the kinetic energy, however many bodies it passes through
(a Newton's cradle passes it on as successive binary impacts) and however many contacts
take part at once (simultaneous impacts get the simultaneous Newton answer); for e <= 1
no contact configuration gains energy (coincident points, a flat hit with friction);
the answer does not depend on the order of the bodies or of the contacts.
"""

from __future__ import annotations

import numpy as np
import pytest

from collres_ros.core.config import SolverSettings
from collres_ros.core.types import BodySpec, ContactKind
from collres_ros.core.world import World

from contacts import box, contact_set, FixedContacts, sphere, states  # noqa: I100
from integrator import Simulation
from test_physics_properties import totals

ZERO_G = np.zeros(3)


def kinetic(world: World, s) -> float:
    return totals(world, s, np.zeros(3))[2]


def solved_at(before, after):
    """The solved velocities at the poses they were solved at (energy, momenta)."""
    out = after.copy()
    out.position, out.orientation = before.position, before.orientation
    return out


@pytest.mark.parametrize('touching', [3, 5])
def test_newtons_cradle_passes_the_impact_to_the_last_ball(touching):
    """A ball at v0 hits a row of `touching` resting balls (e = 1, no gravity): the last
    ball leaves at v0, the others stay, the kinetic energy is kept."""
    r, v0 = 0.05, 1.0
    bodies = [sphere(f's{i}', r, 1.0, e=1.0) for i in range(touching + 1)]
    x = [-2 * r - 0.004] + [2 * r * i for i in range(touching)]
    initial = states([[xi, 0.0, 0.0] for xi in x], [[v0, 0.0, 0.0]] + [[0.0] * 3] * touching)
    sim = Simulation(bodies, initial, 240.0, gravity=ZERO_G)
    energy = sim.energy()
    for _ in range(48):
        sim.step()
    v = sim.state.linear[:, 0]
    print('velocities', v, 'energy ratio', sim.energy() / energy)
    assert sim.energy() == pytest.approx(energy, rel=0.01)
    assert v[-1] >= 0.95 * v0
    assert np.all(np.abs(v[:-1]) <= 0.05 * v0)


@pytest.mark.parametrize('r, v0, rate', [(0.01, 1.0, 30.0), (0.005, 3.0, 100.0),
                                         (0.005, 5.0, 240.0)])
def test_a_cradle_of_small_balls_struck_fast_passes_the_impact_to_the_last_ball(r, v0, rate):
    """The cradle with balls that move about a diameter per step (e = 1, no gravity): the
    striker meets the second ball within the step only through the first, so the hit still
    passes on ball by ball: the last ball leaves at v0, the others stay, energy is kept.
    (Was: the striker hit the first two balls at once; the last ball left at 0.50-0.89 v0.)"""
    touching = 5
    bodies = [sphere(f's{i}', r, 1.0, e=1.0) for i in range(touching + 1)]
    x = [-2 * r - 0.004] + [2 * r * i for i in range(touching)]
    initial = states([[xi, 0.0, 0.0] for xi in x], [[v0, 0.0, 0.0]] + [[0.0] * 3] * touching)
    sim = Simulation(bodies, initial, rate, gravity=ZERO_G)
    energy = sim.energy()
    for _ in range(max(8, int(0.3 * rate))):
        sim.step()
    v = sim.state.linear[:, 0]
    print('velocities', v / v0, 'energy ratio', sim.energy() / energy)
    assert sim.energy() == pytest.approx(energy, rel=0.01)
    assert v[-1] >= 0.95 * v0
    assert np.all(np.abs(v[:-1]) <= 0.05 * v0)


def three_ball_hit(order=(0, 1, 2), reverse_contacts=False):
    """Two unit spheres at 2 m/s strike a third at rest at the same instant from
    directions 120 degrees apart (e = 1). Returns (world, before, result, body order)."""
    r = 0.1
    n1 = np.array([1.0, 0.0, 0.0])
    n2 = np.array([np.cos(2 * np.pi / 3), np.sin(2 * np.pi / 3), 0.0])
    pos = {0: [0.0, 0.0, 0.0], 1: 2 * r * n1, 2: 2 * r * n2}
    lin = {0: [0.0, 0.0, 0.0], 1: -2.0 * n1, 2: -2.0 * n2}
    index = {body: k for k, body in enumerate(order)}        # body -> position in the list
    bodies = [sphere('abc'[body], r, 1.0, e=1.0) for body in order]
    before = states([pos[body] for body in order], [lin[body] for body in order])
    pairs = [(1, r * n1, n1), (2, r * n2, n2)]
    if reverse_contacts:
        pairs = pairs[::-1]
    a, b, point, normal = [], [], [], []
    for other, p, n in pairs:
        i, j = index[0], index[other]
        a.append(min(i, j))
        b.append(max(i, j))
        point.append(p)
        normal.append(n if i < j else -n)               # normal from A to B
    contacts = contact_set(a, b, point, normal, 0.0, kind=ContactKind.IMPACT)
    world = World(bodies, SolverSettings(), FixedContacts(contacts))
    return world, before, world.step(before, before.copy(), 0.01), index


def test_symmetric_three_ball_hit_gets_the_simultaneous_newton_answer():
    """Each contact reverses its normal approach: 8/3 N s each, mirror-symmetric, the
    kinetic energy kept."""
    world, before, result, _ = three_ball_hit()
    impulses = result.report.normal_impulse
    v = result.states.linear
    print('impulses', impulses, 'velocities', v)
    np.testing.assert_allclose(impulses, [8.0 / 3.0] * 2, atol=1e-6)
    # mirror about the bisector of the two approach directions (the 60 degree line)
    mirror = np.array([[-0.5, np.sqrt(0.75), 0.0], [np.sqrt(0.75), 0.5, 0.0],
                       [0.0, 0.0, 1.0]])
    np.testing.assert_allclose(mirror @ v[1], v[2], atol=1e-9)
    np.testing.assert_allclose(mirror @ v[0], v[0], atol=1e-9)
    assert kinetic(world, solved_at(before, result.states)) == pytest.approx(4.0, rel=1e-9)


@pytest.mark.parametrize('order,reverse', [((2, 0, 1), False), ((1, 2, 0), True),
                                           ((0, 1, 2), True)])
def test_impact_result_is_independent_of_body_and_contact_order(order, reverse):
    _, _, reference, _ = three_ball_hit()
    _, _, result, index = three_ball_hit(order, reverse)
    for body in range(3):
        np.testing.assert_allclose(result.states.linear[index[body]],
                                   reference.states.linear[body], atol=1e-9)
        np.testing.assert_allclose(result.states.angular[index[body]],
                                   reference.states.angular[body], atol=1e-9)


@pytest.mark.parametrize('angle', [90.0, 120.0, 150.0])
@pytest.mark.parametrize('radius, rate, arrive', [(0.05, 30.0, 0.1), (0.02, 60.0, 0.37),
                                                  (0.01, 120.0, 0.37), (0.005, 240.0, 0.1)])
def test_two_balls_striking_a_third_in_flight_get_the_simultaneous_newton_answer(
        angle, radius, rate, arrive):
    """Two equal balls (e = 1, 1 kg, 2 m/s) strike a third at rest at the same instant,
    `arrive` of the way into a step, from directions `angle` apart (>= 90 deg: after the hit
    the strikers move apart and never meet), integrated through World with coal's contacts
    and default settings: the simultaneous Newton answer, each striker's normal impulse
    P = 2 u / (2 + cos(angle)) m along its line, within 1e-6 of u. The strikers, unhindered,
    would overlap one another at the step's end: that contact, later in the step than the
    hits on the third ball and on the side of them (its normal out of a striker 90 - angle / 2
    deg from the hit's), must wait for them: the strikers then part. (Struck at once with
    the hits, the three contacts took 0.133, 0.133 and 0.231 N s at 120 deg and the strikers
    left at 1.15 m/s across their lines, 1.3 m/s from the answer; energy and momentum kept.)"""
    u = 2.0
    th = np.radians(angle)
    n = [np.array([1.0, 0.0, 0.0]), np.array([np.cos(th), np.sin(th), 0.0])]
    start = 2 * radius + arrive * u / rate
    sim = Simulation([sphere(f'b{i}', radius, 1.0, e=1.0) for i in range(3)],
                     states([[0.0] * 3, start * n[0], start * n[1]],
                            [[0.0] * 3, -u * n[0], -u * n[1]]), rate, gravity=ZERO_G)
    for _ in range(3):
        sim.step()
    impulse = 2 * u / (2 + np.cos(th))
    want = [-impulse * (n[0] + n[1]), (impulse - u) * n[0], (impulse - u) * n[1]]
    print('velocities', sim.state.linear, 'law', want)
    np.testing.assert_allclose(sim.state.linear, want, atol=1e-6 * u)


GAS_SIDE = 1.0   # m, the inside of the gas's closed box (centred on the origin)


def elastic_gas(rate: float, threshold: float, radius: float = 0.05, rms: float = 1.5,
                seed: int = 3) -> Simulation:
    """40 frictionless spheres (r 5 cm, 1 kg, e = 1) at 1.5 m/s rms in a closed box of
    static walls (inside GAS_SIDE wide), no gravity, at ``rate`` with ``threshold`` as the
    restitution threshold (m/s). Other radii scale the box and the walls with the balls
    (``radius`` / 0.05 of GAS_SIDE); ``rms`` (m/s) and ``seed`` draw the velocities."""
    rng = np.random.default_rng(seed)
    scale = radius / 0.05
    side, r, t = GAS_SIDE * scale, radius, 0.2 * scale
    outer = side + 2 * t
    walls = [box(f'w{i}', size, 1.0, e=1.0, static=True) for i, size in enumerate(
        [(outer, outer, t)] * 2 + [(t, outer, outer)] * 2 + [(outer, t, outer)] * 2)]
    d = (side + t) / 2
    wall_at = [[0, 0, -d], [0, 0, d], [-d, 0, 0], [d, 0, 0], [0, -d, 0], [0, d, 0]]
    grid = np.array([[x, y, z] for x in range(4) for y in range(4) for z in range(3)],
                    float)[:40]
    balls = [sphere(f'b{i}', r, 1.0, e=1.0) for i in range(40)]
    initial = states(wall_at + ((grid - grid.mean(0)) * 0.22 * scale).tolist(),
                     np.r_[np.zeros((6, 3)), rng.normal(0.0, rms, (40, 3))])
    return Simulation(walls + balls, initial, rate,
                      SolverSettings(restitution_threshold=threshold), gravity=ZERO_G)


@pytest.mark.slow
@pytest.mark.parametrize('rate', [30.0, 60.0, 120.0, 240.0])
def test_elastic_gas_in_a_closed_box_keeps_its_energy(rate):
    """40 frictionless spheres (e = 1) in a closed box for 5 s without gravity: the kinetic
    energy stays within 1 %, never above +0.5 %. The restitution threshold is set to
    0.05 m/s: slower approaches are inelastic by the threshold's definition. (When the
    resting solve measured a speculative row from the later of its two bodies' reference
    times, balls near a late impact were stopped short of it inelastically: 34 % lost at
    60 Hz, 15 % at 120 Hz.)"""
    sim = elastic_gas(rate, 0.05)
    energy, ratios, contacts = sim.energy(), [], 0
    for _ in range(int(5 * rate)):
        contacts += sim.step().report.contacts.count
        ratios.append(sim.energy() / energy)
    print('energy ratio: final', ratios[-1], 'min', min(ratios), 'max', max(ratios),
          'contacts', contacts)
    assert contacts > 1000
    assert min(ratios) >= 0.99
    assert max(ratios) <= 1.005


@pytest.mark.parametrize('rate', [30.0, 60.0, 120.0, 240.0])
def test_elastic_gas_keeps_its_energy_with_default_settings(rate):
    """The elastic gas with SolverSettings() (restitution_threshold 0.5 m/s): nothing presses
    two balls, or a ball and a wall, together (no gravity), so no approach rests on the
    threshold and every hit bounces. The kinetic energy stays within 1 % over 5 s, never
    above +0.5 %. (With the threshold a resting speed of every pair, the hits slower than
    0.5 m/s ended inelastically: 97.7-98.4 % of the energy was left after 5 s.)"""
    sim = elastic_gas(rate, SolverSettings().restitution_threshold)
    assert sim.world.settings == SolverSettings()
    assert_keeps_its_energy(sim, rate)


@pytest.mark.parametrize('rate', [30.0, 240.0])
@pytest.mark.parametrize('speed', [0.3, 0.1])
def test_a_free_ball_drifting_into_a_wall_bounces_below_the_threshold(rate, speed):
    """A ball (r 5 cm, 1 kg, e = 1) drifts at `speed`, below the default restitution
    threshold (0.5 m/s; above the sleep speed), into a static wall (e = 1) without
    gravity, default settings:
    nothing loads it, so nothing would bring a slow bounce back, and it leaves at the
    speed it came (Newton, e = 1). (With the threshold the resting speed of every pair,
    it stopped at the wall and stayed there: all of its energy lost.)"""
    r = 0.05
    wall = box('wall', (0.2, 1.0, 1.0), 1.0, e=1.0, static=True)
    ball = sphere('ball', r, 1.0, e=1.0)
    sim = Simulation([wall, ball], states([[0.0, 0.0, 0.0], [0.1 + r + 0.5 * speed / rate,
                                                             0.0, 0.0]],
                                          [[0, 0, 0], [-speed, 0.0, 0.0]]),
                     rate, gravity=ZERO_G)
    assert sim.world.settings == SolverSettings()
    closest = np.inf
    for _ in range(int(round(0.25 * rate))):
        sim.step()
        closest = min(closest, float(sim.state.position[1, 0]))
    print(f'{rate:g} Hz, {speed} m/s: after {sim.state.linear[1]} m/s, '
          f'closest {(closest - 0.1 - r) * 1e3:.3f} mm')
    np.testing.assert_allclose(sim.state.linear[1], [speed, 0.0, 0.0], atol=1e-9)
    assert closest > 0.1 + r - 1e-4


@pytest.mark.parametrize('rate', [50.0, 60.0, 100.0])
def test_an_elastic_gas_of_small_balls_keeps_its_energy(rate):
    """The elastic gas with balls of 5 mm in a 10 cm box (0.5 m/s rms, threshold 0.05 m/s):
    balls pass each other and their neighbours well inside the 2 cm speculative margin,
    so most hits are gap contacts that close within a step. The kinetic energy stays
    within 1 % over 5 s, never above +0.5 %. (A gap contact closed within the step by a
    partner's impact, or by a pass, was stopped at the touch by the resting solve and its
    landing, without a bounce: at 50, 60 and 100 Hz 9.0, 19.1 and 15.5 % lost, up to
    6.2 % in one step.)"""
    sim = elastic_gas(rate, 0.05, radius=0.005, rms=0.5, seed=1)
    assert_keeps_its_energy(sim, rate)


def assert_keeps_its_energy(sim, rate):
    """The gas's kinetic energy over 5 s of steps at ``rate``: within 1 %, never above
    +0.5 %."""
    energy, ratios = sim.energy(), []
    for _ in range(int(5 * rate)):
        sim.step()
        ratios.append(sim.energy() / energy)
    print('energy ratio: final', ratios[-1], 'min', min(ratios), 'max', max(ratios))
    assert min(ratios) >= 0.99
    assert max(ratios) <= 1.005


@pytest.mark.parametrize('radius,rms,rate,seed', [
    (0.02, 5.0, 30.0, 1), (0.05, 5.0, 30.0, 2), (0.005, 0.5, 30.0, 1), (0.005, 5.0, 120.0, 1),
    (0.005, 0.5, 30.0, 2), (0.005, 1.5, 60.0, 2)])
def test_an_elastic_gas_of_fast_balls_keeps_its_energy(radius, rms, rate, seed):
    """The elastic gas with balls that travel farther in a step than half a wall is thick
    (the walls are 0.2 m scaled with the balls: 2 cm balls at 5 m/s rms at 30 Hz, 5 cm at
    5 m/s, 5 mm at 0.5 m/s, 5 mm at 5 m/s at 120 Hz): the kinetic energy stays within 1 %
    over 5 s, never above +0.5 %. A ball struck into a wall within a step waits at the wall
    with its velocity for the next step's bounce; that step's contact must be the face it
    touches, not the far face or the end face of a wall its motion carried it to, nor be
    dropped as buried in a third wall it is carried out beside. (Was: the ball stopped dead
    where it stood: 0.12, 0.54, 0.62 and 0.062 of the energy left.) A ball that a wall's
    impact drives into a ball it was apart from bounces off it, also when their gap closes
    in a substep before the step's last. (Was: that pair stopped inelastically, 0.985 and
    0.976 of the energy left with 5 mm balls at 0.5 m/s and 30 Hz and at 1.5 m/s and 60 Hz.)"""
    sim = elastic_gas(rate, 0.05, radius=radius, rms=rms, seed=seed)
    assert_keeps_its_energy(sim, rate)


def test_two_coincident_points_between_spheres_gain_no_energy():
    """Two identical contact points (a degenerate patch) between two spinning spheres,
    average combine rules (a case the random property test once failed on: 258.7 J in,
    270.3 J out)."""
    bodies = [BodySpec('a', 'sphere', (0.53,), mass=6.5, restitution=0.84,
                       static_friction=0.93, kinetic_friction=1.46),
              BodySpec('b', 'sphere', (0.13,), mass=7.1, restitution=0.43,
                       static_friction=0.71, kinetic_friction=0.51)]
    before = states([[0.44, 0.19, -0.33], [-0.92, -0.6, -0.24]],
                    [[-1.4, 4.0, -2.9], [-4.7, 1.9, 4.3]],
                    [[-2.3, -4.5, 4.0], [-3.7, -2.3, -4.6]])
    point = [-0.42, -0.21, -0.35]
    contacts = contact_set(0, 1, [point, point], [0.9, 0.3, -0.5], 0.0,
                           kind=ContactKind.IMPACT)
    config = SolverSettings(restitution_rule='average', friction_rule='average',
                            restitution_threshold=0.0)
    world = World(bodies, config, FixedContacts(contacts, config))
    result = world.step(before, before.copy(), 0.01)
    k0 = totals(world, before, np.array(point))[2]
    k1 = totals(world, solved_at(before, result.states), np.array(point))[2]
    print('kinetic energy', k0, '->', k1, 'impulses', result.report.normal_impulse)
    assert result.report.normal_impulse.sum() > 0.0
    assert k1 <= k0 * (1 + 1e-9)


def test_thin_box_hitting_a_wall_flat_gets_mirror_symmetric_impulses_and_no_energy():
    """A long thin box (1 m x 0.1 m x 0.1 m) spinning about its long axis hits a wall with
    the edge that leads the spin (e = 0.5, friction): the hit is mirror-symmetric about
    the box's middle, so are the two corners' impulses and the box's motion after."""
    bodies = [box('wall', (0.2, 4.0, 4.0), 1.0, e=0.5, mu_s=0.5, mu_k=0.4, static=True),
              box('stick', (0.1, 1.0, 0.1), 2.0, e=0.5, mu_s=0.5, mu_k=0.4)]
    before = states([[-0.1, 0.0, 0.0], [0.05, 0.0, 0.0]], [[0, 0, 0], [-3.0, 0.0, 1.0]],
                    [[0, 0, 0], [0.0, 60.0, 0.0]])
    corners = [[0.0, 0.5, -0.05], [0.0, -0.5, -0.05]]
    contacts = contact_set(0, 1, corners, [1.0, 0.0, 0.0], 0.0, kind=ContactKind.IMPACT)
    world = World(bodies, SolverSettings(), FixedContacts(contacts))
    result = world.step(before, before.copy(), 0.01)
    impulses = result.report.normal_impulse
    friction = result.report.friction_impulse
    v, w = result.states.linear[1], result.states.angular[1]
    k0 = kinetic(world, before)
    k1 = kinetic(world, solved_at(before, result.states))
    print('impulses', impulses, 'friction', friction, 'v', v, 'w', w, 'energy', k0, k1)
    assert impulses[0] > 0.0
    assert impulses[0] == pytest.approx(impulses[1], rel=1e-6)
    flip = np.array([1.0, -1.0, 1.0])                   # the mirror y -> -y
    np.testing.assert_allclose(friction[0], flip * friction[1], atol=1e-6 * impulses[0])
    assert abs(v[1]) < 1e-9 and abs(w[0]) < 1e-6 and abs(w[2]) < 1e-6
    assert k1 <= k0 * (1 + 1e-9)


@pytest.mark.parametrize('spacing', [0.0, 0.001, 0.01, 0.1])
def test_two_point_impact_with_kinetic_friction_gains_no_energy(spacing):
    """A spinning box hits a floor through two hand-made points `spacing` apart (lever arm
    0.22 m), friction 0.9, e = 0.79: the kinetic energy does not grow (e times each
    point's compression impulse alone returned up to 61 % more than it came in with)."""
    bodies = [box('floor', (4.0, 4.0, 0.2), 1.0, e=0.79, mu_s=0.9, mu_k=0.9, static=True),
              box('box', (0.4, 0.2, 0.1), 1.0, e=0.79, mu_s=0.9, mu_k=0.9)]
    before = states([[0.0, 0.0, -0.3], [0.0, 0.0, 0.0]], [[0, 0, 0], [0.4, 1.0, -1.2]],
                    [[0, 0, 0], [-9.0, 9.0, -9.0]])
    centre, along = np.array([-0.01, 0.14, -0.17]), np.array([-3.0, -1.0, 0.0]) / np.sqrt(10)
    edge = [centre + 0.5 * spacing * along, centre - 0.5 * spacing * along]
    contacts = contact_set(0, 1, edge, [0.0, 0.0, 1.0], 0.0, kind=ContactKind.IMPACT)
    world = World(bodies, SolverSettings(), FixedContacts(contacts))
    result = world.step(before, before.copy(), 0.01)
    k0 = kinetic(world, before)
    k1 = kinetic(world, solved_at(before, result.states))
    print('spacing', spacing, 'energy', k0, '->', k1, 'impulses',
          result.report.normal_impulse)
    assert result.report.normal_impulse.sum() > 0.0
    assert k1 <= k0 * (1 + 1e-9)


def test_a_four_point_impact_whose_friction_turns_a_slip_around_gains_no_energy():
    """A spinning box hits a static box through four hand-made points with high friction
    (from the long random run: Coulomb friction on the coupled points of an impact's
    compression can return energy; 332.07 J in, up to 506.72 J out)."""
    bodies = [BodySpec('a', 'box', (0.22016, 0.279414, 0.139679), mass=35.060932,
                       restitution=0.666959, static_friction=1.418681,
                       kinetic_friction=1.29493),
              BodySpec('b', 'box', (0.740134, 0.752482, 0.290008), static=True,
                       restitution=0.669645, static_friction=1.010309,
                       kinetic_friction=1.010309)]
    before = states([[0.110371, 0.186158, 0.036925], [0.162722, -0.087484, -0.133736]],
                    [[0.486458, -3.444892, -2.548946], [0, 0, 0]],
                    [[4.50701, -2.165692, 2.955287], [0, 0, 0]],
                    [[-0.698873, 0.296756, 0.63349, 0.149002],
                     [0.593009, 0.797764, 0.013791, 0.108271]])
    points = [[-0.033088, 0.057197, 0.021485], [0.120271, 0.168808, -0.052102],
              [-0.013965, 0.209751, -0.254886], [0.266798, 0.154514, 0.056238]]
    contacts = contact_set(0, 1, points, [-0.851553, -0.360863, -0.380309],
                           [-0.00074854, -0.00107452, -1.303e-05, 0.00118236],
                           kind=ContactKind.IMPACT)
    config = SolverSettings(restitution_rule='max', friction_rule='min',
                            restitution_threshold=0.0)
    world = World(bodies, config, FixedContacts(contacts, config))
    result = world.step(before, before.copy(), 0.01)
    k0, k1 = kinetic(world, before), kinetic(world, solved_at(before, result.states))
    print('kinetic energy', k0, '->', k1, 'impulses', result.report.normal_impulse)
    assert result.report.normal_impulse.sum() > 0.0
    assert k1 <= k0 * (1 + 1e-9)


@pytest.mark.parametrize('rate, speed, late', [(60.0, 2.4, 0.9), (60.0, 1.2, 0.9),
                                               (120.0, 2.4, 0.9), (60.0, 2.4, 0.6)])
def test_a_ball_passing_a_late_bounce_keeps_the_energy(rate, speed, late):
    """Ball A bounces off a wall late in a step (e = 1 everywhere) while ball B comes down
    past it, 4 mm from touching it at the step's end on their unbounced paths: the step
    keeps the kinetic energy. (A resting solve that measured B's approach over the whole
    step against the time left after A's impact stopped B inelastically: 2.4 m/s -> 1.04
    m/s at 60 Hz, 44 % of the energy gone.)"""
    r, va, dt = 0.05, 1.85, 1.0 / rate
    bodies = [box('wall', (0.2, 2.0, 2.0), 1.0, e=1.0, static=True),
              sphere('a', r, 1.0, e=1.0), sphere('b', r, 1.0, e=1.0)]
    xa = -r - late * va * dt                 # meets the wall's face (x = 0) at `late` dt
    zb = 2 * r + 0.004 + speed * dt
    before = states([[0.1, 0.0, 0.0], [xa, 0.0, 0.0], [xa, 0.0, zb]],
                    [[0.0, 0.0, 0.0], [va, 0.0, 0.0], [0.0, 0.0, -speed]])
    after = before.copy()
    after.position += after.linear * dt
    world = World(bodies, SolverSettings(sleeping=False))
    result = world.step(before, after, dt)
    k0, k1 = kinetic(world, before), kinetic(world, result.states)
    print('impulses', result.report.normal_impulse, 'A', result.states.linear[1], 'B',
          result.states.linear[2], 'energy', k0, '->', k1)
    assert result.report.normal_impulse[0] == pytest.approx(2 * va)   # A bounced
    assert k1 == pytest.approx(k0, rel=1e-9)


@pytest.mark.parametrize('rate', [30.0, 60.0])
def test_a_ball_struck_towards_a_wall_keeps_the_energy(rate):
    """Ball B at 3 m/s strikes ball A at rest (e = 1 everywhere), which flies on into a
    wall within the same step: the kinetic energy is kept over the following steps
    (a sphere that the end-of-step hold-back stops short of a fixed shape keeps its
    twist; it was answered at rest, and all of the energy was lost)."""
    r, v, dt = 0.05, 3.0, 1.0 / rate
    bodies = [box('wall', (0.2, 2.0, 2.0), 1.0, e=1.0, static=True),
              sphere('a', r, 1.0, e=1.0), sphere('b', r, 1.0, e=1.0)]
    xa = r + 0.5 * v * dt                    # A reaches the wall before the step ends
    xb = xa + 2 * r + 0.3 * v * dt           # B strikes A at 0.3 of the step
    sim = Simulation(bodies, states([[-0.1, 0, 0], [xa, 0, 0], [xb, 0, 0]],
                                    [[0, 0, 0], [0, 0, 0], [-v, 0, 0]]), rate,
                     SolverSettings(sleeping=False), gravity=ZERO_G)
    energy = sim.energy()
    for _ in range(int(0.3 * rate)):
        sim.step()
        assert sim.energy() == pytest.approx(energy, rel=1e-6)
    assert sim.state.position[1, 0] >= r - 1e-4           # A never went into the wall


def test_a_ball_struck_while_passing_another_keeps_momentum_and_energy():
    """Ball A ((3, 3) m/s) passes ball B ((0, 3) m/s) 16 mm from touching it: over the
    step B slides 0.1 m past A, so their normal at the step's end is turned 51 deg from
    the one at its start; ball C comes at A at 3 m/s and strikes it within the step (e = 1,
    no gravity, default settings, 30 Hz). The three keep their momentum and their kinetic
    energy.
    (Their gap at the step's start measured along the end's normal read -27 mm: A and B
    were taken as each other's support, A leaving B at 1.3 m/s, and A's struck path was
    held against B one-sidedly: 1.42 N s of momentum appeared and 5.6 % of the
    energy went; an elastic gas of 40 balls in a box at 30 Hz lost 2.8 % in 5 s so.)"""
    balls = [sphere(name, 0.05, 1.0, e=1.0) for name in 'abc']
    sim = Simulation(balls, states([[-0.05, 0.0, 0.0], [0.0, 0.105, 0.0], [0.12, 0.12, 0.0]],
                                   [[3.0, 3.0, 0.0], [0.0, 3.0, 0.0], [-3.0, 0.0, 0.0]]),
                     30.0, gravity=ZERO_G)
    energy, momentum = sim.energy(), sim.state.linear.sum(axis=0)
    result = sim.step()
    impulses = result.report.normal_impulse
    print('energy', energy, '->', sim.energy(), 'momentum', momentum, '->',
          sim.state.linear.sum(axis=0), 'impulses', impulses)
    assert impulses.max() > 5.0                          # C struck A
    np.testing.assert_allclose(sim.state.linear.sum(axis=0), momentum, atol=1e-9)
    assert sim.energy() == pytest.approx(energy, rel=1e-9)


@pytest.mark.parametrize('drift', [0.04, 0.02])
def test_a_ball_struck_while_drifting_into_another_keeps_momentum(drift):
    """Ball A drifts at `drift` (below the 0.05 m/s restitution threshold) into ball B,
    touching it (5e-5 m apart), and ball C strikes A from the side at 3 m/s within the
    step (e = 1, no gravity, 30 Hz). Momentum is kept, and the energy up to A's drift
    into B (slower than the threshold: inelastic by the threshold's definition). (A was
    taken as resting on B and held on it one-sidedly, its approach into B dropped: the
    step lost all of the drift's momentum; an elastic gas of 2 cm balls at 0.5 m/s rms
    lost 1.0-1.4 % of its energy so at 30-100 Hz.)"""
    r, v, rate = 0.05, 3.0, 30.0
    balls = [sphere(name, r, 1.0, e=1.0) for name in 'abc']
    sim = Simulation(balls, states([[0.0, 0.0, 0.0], [2 * r + 5e-5, 0.0, 0.0],
                                    [0.0, 2 * r + 0.3 * v / rate, 0.0]],
                                   [[drift, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, -v, 0.0]]),
                     rate, SolverSettings(restitution_threshold=0.05), gravity=ZERO_G)
    energy, momentum = sim.energy(), sim.state.linear.sum(axis=0)
    result = sim.step()
    print('momentum', momentum, '->', sim.state.linear.sum(axis=0), 'energy', energy, '->',
          sim.energy(), 'impulses', result.report.normal_impulse)
    assert result.report.normal_impulse.max() > 2.0                 # C struck A
    np.testing.assert_allclose(sim.state.linear.sum(axis=0), momentum, atol=1e-9)
    assert energy - 0.5 * drift ** 2 <= sim.energy() <= energy * (1 + 1e-9)
