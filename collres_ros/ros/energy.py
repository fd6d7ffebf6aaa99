"""Mechanical energy of bodies: the one definition used by the demo report, plots and tests.

Kinetic energy ``1/2 m v^2 + 1/2 w_b . I w_b`` (``w_b`` = R^T w, the angular
velocity in the body axes; ``I`` the principal inertia about the origin, the
centre of mass) plus the potential ``-m g . x`` (zero at the world origin).
Static bodies count 0. ROS-free: numpy and the core's shapes only.

A state published by collres_sim (or corrected by the node) carries the
semi-implicit Euler's mid-step velocity; the report and the plot evaluate the
energy at the stamps, with v + g dt/2 (``integrator.stamp_velocity``, used by
``analysis.energy``), so free flight is flat.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from collres_ros.core.rotation import to_matrix
from collres_ros.core.types import BodySpec


def body_inertia(spec: BodySpec) -> np.ndarray:
    """Principal inertia (3,) kg m^2 about the origin, body frame (solid shapes)."""
    if spec.inertia is not None:
        return np.asarray(spec.inertia, float)
    try:
        from collres_ros.core.shapes import mass_properties
        _, inv_inertia = mass_properties(spec)
        inv = np.diag(np.asarray(inv_inertia, float))
        return np.where(inv > 0, 1.0 / np.where(inv > 0, inv, 1.0), 0.0)
    except Exception:  # shapes not available: spheres and boxes by formula, else 0
        m, size = spec.mass, spec.size
        if spec.shape == 'sphere':
            return np.full(3, 0.4 * m * size[0] ** 2)
        if spec.shape == 'box':
            x, y, z = size
            return m / 12.0 * np.array([y * y + z * z, x * x + z * z, x * x + y * y])
        return np.zeros(3)


def kinetic_energy(orientation: np.ndarray, linear: np.ndarray, angular: np.ndarray,
                   specs: Sequence[BodySpec]) -> np.ndarray:
    """Kinetic energy per body, J, shape (..., N): arrays (..., N, 4|3) in the world frame."""
    mass = np.array([0.0 if s.static else s.mass for s in specs])
    inertia = np.array([np.zeros(3) if s.static else body_inertia(s) for s in specs])
    inertia = inertia.reshape(len(specs), 3)
    rot = to_matrix(orientation)                             # (..., N, 3, 3)
    w_body = np.einsum('...ji,...j->...i', rot, angular)     # R^T w
    return 0.5 * mass * np.sum(linear ** 2, axis=-1) \
        + 0.5 * np.sum(inertia * w_body ** 2, axis=-1)


def potential_energy(position: np.ndarray, specs: Sequence[BodySpec],
                     gravity: Sequence[float]) -> np.ndarray:
    """Potential energy per body, J, shape (..., N): -m g . x (static bodies 0)."""
    mass = np.array([0.0 if s.static else s.mass for s in specs])
    return -mass * np.einsum('...i,i->...', position, np.asarray(gravity, float))


def total_energy(position: np.ndarray, orientation: np.ndarray, linear: np.ndarray,
                 angular: np.ndarray, specs: Sequence[BodySpec],
                 gravity: Sequence[float]) -> np.ndarray:
    """Kinetic + potential energy summed over the N bodies, J, shape (...)."""
    return np.sum(kinetic_energy(orientation, linear, angular, specs)
                  + potential_energy(position, specs, gravity), axis=-1)
