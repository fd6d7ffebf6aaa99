"""Long steps hold the floor: a step that spans several periods after dropped inputs.

A node that falls behind drops inputs, and the next step it takes spans k periods. The
simulator that drives it never got the answers of the dropped steps: it integrated its
own state under gravity, so the input of the long step is the last answer integrated for
k periods (``euler_step`` k times), stamped k periods after it. A resting body then
arrives g t^2 / 2 below where it rests (0.27 m after 7 periods at 30 Hz, through a 0.1 m
floor) with the speed g t, but it never left the floor: its previous pose (the last
answer) touches it. Such a contact holds from the start of the step, its approach then
is the previous state's (none for a resting body), and the step's gravity is carried by
the resting solve: no impact, no bounce.

Laws, for a resting box on a floor box, on a floor plane, and for a settled pile of boxes
and spheres on a floor box, at 30 Hz and 10 Hz, and k = 1..8 periods: every answer is at
or above the floor within the slop, no body leaves faster than it came, and no energy is
gained (beyond lifting every body by the slop, which the position pass may do); then a
closed loop at 30 Hz whose node drops inputs at random keeps the pile on its floor.
"""

from __future__ import annotations

import numpy as np
import pytest

from collres_ros.core.config import SolverSettings
from collres_ros.core.rotation import to_matrix
from collres_ros.core.types import BodySpec, BodyStates
from collres_ros.core.world import World
from collres_ros.ros.integrator import euler_step

GRAVITY = np.array([0.0, 0.0, -9.81])
SIZE = 0.1                       # m, cube edge and sphere diameter
SETTINGS = SolverSettings(sleeping=False)   # an awake pile: what the solver must hold
SLOP = SETTINGS.linear_slop
CORNERS = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)]) * SIZE / 2


def floor_box() -> BodySpec:
    """A 2 m x 2 m floor 0.1 m thick, its top at z = 0 (placed at z = -0.05)."""
    return BodySpec('floor', 'box', (2.0, 2.0, 0.1), static=True, restitution=0.2,
                    static_friction=0.6, kinetic_friction=0.4)


def cube(name: str) -> BodySpec:
    return BodySpec(name, 'box', (SIZE,) * 3, mass=1.0, restitution=0.2,
                    static_friction=0.6, kinetic_friction=0.4)


def ball(name: str) -> BodySpec:
    return BodySpec(name, 'sphere', (SIZE / 2,), mass=0.5, restitution=0.2,
                    static_friction=0.6, kinetic_friction=0.4)


def one_box(floor: str) -> tuple[list[BodySpec], BodyStates]:
    """A cube resting on a floor box or a floor plane (top at z = 0)."""
    ground = floor_box() if floor == 'box' else \
        BodySpec('floor', 'plane', (0.0, 0.0, 1.0, 0.0), static=True)
    state = BodyStates.zeros(2)
    state.position[0] = [0.0, 0.0, -0.05 if floor == 'box' else 0.0]
    state.position[1] = [0.0, 0.0, SIZE / 2 + 0.001]
    return [ground, cube('box')], state


def pile(count: int = 36, seed: int = 3) -> tuple[list[BodySpec], BodyStates]:
    """Cubes and spheres, alternating, dropped in two layers into a 0.6 m bin of four
    wall planes on a floor box."""
    rng = np.random.default_rng(seed)
    half = 0.3
    bodies = [floor_box()] + [BodySpec(f'wall{k}', 'plane', (*n, -half), static=True)
                              for k, n in enumerate([(1.0, 0.0, 0.0), (-1.0, 0.0, 0.0),
                                                     (0.0, 1.0, 0.0), (0.0, -1.0, 0.0)])]
    positions = [[0.0, 0.0, -0.05]] + [[0.0, 0.0, 0.0]] * 4
    for i in range(count):
        layer, cell = divmod(i, 25)
        row, col = divmod(cell, 5)
        bodies.append(cube(f'box{i}') if i % 2 else ball(f'ball{i}'))
        positions.append([-half + 0.12 * (col + 0.5), -half + 0.12 * (row + 0.5),
                          SIZE / 2 + 0.005 + 0.12 * layer] + rng.uniform(-0.005, 0.005, 3))
    state = BodyStates.zeros(len(bodies))
    state.position[:] = positions
    return bodies, state


def lowest(specs: list[BodySpec], state: BodyStates) -> np.ndarray:
    """(N,) m: the height of each dynamic body's lowest point (nan for static ones)."""
    out = np.full(len(specs), np.nan)
    for i, spec in enumerate(specs):
        if spec.static:
            continue
        if spec.shape == 'sphere':
            out[i] = state.position[i, 2] - spec.size[0]
        else:
            rotation = to_matrix(state.orientation[i:i + 1])[0]
            out[i] = (state.position[i] + CORNERS @ rotation.T)[:, 2].min()
    return out


def energy(world: World, state: BodyStates) -> np.ndarray:
    """(N,) J: each dynamic body's kinetic plus potential energy (0 for static ones)."""
    mass = np.where(world.dynamic, 1.0 / np.where(world.dynamic, world.inv_mass, 1.0), 0.0)
    rotation = to_matrix(state.orientation)
    inertia = rotation @ np.linalg.inv(np.where(world.dynamic[:, None, None],
                                                world.inv_inertia_body, np.eye(3))) \
        @ rotation.transpose(0, 2, 1)
    spin = 0.5 * np.einsum('ni,nij,nj->n', state.angular, inertia, state.angular)
    kinetic = 0.5 * mass * np.sum(state.linear ** 2, 1) + spin
    return np.where(world.dynamic, kinetic - mass * (state.position @ GRAVITY), 0.0)


