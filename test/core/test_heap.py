"""The heap law: spheres with rolling resistance poured onto a floor form a heap.

A pour of 100 spheres (r = 5 cm, 0.5 kg, e = 0.1, friction 0.8, rolling resistance and
torsional friction 0.3) released one every 0.1 s from 0.5 m above the same point of a
floor, at 120 Hz with collres_sim's integrator. With rolling resistance mu_r a ball holds on a
slope while tan(theta) <= mu_r (test_rolling.py); a heap stands at least that steep
(tan(15 deg) = 0.27 < 0.3). Without rolling resistance spheres roll apart: no heap.

And the heap rests: over its last second (2-3 s after the last release) the fastest sphere
is under 0.05 m/s (Box2D's sleep speed) in most steps. A heap has avalanches: one sphere
slipping at a given instant is not a heap that does not rest (the same pour of seed 3 shows
0.005-0.02 m/s for seconds with one 0.2 m/s slip between), so the law is on the median of
the last second, not on its last step.
"""

from __future__ import annotations

import numpy as np

from collres_ros.core.config import SolverSettings
from collres_ros.core.types import BodySpec, BodyStates
from collres_ros.core.world import World
from collres_ros.ros.integrator import euler_step

GRAVITY = np.array([0.0, 0.0, -9.81])

RADIUS, COUNT, EVERY, HZ = 0.05, 100, 0.1, 120.0


def pour(rolling: float) -> tuple[BodyStates, np.ndarray]:
    """The states 3 s after the last of COUNT spheres was released, and the fastest sphere's
    speed (m/s) at each step of the last second."""
    bodies = [BodySpec('floor', 'plane', (0.0, 0.0, 1.0, 0.0), static=True)]
    bodies += [BodySpec(f's{i}', 'sphere', (RADIUS,), mass=0.5, restitution=0.1,
                        static_friction=0.8, kinetic_friction=0.8,
                        rolling_resistance=rolling, torsional_friction=rolling)
               for i in range(COUNT)]
    state = BodyStates.zeros(COUNT + 1)
    state.position[1:] = [[10.0 + 0.2 * i, 10.0, 1.0] for i in range(COUNT)]  # parked apart
    state.orientation[:, 3] = 1.0
    world = World(bodies, SolverSettings(sleeping=False))
    rng = np.random.default_rng(3)
    dt, released = 1.0 / HZ, 0
    steps = int(round((COUNT * EVERY + 3.0) * HZ))
    fastest = []
    for k in range(steps):
        if released < COUNT and k * dt >= released * EVERY - 1e-9:
            state.position[1 + released] = [*rng.uniform(-0.01, 0.01, 2), 0.5]
            released += 1
        falling = world.dynamic.copy()
        falling[1 + released:] = False       # parked spheres wait without gravity
        state = world.step(state, euler_step(state, falling, GRAVITY, dt), dt).states
        if k >= steps - int(HZ):
            fastest.append(np.linalg.norm(state.linear[1:], axis=1).max())
    return state, np.array(fastest)


def test_a_pour_of_spheres_with_rolling_resistance_forms_a_heap_steeper_than_15_deg():
    state, fastest = pour(rolling=0.3)
    spheres = state.position[1:]
    height = spheres[:, 2].max() + RADIUS
    radius = np.percentile(np.hypot(spheres[:, 0], spheres[:, 1]), 90) + RADIUS
    angle = np.degrees(np.arctan2(height, radius))
    print(f'heap: {height:.3f} m high, 90 % of the spheres within {radius:.3f} m: '
          f'{angle:.1f} deg; fastest over the last second: median {np.median(fastest):.4f}, '
          f'max {fastest.max():.4f} m/s')
    assert angle > 15.0
    assert np.median(fastest) < 0.05      # it rests
