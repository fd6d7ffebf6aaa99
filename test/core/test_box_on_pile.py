"""A box dropped on a settled pile comes to rest on it, not in it.

A pile of ``bench/pile.py`` (100 cubes and spheres in a bin) is dropped and settled at
30 Hz, its answers integrated (sleeping on), then a cube turned 0.4 rad about z falls onto
it from 0.3 m above its top at three places, and rests (4 s). At rest the cube is no
deeper in anything than the slop plus 0.1 mm (measured with coal's own signed distance
on the answered poses, not with the detector under test): the push-out leaves a resting
contact at the slop, and the 0.1 mm is the resting solve's residual under the cube's
weight (measured: 0.11-0.15 mm over three piles and three places). On 1c15e3e the cube
dropped on the middle of pile 3 came to rest 1.61 mm into a box of the pile: where their
faces crossed tilted, the manifold's reduction to four points dropped the deepest, and
the cube sank there unseen.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from collres_ros.core import rotation
from collres_ros.core.config import SolverSettings
from collres_ros.core.types import BodySpec, BodyStates
from collres_ros.core.world import World

from overlap import deepest_into  # noqa: I100

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / 'bench'))
from pile import SIZE, integrate, make_pile  # noqa: E402

RATE = 30.0
TOLERANCE = 1e-4   # m beyond the slop: the resting solve's residual (module docstring)


@pytest.fixture(scope='module')
def settled():
    bodies, state = make_pile(100, seed=3, kind='mixed')
    world = World(bodies, SolverSettings())
    for _ in range(int(4.0 * RATE)):
        state = world.step(state, integrate(state, world.dynamic, 1.0 / RATE),
                           1.0 / RATE).states
    return bodies, state


@pytest.mark.parametrize('place', [(0.0, 0.0), (0.05, -0.03), (-0.1, 0.07)])
def test_a_box_dropped_on_a_settled_pile_rests_on_it(settled, place) -> None:
    pile, rest = settled
    cube = BodySpec('dropped', 'box', (SIZE,) * 3, mass=1.0, restitution=0.2,
                    static_friction=0.6, kinetic_friction=0.4)
    bodies = pile + [cube]
    state = BodyStates.zeros(len(bodies))
    for name in ('position', 'orientation', 'linear', 'angular'):
        getattr(state, name)[:-1] = getattr(rest, name)
    top = rest.position[[not b.static for b in pile], 2].max()
    state.position[-1] = [*place, top + 0.3]
    state.orientation[-1] = rotation.from_rotation_vector(np.array([0.0, 0.0, 0.4]))
    world = World(bodies, SolverSettings())
    for _ in range(int(4.0 * RATE)):
        result = world.step(state, integrate(state, world.dynamic, 1.0 / RATE), 1.0 / RATE)
        state = result.states
    depth = deepest_into(bodies, state, len(bodies) - 1)
    print(f'dropped at {place}: at rest {depth * 1e3:.2f} mm deep, asleep '
          f'{bool(result.sleeping[-1])}')
    assert result.sleeping[-1]
    assert depth <= SolverSettings().linear_slop + TOLERANCE
