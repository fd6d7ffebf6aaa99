"""Detection defects found by physics laws (one test per defect, each fails on the old code).

1. A glancing impact between spheres that were already within the speculative margin
   before the step must be solved at its time of impact: the normal and lever arms of the
   end-of-step (overlapping) pose tilt the normal, break the restitution law along the
   true normal, spin the spheres and change the angular momentum.
2. A cylinder lying on its side on a floor must stay still: contact points reused in the
   body frame of a curved surface turn with the body and make it roll.
3. A flat landing must get its face manifold at the time of impact even where coal's
   GJK/EPA fail on the just-touching pose.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from collres_ros.core.config import SolverSettings
from collres_ros.core.types import BodySpec, ContactState
from collres_ros.core.world import World

from contacts import box, sphere, states  # noqa: I100
from integrator import Simulation


def test_glancing_impact_from_within_the_margin_is_solved_at_the_time_of_impact() -> None:
    # A (3 m/s along +x) meets B at rest with the line of centres 30 degrees off the motion;
    # 5 mm apart before the step (inside the 20 mm margin), overlapping after it
    r, speed, e, dt = 0.1, 3.0, 0.5, 1.0 / 240.0
    angle = math.radians(30.0)
    offset = 2 * r * math.sin(angle)
    x0 = math.sqrt((2 * r + 0.005) ** 2 - offset ** 2)
    world = World([sphere('a', r, 1.0, e), sphere('b', r, 1.0, e)], SolverSettings())
    before = states([[0, 0, 0], [x0, offset, 0]], [[speed, 0, 0], [0, 0, 0]])
    after = before.copy()
    after.position += after.linear * dt
    assert np.linalg.norm(after.position[1] - after.position[0]) < 2 * r   # overlapping now
    result = world.step(before, after, dt)
    out, report = result.states, result.report
    assert report.contacts.count == 1 and report.state[0] == ContactState.IMPACT
    assert report.normal_impulse[0] > 0.0
    true_normal = np.array([math.cos(angle), math.sin(angle), 0.0])
    tilt = math.degrees(math.acos(min(1.0, float(report.contacts.normal[0] @ true_normal))))
    approach = (before.linear[1] - before.linear[0]) @ true_normal
    leave = (out.linear[1] - out.linear[0]) @ true_normal
    spin = np.linalg.norm(out.angular, axis=1)
    # angular momentum about the origin (equal spheres, unit mass: spins add I w)
    inertia = 0.4 * r * r
    momentum_before = sum(np.cross(before.position[k], before.linear[k]) for k in range(2))
    momentum_after = sum(np.cross(out.position[k], out.linear[k]) + inertia * out.angular[k]
                         for k in range(2))
    change = float(np.linalg.norm(momentum_after - momentum_before))
    print(f'normal {tilt:.4f} deg off the line of centres at impact; restitution along it '
          f'{-leave / approach:.5f} (e = {e}); spins {spin} rad/s; '
          f'angular momentum change {change:.2e} N m s')
    assert tilt < 0.05
    assert abs(-leave / approach - e) < 2e-3
    assert np.all(spin < 1e-9)      # a frictionless hit along the line of centres: no spin
    assert change < 1e-6


@pytest.mark.parametrize('floor', [BodySpec('floor', 'box', (4, 4, 0.2), static=True),
                                   BodySpec('floor', 'plane', (0, 0, 1, 0), static=True)],
                         ids=['box', 'plane'])
def test_cylinder_lying_on_its_side_stays_still(floor: BodySpec) -> None:
    r, length = 0.1, 0.3
    lying = [math.sin(math.pi / 4), 0.0, 0.0, math.cos(math.pi / 4)]   # axis along y
    bodies = [floor, BodySpec('log', 'cylinder', (r, length), mass=2.0, static_friction=0.5,
                              kinetic_friction=0.3, restitution=0.2)]
    top = 0.0 if floor.shape == 'plane' else -0.1   # floor origin: its top face at z = 0
    start = states([[0, 0, top], [0, 0, r]], [[0, 0, 0], [0, 0, 0]],
                   orientation=[[0, 0, 0, 1], lying])
    sim = Simulation(bodies, start, 240.0)
    rates, travel, contacts = [], [], 0
    for _ in range(int(5.0 * 240)):
        contacts += sim.step().report.contacts.count
        rates.append(float(np.linalg.norm(sim.state.angular[1])))
        travel.append(float(np.abs(sim.state.position[1, :2] - start.position[1, :2]).max()))
    spin, travel = max(rates), max(travel)
    print(f'after 5 s: largest roll rate {spin:.2e} rad/s, horizontal travel '
          f'{travel * 1000:.4f} mm, {contacts / len(rates):.1f} contacts per step')
    assert contacts >= len(rates), 'the cylinder lost its contact'
    assert spin < 1e-3
    assert travel < 1e-4


def test_a_flat_landing_on_a_long_box_gets_its_four_point_impact_manifold():
    """coal's GJK/EPA fail on some just-touching poses (depth -DBL_MAX, a wrong normal).

    A 20 cm box landing flat on a 40 m long box whose centre is 0.5 m away: the
    bisection used to end on such a pose, and the impact came out as one point at the
    box's centre or four points in one place (the box then tipped over on a flat
    landing). Expected: the four corners of the bottom face, normal +z, at the time the
    face reaches the top (0.0036 m of a 0.0041 m step).
    """
    from collres_ros.core.detection import Detection
    from collres_ros.core.types import BodyStates
    specs = [BodySpec('belt', 'box', (40.0, 2.0, 0.2), static=True),
             BodySpec('box', 'box', (0.2, 0.2, 0.2))]
    detection = Detection(specs, SolverSettings())
    for belt_x in ((0.5, 0.5), (0.0, 0.001)):
        previous, current = BodyStates.zeros(2), BodyStates.zeros(2)
        previous.position[:] = [[belt_x[0], 0.0, -0.1], [0.0, 0.0, 0.1036]]
        current.position[:] = [[belt_x[1], 0.0, -0.1], [0.0, 0.0, 0.0995]]
        previous.linear[1], current.linear[1] = [0.0, 0.0, -0.96], [0.0, 0.0, -0.98]
        detection.reset()
        contacts = detection.detect(previous, current)
        corners = sorted(map(tuple, np.round(contacts.point[:, :2], 6)))
        print(belt_x, contacts.kind, contacts.toi, corners)
        assert corners == [(-0.1, -0.1), (-0.1, 0.1), (0.1, -0.1), (0.1, 0.1)]
        assert np.allclose(contacts.normal, [0.0, 0.0, 1.0], atol=1e-6)
        assert np.allclose(contacts.toi, 0.0036 / 0.0041, atol=1e-3)
        assert np.allclose(contacts.point[:, 2], 0.0, atol=1e-5)


@pytest.mark.parametrize('rate,speed,angle', [(30.0, 1.5, 85.0), (60.0, 3.0, 85.0)])
def test_a_ball_driven_into_a_corner_of_overlapping_walls_is_only_stopped(
        rate: float, speed: float, angle: float) -> None:
    """Two static walls 20 mm thick overlap in an L (each 10 mm into the other, as bins are
    built); a 1 kg ball of 5 mm (e 0.5) is driven into the corner, its input velocity
    restored every step (as a source that keeps pushing it). The end face of one wall,
    buried in the other, gives no row: the walls' rows only stop the ball, never more than
    (1 + e) m (|v_x| + |v_y|) in a step, and it never leaves faster than driven. (Was: that
    face's row pushed the ball into the other wall, the two rows against each other, 11.9
    and 26.3 N s a step.)"""
    length, thick, into, r = 0.5, 0.02, 0.01, 0.005
    walls = [box('wa', (thick, length + into, 0.2), 1.0, static=True),
             box('wb', (length + into, thick, 0.2), 1.0, static=True)]
    ball = sphere('ball', r, 1.0, e=0.5)
    d = np.array([math.cos(math.radians(angle)), math.sin(math.radians(angle)), 0.0])
    start = np.array([-r, -r, 0.0]) - 1.5 * d * speed / rate
    zero = [0.0] * 3
    initial = states([[thick / 2, (into - length) / 2, 0.0], [(into - length) / 2, thick / 2, 0.0],
                      start], [zero, zero, speed * d])
    sim = Simulation(walls + [ball], initial, rate, gravity=np.zeros(3))
    worst, fastest = 0.0, 0.0
    for _ in range(int(0.3 * rate)):
        current = sim.state.copy()
        current.linear[2] = speed * d
        current.position[2] = sim.state.position[2] + speed * d / rate
        result = sim.world.step(sim.state, current, 1.0 / rate)
        sim.state = result.states
        worst = max(worst, float(np.sum(result.report.normal_impulse)))
        fastest = max(fastest, float(np.linalg.norm(sim.state.linear[2])))
    print('largest impulse of a step', worst, 'N s; fastest', fastest, 'm/s')
    assert worst <= 1.5 * speed * float(np.sum(np.abs(d))) * 1.01
    assert fastest <= speed * 1.01


WALL = 0.02   # m, thick


def touching_ball_driven_in(walls, start, velocity, rate=30.0):
    """A 1 kg ball of 5 mm (e 1) touching a wall (0.05 mm into its face), driven into it at
    ``velocity``, no gravity: its state after each of three steps and the energy ratio."""
    bodies = [box(name, size, 1.0, e=1.0, static=True) for name, size, _ in walls]
    bodies.append(sphere('ball', 0.005, 1.0, e=1.0))
    zero = [0.0] * 3
    sim = Simulation(bodies, states([at for _, _, at in walls] + [start],
                                    [zero] * len(walls) + [velocity]), rate,
                     gravity=np.zeros(3))
    energy = sim.energy()
    for _ in range(3):
        sim.step()
    return sim.state.position[-1], sim.state.linear[-1], sim.energy() / energy


def test_a_ball_driven_through_more_than_half_a_wall_bounces_off_the_face_it_touches() -> None:
    """A ball touching a 20 mm wall, driven into it at 1.2 m/s at 30 Hz (40 mm a step: its
    end pose is past the wall's middle, its contact there faces out of the far face), as a
    ball struck into a wall within a step waits there for the next step: it bounces off the
    face it touched, its energy kept. (Was: the far face's contact, then the hold-back,
    stopped it dead: all its energy lost.)"""
    r = 0.005
    position, velocity, energy = touching_ball_driven_in(
        [('wall', (0.2, WALL, 0.2), [0.0, -WALL / 2, 0.0])], [0.0, r - 5e-5, 0.0],
        [0.3, -1.2, 0.0])
    print('position', position, 'velocity', velocity, 'energy ratio', energy)
    assert np.allclose(velocity, [0.3, 1.2, 0.0], atol=1e-6)
    assert abs(energy - 1.0) < 1e-6
    assert position[1] > r


def test_a_ball_driven_through_a_corner_of_two_walls_ending_together_bounces_off_both() -> None:
    """A floor and a side wall (20 mm thick) meet in an L whose outer ends are flush (as a
    bin's walls); a ball touching the floor 20 mm from the side wall is driven at
    (2.4, -1.5) m/s at 30 Hz: its end pose is out beyond both walls, where the side wall's
    end face is exposed. It bounces off the floor at once and off the side wall within the
    step, and stays in the corner's inside, its energy kept. (Was: the floor's contact
    was dropped as buried in the side wall, the end face's row as well: the ball left
    through the floor.)"""
    r, side = 0.005, 0.05
    position, velocity, energy = touching_ball_driven_in(
        [('floor', (side + WALL, WALL, 0.2), [(side + WALL) / 2 - WALL, -WALL / 2, 0.0]),
         ('side', (WALL, side + WALL, 0.2), [side + WALL / 2, (side + WALL) / 2 - WALL, 0.0])],
        [side - 0.02, r - 5e-5, 0.0], [2.4, -1.5, 0.0])
    print('position', position, 'velocity', velocity, 'energy ratio', energy)
    assert np.allclose(velocity, [-2.4, 1.5, 0.0], atol=1e-6)
    assert abs(energy - 1.0) < 1e-6
    assert position[1] > r and position[0] < side - r
