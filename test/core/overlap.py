"""Test helper: how deep a body is in the others, by coal's own signed distance on the
given poses (a measure independent of the detector under test)."""

from __future__ import annotations

import coal
import numpy as np

from collres_ros.core import rotation
from collres_ros.core.types import BodySpec, BodyStates


def geometry(spec: BodySpec) -> coal.CollisionGeometry:
    """coal's shape of a plane, sphere or box spec."""
    if spec.shape == 'plane':
        return coal.Halfspace(np.array(spec.size[:3]), spec.size[3])
    if spec.shape == 'sphere':
        return coal.Sphere(spec.size[0])
    return coal.Box(*spec.size)


def deepest_into(bodies: list[BodySpec], state: BodyStates, index: int) -> float:
    """m, how deep body ``index`` is in the deepest other body (0 when it touches none)."""
    poses = [coal.Transform3s(r, p) for r, p in
             zip(rotation.to_matrix(state.orientation), state.position)]
    shapes = [geometry(spec) for spec in bodies]
    depth = 0.0
    for k in range(len(bodies)):
        if k == index:
            continue
        request, result = coal.CollisionRequest(), coal.CollisionResult()
        if coal.collide(shapes[index], poses[index], shapes[k], poses[k], request, result):
            depth = max(depth, -result.getContact(0).penetration_depth)
    return depth


def deepest_between(bodies: list[BodySpec], state: BodyStates,
                    movable: np.ndarray) -> float:
    """m, the deepest overlap of any two movable bodies (``movable``: (N,) mask; 0 when no
    two touch); pairs whose bounding spheres are apart are skipped."""
    poses = [coal.Transform3s(r, p) for r, p in
             zip(rotation.to_matrix(state.orientation), state.position)]
    shapes = [geometry(spec) for spec in bodies]
    index = np.flatnonzero(movable)
    radius = np.array([np.linalg.norm(np.asarray(bodies[i].size[:3], float)) / 2.0
                       if bodies[i].shape == 'box' else bodies[i].size[0] for i in index])
    centre = state.position[index]
    depth = 0.0
    for m, i in enumerate(index):
        near = np.linalg.norm(centre[m + 1:] - centre[m], axis=1) <= radius[m + 1:] + radius[m]
        for k in index[m + 1:][near]:
            request, result = coal.CollisionRequest(), coal.CollisionResult()
            if coal.collide(shapes[i], poses[i], shapes[k], poses[k], request, result):
                depth = max(depth, -result.getContact(0).penetration_depth)
    return depth
