"""``body_markers``: every body's shape at its corrected pose, a constant number of markers.

The markers of a scene are planned once (``BodyMarkers``), then each message
is a few numpy operations over the step's (N, 7) poses, whatever the number
of bodies:

* spheres: one ``SPHERE_LIST`` per (diameter, static or not) group of
  spheres (namespace ``body_spheres``), a point per sphere at its centre;
* every other shape as triangles (``TRIANGLE_LIST``, namespace
  ``body_meshes``, id 0 for dynamic bodies and 1 for static ones): boxes (12
  triangles), capsules, cylinders and cones (lathed, ``SEGMENTS`` around),
  convex bodies (their convex hull, from coal) and planes (a square
  ``2 * PLANE_HALF_SIZE`` wide around the point of the plane nearest the body
  origin); the body-frame vertices are transformed by each pose at once.

One colour per marker (dynamic: ``DYNAMIC_COLOUR``, static and kinematic:
``STATIC_COLOUR``) rather than per point keeps the message 40 % smaller.
Static bodies are included (their published pose, else their params pose).
All positions in the world frame, in m; marker poses are identity.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from collres_ros.core.rotation import to_matrix
from collres_ros.core.shapes import (convex_hull, convex_points, piece_spec, plane_normal_offset,
                                     shape_offset)
from collres_ros.core.types import COMPOUND, TRIANGLE_MESH, BodySpec
from collres_ros.ros.codec import MarkerSpec

SPHERE_LIST, TRIANGLE_LIST = 7, 11     # visualization_msgs/Marker constants
ADD = 0
SPHERES_NS, MESHES_NS = 'body_spheres', 'body_meshes'
DYNAMIC_COLOUR = (0.55, 0.7, 0.9, 1.0)   # light blue
STATIC_COLOUR = (0.6, 0.6, 0.6, 1.0)     # grey
SEGMENTS = 16                            # around the axis of capsules, cylinders, cones
CAP_RINGS = 4                            # per capsule hemisphere
PLANE_HALF_SIZE = 10.0                   # m


def _lathe(profile: Sequence[tuple[float, float]]) -> np.ndarray:
    """Triangles (T * 3, 3) of a profile [(radius, z), ...] turned about the z axis."""
    angle = 2.0 * np.pi * np.arange(SEGMENTS) / SEGMENTS
    ring = np.stack([np.cos(angle), np.sin(angle), np.zeros(SEGMENTS)], 1)
    rings = np.array([ring * r + (0.0, 0.0, z) for r, z in profile])   # (R, S, 3)
    k = np.arange(SEGMENTS)
    k1 = (k + 1) % SEGMENTS
    low, high = rings[:-1], rings[1:]
    quads = [low[:, k], low[:, k1], high[:, k1], low[:, k], high[:, k1], high[:, k]]
    # (R-1, S, 6, 3): two triangles per quad; degenerate ones at r = 0 are harmless
    return np.stack(quads, 2).reshape(-1, 3)


def _box(size: Sequence[float]) -> np.ndarray:
    half = np.asarray(size, float) / 2.0
    corner = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)],
                      float) * half
    faces = [(0, 1, 3), (0, 3, 2), (4, 6, 7), (4, 7, 5), (0, 4, 5), (0, 5, 1),
             (2, 3, 7), (2, 7, 6), (0, 2, 6), (0, 6, 4), (1, 5, 7), (1, 7, 3)]
    return corner[np.array(faces).reshape(-1)]


def _plane(spec: BodySpec) -> np.ndarray:
    normal, offset = plane_normal_offset(spec)
    helper = np.eye(3)[int(np.argmin(np.abs(normal)))]
    u = np.cross(normal, helper)
    u /= np.linalg.norm(u)
    v = np.cross(normal, u)
    c = offset * normal
    a, b = PLANE_HALF_SIZE * u, PLANE_HALF_SIZE * v
    return np.array([c - a - b, c + a - b, c + a + b, c - a - b, c + a + b, c - a + b])


def _convex(spec: BodySpec) -> np.ndarray:
    hull = convex_hull(convex_points(spec))
    points = np.asarray(hull.points(), float).reshape(-1, 3)
    corners = [[int(t[j]) for j in range(3)]
               for t in (hull.polygons(i) for i in range(hull.num_polygons))]
    return points[np.array(corners, np.int64).reshape(-1)]


def _compound(spec: BodySpec) -> np.ndarray:
    """Each piece's triangles (a sphere piece as a lathe of its profile) at its pose."""
    placed = []
    for piece in spec.pieces:
        alone = piece_spec(spec, piece)
        corners = triangles(alone) if piece.shape != 'sphere' else _lathe(
            [(float(piece.size[0]) * np.sin(t), -float(piece.size[0]) * np.cos(t))
             for t in np.linspace(0.0, np.pi, CAP_RINGS * 2 + 1)])
        rotation = to_matrix(np.asarray(piece.orientation, float))
        placed.append(corners @ rotation.T + np.asarray(piece.position, float))
    return np.concatenate(placed)