def speed(specs: list[BodySpec], state: BodyStates) -> np.ndarray:
    """(N,) m/s: the speed of each body's farthest point, |v| + |w| r."""
    radius = np.array([np.linalg.norm(s.size) if s.shape == 'box' else s.size[0]
                       for s in specs]) * np.array([0.5 if s.shape == 'box' else 1.0
                                                    for s in specs])
    return np.linalg.norm(state.linear, axis=1) + np.linalg.norm(state.angular, axis=1) * radius


def allowed_gain(world: World) -> float:
    """J: the potential energy of lifting every dynamic body by the slop."""
    mass = 1.0 / world.inv_mass[world.dynamic]
    return float(mass.sum() * -GRAVITY[2] * SLOP)


def drive(world: World, state: BodyStates, dt: float, periods: int) -> BodyStates:
    """One step of ``periods`` periods of ``dt``: the input is ``state`` (the last answer)
    integrated under gravity that many times, as a simulator that got no answer does."""
    current = state
    for _ in range(periods):
        current = euler_step(current, world.dynamic, GRAVITY, dt)
    return world.step(state, current, periods * dt).states


def settled(specs: list[BodySpec], state: BodyStates, rate: float
            ) -> tuple[World, BodyStates]:
    """A world whose bodies were dropped and settled: 3 s at 60 Hz, then 2 s at ``rate``."""
    world = World(specs, SETTINGS)
    for hz, seconds in ((60.0, 3.0), (rate, 2.0)):
        for _ in range(int(seconds * hz)):
            state = drive(world, state, 1.0 / hz, 1)
    return world, state


def check_long_steps(specs: list[BodySpec], state: BodyStates, rate: float) -> None:
    """From rest, a step of k = 1..8 periods (then 1 s of steps of one period before the
    next k): the laws of the module docstring, after every step. Steps longer than
    ``max_dt`` are left out (at 10 Hz, 6 periods and more): the resolver starts those
    afresh, from the input alone."""
    world, state = settled(specs, state, rate)
    dynamic = world.dynamic
    assert lowest(specs, state)[dynamic].min() > -2 * SLOP, 'the pile did not settle'
    worst = []
    for k in range(1, 9):
        if k / rate > SETTINGS.max_dt:
            break
        for periods in [k] + [1] * int(rate):
            answer = drive(world, state, 1.0 / rate, periods)
            low = lowest(specs, answer)[dynamic].min()
            faster = (speed(specs, answer) - speed(specs, state))[dynamic].max()
            gain = float(energy(world, answer).sum() - energy(world, state).sum())
            worst.append((low, faster, gain))
            assert low > -2 * SLOP, \
                f'{rate} Hz, {k} periods: a body {-low * 1e3:.2f} mm into the floor'
            assert faster < 0.01, \
                f'{rate} Hz, {k} periods: a body left {faster:.3f} m/s faster than it came'
            assert gain < allowed_gain(world), f'{rate} Hz, {k} periods: {gain:.3g} J gained'
            state = answer
    low, faster, gain = np.array(worst).T
    print(f'{rate} Hz: deepest {-low.min() * 1e3:.3f} mm, faster by {faster.max():.2g} '
          f'm/s, gained {gain.max():.2g} J')


@pytest.mark.parametrize('rate', [30.0, 10.0])
@pytest.mark.parametrize('floor', ['box', 'plane'])
def test_a_resting_box_holds_the_floor_through_long_steps(rate, floor):
    check_long_steps(*one_box(floor), rate)


@pytest.mark.parametrize('rate', [30.0, 10.0])
def test_a_settled_pile_holds_the_floor_through_long_steps(rate):
    check_long_steps(*pile(), rate)


def test_a_pile_whose_node_drops_inputs_stays_on_its_floor():
    """30 Hz for 20 s after settling; the node takes each input with probability 0.6, so a
    step spans 1 to 8 periods (at most 8, then it takes one), and the simulator integrates
    its own state meanwhile: every answer on the floor, nothing launched, no energy
    gained."""
    specs, state = pile()
    rate = 30.0
    world, state = settled(specs, state, rate)
    dynamic = world.dynamic
    rng = np.random.default_rng(7)
    steps, deepest, fastest, gained = 0, 0.0, 0.0, -np.inf
    while steps < int(20 * rate):
        periods = 1
        while periods < 8 and rng.random() > 0.6:
            periods += 1
        answer = drive(world, state, 1.0 / rate, periods)
        steps += periods
        deepest = min(deepest, lowest(specs, answer)[dynamic].min())
        fastest = max(fastest, speed(specs, answer)[dynamic].max())
        gained = max(gained, float(energy(world, answer).sum() - energy(world, state).sum()))
        state = answer
    print(f'deepest {-deepest * 1e3:.3f} mm, fastest {fastest:.3f} m/s, '
          f'largest gain {gained:.2g} J')
    assert deepest > -2 * SLOP and fastest < 0.05 and gained < allowed_gain(world)
