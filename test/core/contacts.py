"""Test helpers: hand-made contacts and textbook mass properties (no coal needed)."""

from __future__ import annotations

import numpy as np

from collres_ros.core.config import SolverSettings
from collres_ros.core.types import (BodySpec, BodyStates, ContactKind, ContactSet,
                                    pair_manifolds)


class FixedContacts:
    """A detector that returns the same hand-made ContactSet every step."""

    def __init__(self, contacts: ContactSet, settings: SolverSettings | None = None) -> None:
        self.contacts = contacts
        self.settings = settings or SolverSettings()
        self.budget = (0, 0)
        self.thread_runs = (0, 0, 0, 0)   # one thread: no runs posted for two

    def detect(self, previous: BodyStates, current: BodyStates,
               active: np.ndarray | None = None, threads: int = 1,
               dt: float = 0.0) -> ContactSet:
        return self.contacts


def contact_set(a, b, point, normal, separation, toi=0.0, kind=ContactKind.IMPACT,
                feature=None) -> ContactSet:
    """A ContactSet from per-contact lists (normal normalised here)."""
    point = np.atleast_2d(np.asarray(point, float))
    normal = np.atleast_2d(np.asarray(normal, float))
    normal = normal / np.linalg.norm(normal, axis=1, keepdims=True)
    count = point.shape[0]
    normal = np.broadcast_to(normal, (count, 3)).copy()
    full = (lambda v, dtype: np.broadcast_to(np.asarray(v, dtype), (count,)).copy())
    body_a, body_b = full(a, np.int64), full(b, np.int64)
    return ContactSet(body_a, body_b, point, normal,
                      full(separation, float), full(toi, float), full(int(kind), np.int8),
                      np.arange(count, dtype=np.int64) if feature is None
                      else full(feature, np.int64), pair_manifolds(body_a, body_b))


def states(position, linear, angular=None, orientation=None) -> BodyStates:
    """BodyStates from per-body lists (identity orientation, no spin by default)."""
    position = np.asarray(position, float).reshape(-1, 3)
    count = position.shape[0]
    result = BodyStates.zeros(count)
    result.position[:] = position
    result.linear[:] = np.asarray(linear, float).reshape(-1, 3)
    if angular is not None:
        result.angular[:] = np.asarray(angular, float).reshape(-1, 3)
    if orientation is not None:
        result.orientation[:] = np.asarray(orientation, float).reshape(-1, 4)
    return result


def sphere(name: str, radius: float, mass: float, e: float = 0.5, mu_s: float = 0.0,
           mu_k: float = 0.0, static: bool = False) -> BodySpec:
    return BodySpec(name, 'sphere', (radius,), static=static, mass=mass, restitution=e,
                    static_friction=mu_s, kinetic_friction=mu_k)


def box(name: str, size, mass: float, e: float = 0.0, mu_s: float = 0.0,
        mu_k: float = 0.0, static: bool = False) -> BodySpec:
    return BodySpec(name, 'box', tuple(float(s) for s in size), static=static, mass=mass,
                    restitution=e, static_friction=mu_s, kinetic_friction=mu_k)


def box_inertia(size, mass: float) -> np.ndarray:
    """Principal moments (3,) kg m^2 of a solid box of full edges ``size``."""
    x, y, z = size
    return mass / 12.0 * np.array([y * y + z * z, x * x + z * z, x * x + y * y])


def sphere_inertia(radius: float, mass: float) -> np.ndarray:
    return np.full(3, 0.4 * mass * radius * radius)


def at_rest(positions, orientations=None) -> BodyStates:
    """States of bodies at ``positions`` (and ``orientations``, x y z w), zero twist."""
    out = BodyStates.zeros(len(positions))
    out.position[:] = positions
    if orientations is not None:
        out.orientation[:] = orientations
    return out