def triangles(spec: BodySpec) -> np.ndarray:
    """Triangle vertices (T * 3, 3) m, body frame, of a non-sphere body's shape."""
    if spec.shape == COMPOUND:
        return _compound(spec)
    if spec.shape == TRIANGLE_MESH:
        return np.asarray(spec.points, float).reshape(-1, 3)
    size = [float(s) for s in spec.size]
    if spec.shape == 'box':
        return _box(size)
    if spec.shape == 'plane':
        return _plane(spec)
    if spec.shape == 'convex':
        return _convex(spec)
    radius, length = size[0], size[1]
    half = length / 2.0
    if spec.shape == 'cylinder':
        profile = [(0.0, -half), (radius, -half), (radius, half), (0.0, half)]
    elif spec.shape == 'cone':
        profile = [(0.0, -half), (radius, -half), (0.0, half)]
    elif spec.shape == 'capsule':
        a = np.linspace(-np.pi / 2, 0.0, CAP_RINGS + 1)
        profile = [(radius * np.cos(t), -half + radius * np.sin(t)) for t in a] + \
            [(radius * np.cos(t), half + radius * np.sin(t)) for t in -a[::-1]]
    else:
        raise ValueError(f'{spec.name}: no marker for shape {spec.shape!r}')
    return _lathe(profile) + shape_offset(spec)


class BodyMarkers:
    """The body markers of one scene (``bodies`` in scene order, as the poses are)."""

    def __init__(self, bodies: Sequence[BodySpec]) -> None:
        self.spheres: list[tuple[float, bool, np.ndarray]] = []   # (diameter, static, index)
        groups: dict[tuple[float, bool], list[int]] = {}
        local: dict[bool, list[np.ndarray]] = {False: [], True: []}
        owner: dict[bool, list[np.ndarray]] = {False: [], True: []}
        for i, body in enumerate(bodies):
            if body.shape == 'sphere':
                groups.setdefault((2.0 * float(body.size[0]), body.static), []).append(i)
                continue
            vertices = triangles(body)
            local[body.static].append(vertices)
            owner[body.static].append(np.full(len(vertices), i, np.int64))
        self.spheres = [(d, static, np.array(index, np.int64))
                        for (d, static), index in sorted(groups.items())]
        # static flag -> (body-frame vertices (V, 3), owner body of each vertex (V,))
        self.meshes = {static: (np.concatenate(local[static]), np.concatenate(owner[static]))
                       for static in (False, True) if local[static]}

    def specs(self, poses: np.ndarray, lifetime_ns: int) -> list[MarkerSpec]:
        """The markers at ``poses`` (N, 7): position m, orientation x, y, z, w (world)."""
        poses = np.asarray(poses, float)
        out = []
        for k, (diameter, static, index) in enumerate(self.spheres):
            out.append(MarkerSpec(action=ADD, type=SPHERE_LIST, ns=SPHERES_NS, id=k,
                                  scale=(diameter,) * 3, lifetime_ns=lifetime_ns,
                                  color=STATIC_COLOUR if static else DYNAMIC_COLOUR,
                                  points=poses[index, 0:3]))
        if self.meshes:
            rotation = to_matrix(poses[:, 3:7])                         # (N, 3, 3) body -> world
        for static, (vertices, owner) in self.meshes.items():
            world = np.einsum('vij,vj->vi', rotation[owner], vertices) + poses[owner, 0:3]
            out.append(MarkerSpec(action=ADD, type=TRIANGLE_LIST, ns=MESHES_NS, id=int(static),
                                  scale=(1.0, 1.0, 1.0), lifetime_ns=lifetime_ns,
                                  color=STATIC_COLOUR if static else DYNAMIC_COLOUR,
                                  points=world))
        return out
