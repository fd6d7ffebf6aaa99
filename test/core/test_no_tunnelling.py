"""No tunnelling at low rates: a body that hits the floor on one corner stays on it.

At 30 Hz and below, a box falling at 1.6 m/s onto a 0.1 m floor box hits it on one corner.
The impact stops that corner; the rest of the step (rewound to the time of impact, then
advanced) turns the body about it, so its other corners reach the floor within the same
step. Detection hands the solver, with the impact's manifold, a second manifold of the
same pair at the time of impact: the body's other corners above the floor's plane
(speculative rows, gap = their height), which the solver keeps from closing by more than
that. A persistent contact deeper than EPA is trusted takes its normal from the previous,
shallow state (EPA's normal flips past the floor's mid-plane), and a pair near at both
ends that moved farther than both gaps is swept for a hit it passed through.

A body that tumbles into the floor (a thin plate turning 0.8 rad a step at 10 Hz) takes
its corners along arcs that straight-line rows do not follow, and its corners without rows
are not held at all: after the solve, a body whose motion from its previous pose to its
answer goes deeper into a fixed shape than it was (by more than the slop) is held at the
latest pose of that motion before, at rest (``Detection.hold_back``, as Box2D v3's
continuous step).

Laws: whatever corner it lands on, at 30 Hz and at 10 Hz, the body's lowest point never
goes 2 cm below the floor's top (the floor is 10 cm thick) and ends within 3 mm of it;
a settled pile driven at 30 Hz the way ``collres_sim`` handles lost answers (it integrates
its own state again) stays in its bin on the floor; 30 random tumbling drops of a 1 m plate
and of a 0.4 m stick at 10 Hz and 30 Hz (fixed seeds; ``bench/tunnelling.py`` runs more)
never go more than 3 mm into a 0.1 m floor box.
"""

from __future__ import annotations

import numpy as np
import pytest

from collres_ros.core.pipeline import Resolver
from collres_ros.core.rotation import from_rotation_vector, multiply, to_matrix
from collres_ros.core.types import BodyInput, BodySpec, BodyStates
from collres_ros.ros.integrator import euler_step
from collres_ros.ros.params import load_scene
from integrator import Simulation

from pathlib import Path

PILE = Path(__file__).resolve().parents[2] / 'config' / 'scenes' / 'pile.yaml'


def lowest_corner(sim: Simulation, points: np.ndarray, seconds: float) -> np.ndarray:
    """Height (m) of body 1's lowest corner (``points``: its corners, body frame) after each
    of ``seconds`` of steps."""
    lowest = []
    for _ in range(int(round(seconds / sim.dt))):
        sim.step()
        rotation = to_matrix(sim.state.orientation[1:2])[0]
        lowest.append((sim.state.position[1] + points @ rotation.T)[:, 2].min())
    return np.array(lowest)


def corners(size) -> np.ndarray:
    half = np.asarray(size, float) / 2
    return np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]) * half


def corner_down(corner: np.ndarray) -> np.ndarray:
    """An orientation (x, y, z, w) with ``corner`` (body frame) straight down, then tilted
    a little (0.2 rad about x, 0.1 about y) so that it alone hits first."""
    c = corner / np.linalg.norm(corner)
    down = np.array([0.0, 0.0, -1.0])
    axis = np.cross(c, down)
    q = from_rotation_vector(axis / np.linalg.norm(axis) * np.arccos(np.clip(c @ down, -1, 1)))
    return multiply(from_rotation_vector(np.array([0.2, 0.1, 0.0])), q)


def lowest_points(rate: float, size, corner: np.ndarray, seconds: float = 3.0) -> np.ndarray:
    """The box's lowest point (m, z) after every step of a fall at 1.6 m/s from 2 cm onto
    a 2 m x 2 m x 0.1 m floor box (top at z = 0), landing on ``corner``."""
    bodies = [BodySpec('floor', 'box', (2.0, 2.0, 0.1), static=True, restitution=0.2),
              BodySpec('box', 'box', tuple(size), mass=1.0, restitution=0.2,
                       static_friction=0.5, kinetic_friction=0.4)]
    start = BodyStates.zeros(2)
    start.position[0] = [0.0, 0.0, -0.05]
    q = corner_down(corner)
    points = corners(size)
    start.orientation[1] = q
    start.position[1] = [0.0, 0.0, 0.02 - (points @ to_matrix(q[None])[0].T)[:, 2].min()]
    start.linear[1] = [0.0, 0.0, -1.6]
    return lowest_corner(Simulation(bodies, start, rate), points, seconds)


