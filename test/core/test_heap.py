"""The heap law: spheres with rolling resistance poured onto a floor form a heap.

A pour of 100 spheres (r = 5 cm, 0.5 kg, e = 0.1, friction 0.8, rolling resistance and
torsional friction 0.3) released one every 0.1 s from 0.5 m above the same point of a
floor, at 120 Hz with collres_sim's integrator. With rolling resistance mu_r a ball holds on a
slope while tan(theta) <= mu_r (test_rolling.py); a heap stands at least that steep
(tan(15 deg) = 0.27 < 0.3). Without rolling resistance spheres roll apart: no heap.

And the heap comes to rest: the fastest sphere's median speed over one second falls under
0.05 m/s (Box2D's sleep speed) within REST_BY s of the last release; its angle is measured
then. A heap has avalanches (single 0.1-0.5 m/s slips for seconds), so when it rests is a draw
of the pour: over pour seeds 1-30, 3 s after the last release the median of the last second
was still >= 0.05 m/s for 10 seeds at `row_bound` 2, 5 at 1 and 9 at 0.5, yet every pour
rested within 6.1 s of its last release (median 2.4-2.6 s), at 14.7-35.3 deg at 2 (one heap
under 15), 16.5-29.1 at 1, 17.0-38.8 at 0.5. Without rolling resistance the spheres roll apart
(0.6 deg) and never rest.
"""

from __future__ import annotations

import numpy as np
import pytest

from collres_ros.core.config import SolverSettings
from collres_ros.core.types import BodySpec, BodyStates
from collres_ros.core.world import World
from collres_ros.ros.integrator import euler_step

GRAVITY = np.array([0.0, 0.0, -9.81])

RADIUS, COUNT, EVERY, HZ = 0.05, 100, 0.1, 120.0
REST, REST_BY = 0.05, 8.0    # m/s (Box2D's sleep speed), s after the last release


def pour(rolling: float, seed: int, rate: float = HZ) -> tuple[BodyStates, float | None]:
    """The states when the heap of COUNT spheres poured at ``rate`` (Hz) first rests (the
    fastest sphere's median speed over the second before under REST) and that time in s
    after the last release; the states REST_BY s after the last release and None if it does
    not rest by then."""
    bodies = [BodySpec('floor', 'plane', (0.0, 0.0, 1.0, 0.0), static=True)]
    bodies += [BodySpec(f's{i}', 'sphere', (RADIUS,), mass=0.5, restitution=0.1,
                        static_friction=0.8, kinetic_friction=0.8,
                        rolling_resistance=rolling, torsional_friction=rolling)
               for i in range(COUNT)]
    state = BodyStates.zeros(COUNT + 1)
    state.position[1:] = [[10.0 + 0.2 * i, 10.0, 1.0] for i in range(COUNT)]  # parked apart
    state.orientation[:, 3] = 1.0
    world = World(bodies, SolverSettings(sleeping=False))
    rng = np.random.default_rng(seed)
    dt, released = 1.0 / rate, 0
    last = int(round(COUNT * EVERY * rate))          # the step after the last release
    fastest = []
    for k in range(last + int(round(REST_BY * rate))):
        if released < COUNT and k * dt >= released * EVERY - 1e-9:
            state.position[1 + released] = [*rng.uniform(-0.01, 0.01, 2), 0.5]
            released += 1
        falling = world.dynamic.copy()
        falling[1 + released:] = False       # parked spheres wait without gravity
        state = world.step(state, euler_step(state, falling, GRAVITY, dt), dt).states
        if k >= last:
            fastest.append(np.linalg.norm(state.linear[1:], axis=1).max())
            if len(fastest) >= rate and np.median(fastest[-int(rate):]) < REST:
                return state, len(fastest) / rate
    return state, None


def angle_of_repose(state: BodyStates) -> tuple[float, float, float]:
    """(angle in deg, height in m, radius in m) of a heap of spheres: its top over the radius
    within which 90 % of the spheres lie."""
    spheres = state.position[1:]
    height = spheres[:, 2].max() + RADIUS
    radius = np.percentile(np.hypot(spheres[:, 0], spheres[:, 1]), 90) + RADIUS
    return float(np.degrees(np.arctan2(height, radius))), float(height), float(radius)


@pytest.mark.parametrize('seed', [1, 2, 3])
def test_a_pour_of_spheres_with_rolling_resistance_forms_a_heap_steeper_than_15_deg(seed):
    state, rested = pour(rolling=0.3, seed=seed)
    angle, height, radius = angle_of_repose(state)
    print(f'heap: {height:.3f} m high, 90 % of the spheres within {radius:.3f} m: '
          f'{angle:.1f} deg; at rest {rested} s after the last release')
    assert angle > 15.0
    assert rested is not None             # it rests
