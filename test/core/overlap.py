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