@pytest.mark.parametrize('rate', [30.0, 10.0])
@pytest.mark.parametrize('size', [(0.2, 0.2, 0.2), (0.4, 0.2, 0.1)])
def test_a_box_landing_on_any_corner_stays_on_the_floor(rate, size):
    worst, last = [], []
    for corner in corners(size):
        lowest = lowest_points(rate, size, corner)
        worst.append(lowest.min())
        last.append(lowest[-1])
    print(f'{rate} Hz {size}: deepest {min(worst) * 1e3:.1f} mm, '
          f'at the end {min(last) * 1e3:.2f} mm')
    assert min(worst) > -0.02, 'a corner went more than 2 cm into the floor'
    assert min(last) > -0.003, 'the box ended more than 3 mm into the floor'


def test_a_settled_pile_at_30_hz_with_lost_answers_stays_in_its_bin():
    """One answer in ten lost after the pile settles (4 s): the sim keeps integrating its
    own state, so the next input has sunk by two steps of gravity."""
    scene = load_scene(PILE)
    resolver = Resolver.for_scene(scene)
    states = scene.initial.copy()
    dynamic = np.array([not b.static for b in scene.bodies])
    gravity = np.array(scene.sim.gravity)
    dt_ns = int(round(1e9 / 30.0))
    rng = np.random.default_rng(1)
    lowest, fastest = np.inf, 0.0
    for k in range(int(9.0 * 30)):
        states = euler_step(states, dynamic, gravity, dt_ns * 1e-9)
        inputs = [BodyInput(b.name, tuple(states.position[i]), tuple(states.orientation[i]),
                            tuple(states.linear[i]), tuple(states.angular[i]), 'world', 'world')
                  for i, b in enumerate(scene.bodies) if dynamic[i]]
        out = resolver.resolve(10**9 + k * dt_ns, inputs)
        settled = k * dt_ns > 4e9
        if settled and rng.random() < 0.1:
            continue                                   # the answer is lost
        for name in ('position', 'orientation', 'linear', 'angular'):
            getattr(states, name)[out.index] = getattr(out.states, name)
        if settled:
            lowest = min(lowest, states.position[dynamic, 2].min())
            fastest = max(fastest, np.linalg.norm(states.linear[dynamic], axis=1).max())
    print(f'lowest centre {lowest * 1e3:.1f} mm, fastest {fastest:.2f} m/s')
    inside = np.abs(states.position[dynamic, :2]).max()
    assert lowest > -0.02 and fastest < 2.0 and inside < 0.55


THIN = {'plate': (1.0, 1.0, 0.1), 'stick': (0.4, 0.1, 0.05)}   # m, the tumbling bodies
FLOOR = 0.1   # m, the floor box's thickness (top at z = 0)


def tumbling_drop(size, rate: float, seed: int, seconds: float = 3.0) -> np.ndarray:
    """The lowest corner's height (m) after every step of a random drop of a 2 kg box of
    ``size`` onto a 4 m x 4 m floor box: from 0.3 to 1 m up, turned at random, spinning at
    up to 8 rad/s (0.8 rad a step at 10 Hz), sliding at up to 1 m/s."""
    rng = np.random.default_rng(seed)
    bodies = [BodySpec('floor', 'box', (4.0, 4.0, FLOOR), static=True, restitution=0.2,
                       static_friction=0.6, kinetic_friction=0.4),
              BodySpec('body', 'box', tuple(size), mass=2.0, restitution=0.2,
                       static_friction=0.6, kinetic_friction=0.4)]
    start = BodyStates.zeros(2)
    start.position[0] = [0.0, 0.0, -FLOOR / 2]
    axis = rng.normal(size=3)
    start.orientation[1] = from_rotation_vector(axis / np.linalg.norm(axis)
                                                * rng.uniform(0.0, np.pi))
    points = corners(size)
    low = (points @ to_matrix(start.orientation[1:2])[0].T)[:, 2].min()
    start.position[1] = [0.0, 0.0, rng.uniform(0.3, 1.0) - low]
    spin = rng.normal(size=3)
    start.angular[1] = spin / np.linalg.norm(spin) * rng.uniform(0.0, 8.0)
    start.linear[1, :2] = rng.uniform(-1.0, 1.0, 2) / np.sqrt(2)
    return lowest_corner(Simulation(bodies, start, rate), points, seconds)


@pytest.mark.parametrize('rate', [10.0, 30.0])
@pytest.mark.parametrize('body', sorted(THIN))
def test_tumbling_thin_bodies_never_pass_into_the_floor(body, rate):
    deepest = np.array([tumbling_drop(THIN[body], rate, seed).min() for seed in range(30)])
    print(f'{body} at {rate:g} Hz: deepest {-deepest.min() * 1e3:.2f} mm, '
          f'{(deepest < -FLOOR).sum()} of 30 below the floor')
    assert deepest.min() > -0.003, f'{(deepest < -0.003).sum()} of 30 drops went 3 mm in'
