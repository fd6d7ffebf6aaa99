"""A pile of boxes (and spheres) in a bin of static planes, shared by the benchmarks.

Two kinds: ``mixed`` (alternating 0.1 m cubes and spheres) and ``cubes`` (cubes
only: face contacts of 4 points).

The pile is described by plain data (shapes, sizes, masses, poses) so the
peer engines (MuJoCo, PyBullet) can build exactly the same scene.
"""

from __future__ import annotations

import math

import numpy as np

from collres_ros.core.types import BodySpec, BodyStates

SIZE = 0.1        # m, box edge and sphere diameter
SPACING = 0.12    # m, grid pitch of the initial layout
GRAVITY = np.array([0.0, 0.0, -9.81])
PILES = ('mixed', 'cubes')


def bin_half_width(count: int) -> float:
    columns = max(2, math.ceil(math.sqrt(count / 8.0)))
    return 0.5 * columns * SPACING


def make_pile(count: int, seed: int = 1, kind: str = 'mixed'
              ) -> tuple[list[BodySpec], BodyStates]:
    """Five static planes (floor, four walls) then ``count`` bodies on a jittered grid."""
    if kind not in PILES:
        raise ValueError(f'unknown pile {kind!r}: {", ".join(PILES)}')
    rng = np.random.default_rng(seed)
    half = bin_half_width(count)
    columns = int(round(2 * half / SPACING))
    planes = [BodySpec('floor', 'plane', (0.0, 0.0, 1.0, 0.0), static=True),
              BodySpec('wall_x0', 'plane', (1.0, 0.0, 0.0, -half), static=True),
              BodySpec('wall_x1', 'plane', (-1.0, 0.0, 0.0, -half), static=True),
              BodySpec('wall_y0', 'plane', (0.0, 1.0, 0.0, -half), static=True),
              BodySpec('wall_y1', 'plane', (0.0, -1.0, 0.0, -half), static=True)]
    bodies = list(planes)
    positions = [np.zeros(3)] * len(planes)
    for i in range(count):
        layer, cell = divmod(i, columns * columns)
        row, col = divmod(cell, columns)
        if i % 2 or kind == 'cubes':
            bodies.append(BodySpec(f'box{i}', 'box', (SIZE,) * 3, mass=1.0, restitution=0.2,
                                   static_friction=0.6, kinetic_friction=0.4))
        else:
            bodies.append(BodySpec(f'ball{i}', 'sphere', (SIZE / 2,), mass=0.5,
                                   restitution=0.2, static_friction=0.6,
                                   kinetic_friction=0.4))
        jitter = rng.uniform(-0.005, 0.005, 3)
        positions.append(np.array([-half + SPACING * (col + 0.5), -half + SPACING * (row + 0.5),
                                   SIZE / 2 + 0.005 + SPACING * layer]) + jitter)
    state = BodyStates.zeros(len(bodies))
    state.position[:] = np.array(positions)
    angles = rng.uniform(-0.2, 0.2, (len(bodies), 3))
    angles[:len(planes)] = 0.0
    half_angle = np.linalg.norm(angles, axis=1, keepdims=True) / 2
    axis = angles / np.maximum(np.linalg.norm(angles, axis=1, keepdims=True), 1e-12)
    state.orientation[:] = np.concatenate((axis * np.sin(half_angle), np.cos(half_angle)), 1)
    return bodies, state


def integrate(state: BodyStates, dynamic: np.ndarray, dt: float) -> BodyStates:
    """Semi-implicit Euler with gravity: collres_sim's integrator."""
    from collres_ros.ros.integrator import euler_step
    return euler_step(state, dynamic, GRAVITY, dt)


def describe(bodies: list[BodySpec], state: BodyStates) -> dict:
    """Plain-data description for the peer engines (JSON-serialisable)."""
    return {'bodies': [{'shape': b.shape, 'size': list(b.size), 'static': b.static,
                        'mass': b.mass, 'mu': b.kinetic_friction, 'e': b.restitution}
                       for b in bodies],
            'position': state.position.tolist(), 'orientation': state.orientation.tolist(),
            'half_width': None}
