"""The velocity sweeps on two threads give the same bits as on one.

A large solve is split in two halves that share no movable body, then the manifolds that
join them (``SOLVER_TUNING`` ``parallel_manifolds``); one thread solves them in that order,
two solve the halves at once (``threads``). The law: whatever the thread count, every
step's corrected states and impulses are the same bytes. Here a pile of cubes and spheres
falls into a bin and settles (impacts, stacking, friction, rolling resistance), split from
a low ``parallel_manifolds`` on so that every step with contacts is split.
"""

from __future__ import annotations

import numpy as np

from collres_ros.core.config import SolverSettings
from collres_ros.core.types import BodySpec, BodyStates
from collres_ros.core.world import World
from collres_ros.ros.integrator import euler_step

DT = 1.0 / 120.0
GRAVITY = np.array([0.0, 0.0, -9.81])
STEPS = 90


def pile(count: int = 48) -> tuple[list[BodySpec], BodyStates]:
    """A floor and four walls, then ``count`` cubes and spheres (0.1 m) on a jittered grid."""
    half = 0.25
    bodies = [BodySpec('floor', 'plane', (0.0, 0.0, 1.0, 0.0), static=True),
              BodySpec('wall_x0', 'plane', (1.0, 0.0, 0.0, -half), static=True),
              BodySpec('wall_x1', 'plane', (-1.0, 0.0, 0.0, -half), static=True),
              BodySpec('wall_y0', 'plane', (0.0, 1.0, 0.0, -half), static=True),
              BodySpec('wall_y1', 'plane', (0.0, -1.0, 0.0, -half), static=True)]
    rng = np.random.default_rng(3)
    positions = [np.zeros(3)] * len(bodies)
    for i in range(count):
        layer, cell = divmod(i, 16)
        row, col = divmod(cell, 4)
        if i % 2:
            bodies.append(BodySpec(f'box{i}', 'box', (0.1,) * 3, mass=1.0, restitution=0.2,
                                   static_friction=0.6, kinetic_friction=0.4,
                                   rolling_resistance=0.05))
        else:
            bodies.append(BodySpec(f'ball{i}', 'sphere', (0.05,), mass=0.5, restitution=0.2,
                                   static_friction=0.6, kinetic_friction=0.4,
                                   rolling_resistance=0.05, torsional_friction=0.05))
        positions.append(np.array([-0.18 + 0.12 * col, -0.18 + 0.12 * row, 0.06 + 0.12 * layer])
                         + rng.uniform(-0.01, 0.01, 3))
    state = BodyStates.zeros(len(bodies))
    state.position[:] = positions
    angles = rng.uniform(-0.3, 0.3, (len(bodies), 3))
    angles[:5] = 0.0
    size = np.linalg.norm(angles, axis=1, keepdims=True)
    axis = angles / np.maximum(size, 1e-12)
    state.orientation[:] = np.concatenate((axis * np.sin(size / 2), np.cos(size / 2)), 1)
    return bodies, state


def world(bodies: list[BodySpec], threads: int) -> World:
    w = World(bodies, SolverSettings(sleeping=False))
    w._params.threads = threads
    w._params.parallel_manifolds = 8
    return w


def test_two_threads_give_the_bytes_of_one():
    bodies, start = pile()
    worlds = [world(bodies, 1), world(bodies, 2), world(bodies, 2)]
    states = [start.copy() for _ in worlds]
    split_steps = 0
    for _ in range(STEPS):
        answers = []
        for k, w in enumerate(worlds):
            result = w.step(states[k], euler_step(states[k], w.dynamic, GRAVITY, DT), DT)
            states[k] = result.states
            answers.append(b''.join(np.ascontiguousarray(a, '<f8').tobytes() for a in (
                result.states.position, result.states.orientation, result.states.linear,
                result.states.angular, result.report.normal_impulse,
                result.report.friction_impulse)))
        assert answers[1] == answers[0] and answers[2] == answers[0]
        first, second, count = worlds[1]._solver.split
        split_steps += 0 < first < second <= count
    # the pile was in contact and split in two non-empty halves nearly all the time
    assert split_steps > STEPS // 2
    assert np.isfinite(states[0].position).all()
    assert states[0].position[5:, 2].max() < 0.6          # it fell and piled up
