"""Collision detection with coal: swept broad phase, narrow phase, time of impact.

The one place that talks to coal for queries; it returns our own ContactSet
(world frame, normals from body A to body B, A < B). One step:

1. Broad phase: every finite body gets an axis-aligned proxy box covering its
   bounding sphere swept from the previous to the current pose (plus the
   speculative margin) in a coal DynamicAABBTree manager; pairs of overlapping
   proxies are the candidates. Planes (half-spaces) are tested against every
   body's swept bounding sphere directly.
2. Narrow phase per candidate pair (DESIGN.md, "one step"): PERSISTENT when the
   pair touches (within the margin) at the previous state, IMPACT when it is
   apart before and overlapping now (bisection for the time of impact),
   TUNNELLED when apart at both ends but the sweep hits (conservative
   advancement with coal distance queries, then bisection).
3. Manifolds: coal contact patches (four points for a box face on a floor).
"""

from __future__ import annotations

from typing import Sequence

import coal
import numpy as np

from . import rotation
from .config import SolverSettings
from .shapes import bounding_radius, make_geometry
from .types import BodySpec, BodyStates, ContactKind, ContactSet

DEEP_FRACTION = 0.25  # EPA normal not trusted beyond this fraction of the smaller radius


class _Pose:
    """Lerp/slerp of one body between its previous (t=0) and current (t=1) pose."""

    __slots__ = ('p0', 'p1', 'q0', 'q1', 'tf')

    def __init__(self, p0: np.ndarray, p1: np.ndarray, q0: np.ndarray, q1: np.ndarray):
        self.p0, self.p1, self.q0, self.q1 = p0, p1, q0, q1
        self.tf = coal.Transform3s()

    def at(self, t: float) -> coal.Transform3s:
        self.tf.setTranslation(self.p0 + t * (self.p1 - self.p0))
        self.tf.setRotation(rotation.to_matrix(rotation.slerp(self.q0, self.q1, t)))
        return self.tf


class CollisionWorld:
    """coal geometries, broad phase and queries for a fixed list of bodies."""

    def __init__(self, bodies: Sequence[BodySpec], settings: SolverSettings) -> None:
        self.specs = list(bodies)
        self.settings = settings
        self._geoms = [make_geometry(s) for s in self.specs]
        self._radius = np.array([bounding_radius(s) for s in self.specs])
        self._static = np.array([s.static for s in self.specs], dtype=bool)
        plane = np.array([s.shape == 'plane' for s in self.specs], dtype=bool)
        self._planes = np.flatnonzero(plane)
        self._finite = np.flatnonzero(~plane)
        self._plane_normal = np.zeros((len(self.specs), 3))
        self._plane_offset = np.zeros(len(self.specs))
        for k in self._planes:
            g = self._geoms[k]
            self._plane_normal[k], self._plane_offset[k] = np.array(g.n), float(g.d)
        # broad phase: one proxy box per finite body, resized every step
        self._proxies = [coal.Box(1.0, 1.0, 1.0) for _ in self._finite]
        self._proxy_objects = [coal.CollisionObject(g, coal.Transform3s()) for g in self._proxies]
        self._proxy_body = {g.id(): int(i) for g, i in zip(self._proxies, self._finite)}
        self._manager = coal.DynamicAABBTreeCollisionManager()
        for obj in self._proxy_objects:
            self._manager.registerObject(obj)
        self._manager.setup()
        self._callback = coal.CollisionCallBackDefault()
        self._callback.data.request.num_max_contacts = 10 ** 8
        # reusable query objects
        self._tf_prev = [coal.Transform3s() for _ in self.specs]
        self._tf_curr = [coal.Transform3s() for _ in self.specs]
        self._req = coal.CollisionRequest()
        self._res = coal.CollisionResult()
        self._dreq = coal.DistanceRequest()
        self._dres = coal.DistanceResult()
        self._patch_req = coal.ContactPatchRequest()
        self._patch_res = coal.ContactPatchResult()

    # -- public ------------------------------------------------------------------------------

    def detect(self, previous: BodyStates, current: BodyStates,
               active: np.ndarray | None = None) -> ContactSet:
        """Contacts of the step previous -> current (see the module docstring).

        ``active`` False marks quarantined bodies: the caller holds them fixed
        (previous = current); they still collide but are never moved here.
        """
        self._set_transforms(previous, current)
        out = _ContactLists()
        for a, b in self._candidate_pairs(previous, current):
            self._narrow_phase(a, b, previous, current, out)
        return out.to_set()

    def candidate_pairs(self, previous: BodyStates, current: BodyStates) -> list[tuple[int, int]]:
        """Broad-phase pairs (a < b) whose swept bounds overlap (for tests and tools)."""
        return sorted(self._candidate_pairs(previous, current))

    # -- broad phase -------------------------------------------------------------------------

    def _set_transforms(self, previous: BodyStates, current: BodyStates) -> None:
        r_prev = rotation.to_matrix(previous.orientation)
        r_curr = rotation.to_matrix(current.orientation)
        for i in range(len(self.specs)):
            self._tf_prev[i].setRotation(r_prev[i])
            self._tf_prev[i].setTranslation(previous.position[i])
            self._tf_curr[i].setRotation(r_curr[i])
            self._tf_curr[i].setTranslation(current.position[i])

    def _candidate_pairs(self, previous: BodyStates, current: BodyStates) -> set[tuple[int, int]]:
        margin = self.settings.speculative_margin
        pairs: set[tuple[int, int]] = set()
        fin = self._finite
        if len(fin) > 1:
            lo = np.minimum(previous.position[fin], current.position[fin])
            hi = np.maximum(previous.position[fin], current.position[fin])
            half = 0.5 * (hi - lo) + (self._radius[fin] + 0.5 * margin)[:, None]
            centre = 0.5 * (hi + lo)
            for k, (g, obj) in enumerate(zip(self._proxies, self._proxy_objects)):
                g.halfSide = half[k]
                g.computeLocalAABB()
                obj.setTranslation(centre[k])
                obj.computeAABB()
            self._manager.update()
            self._callback.data.result.clear()
            self._manager.collide(self._callback)
            body = self._proxy_body
            static = self._static
            for c in self._callback.data.result.getContacts():
                a, b = body[c.o1.id()], body[c.o2.id()]
                if a != b and not (static[a] and static[b]):
                    pairs.add((a, b) if a < b else (b, a))
        # half-spaces against every dynamic body's swept bounding sphere
        for k in self._planes:
            n, d = self._plane_normal[k], self._plane_offset[k]
            r_prev = rotation.to_matrix(previous.orientation[k])
            r_curr = rotation.to_matrix(current.orientation[k])
            gap_prev = (previous.position[fin] - previous.position[k]) @ (r_prev @ n) - d
            gap_curr = (current.position[fin] - current.position[k]) @ (r_curr @ n) - d
            near = np.minimum(gap_prev, gap_curr) - self._radius[fin] < margin
            for i in fin[near & ~self._static[fin]]:
                pairs.add((int(min(i, k)), int(max(i, k))))
        return pairs

    # -- narrow phase ------------------------------------------------------------------------

    def _collide(self, a: int, tf_a: coal.Transform3s, b: int, tf_b: coal.Transform3s,
                 margin: float) -> bool:
        self._req.security_margin = margin
        self._res.clear()
        return coal.collide(self._geoms[a], tf_a, self._geoms[b], tf_b,
                            self._req, self._res) > 0

    def _distance(self, a: int, tf_a: coal.Transform3s, b: int, tf_b: coal.Transform3s) -> float:
        self._dres.clear()
        return float(coal.distance(self._geoms[a], tf_a, self._geoms[b], tf_b,
                                   self._dreq, self._dres))

    def _narrow_phase(self, a: int, b: int, previous: BodyStates, current: BodyStates,
                      out: '_ContactLists') -> None:
        margin = self.settings.speculative_margin
        if self._collide(a, self._tf_prev[a], b, self._tf_prev[b], margin):
            if self._collide(a, self._tf_curr[a], b, self._tf_curr[b], margin):
                self._add_manifold(a, self._tf_curr[a], b, self._tf_curr[b],
                                   ContactKind.PERSISTENT, 0.0, None, out)
            return
        if self._collide(a, self._tf_curr[a], b, self._tf_curr[b], margin):
            separation = self._res.getContact(0).penetration_depth
            if separation >= 0.0:  # within the margin, not penetrating: speculative
                self._add_manifold(a, self._tf_curr[a], b, self._tf_curr[b],
                                   ContactKind.PERSISTENT, 0.0, None, out)
            else:
                self._time_of_impact(a, b, previous, current, 0.0, 1.0,
                                     ContactKind.IMPACT, separation, out)
            return
        if self.settings.ccd:
            self._sweep(a, b, previous, current, out)

    def _poses(self, a: int, b: int, previous: BodyStates, current: BodyStates
               ) -> tuple[_Pose, _Pose]:
        return (_Pose(previous.position[a], current.position[a],
                      previous.orientation[a], current.orientation[a]),
                _Pose(previous.position[b], current.position[b],
                      previous.orientation[b], current.orientation[b]))

    def _time_of_impact(self, a: int, b: int, previous: BodyStates, current: BodyStates,
                        t0: float, t1: float, kind: ContactKind, separation_now: float,
                        out: '_ContactLists') -> None:
        """Bisection on [t0, t1] (apart at t0, overlapping at t1), then the manifold at t1."""
        pose_a, pose_b = self._poses(a, b, previous, current)
        tolerance = self.settings.toi_tolerance
        for _ in range(self.settings.toi_max_iterations):
            if t1 - t0 <= tolerance:
                break
            mid = 0.5 * (t0 + t1)
            if self._collide(a, pose_a.at(mid), b, pose_b.at(mid), 0.0):
                t1 = mid
            else:
                t0 = mid
        tf_a, tf_b = pose_a.at(t1), pose_b.at(t1)
        self._collide(a, tf_a, b, tf_b, 0.0)
        depth_at_toi = -self._res.getContact(0).penetration_depth
        fallback = None
        if depth_at_toi > DEEP_FRACTION * min(self._radius[a], self._radius[b]):
            # EPA on a deep overlap is not trusted: the lecture's estimate from the
            # closest points of the last separated configuration
            if self._distance(a, pose_a.at(t0), b, pose_b.at(t0)) > 0.0:
                p1, p2 = self._dres.getNearestPoint1(), self._dres.getNearestPoint2()
                gap = p2 - p1
                norm = float(np.linalg.norm(gap))
                if norm > 0.0:
                    fallback = gap / norm
            tf_a, tf_b = pose_a.at(t1), pose_b.at(t1)
            self._collide(a, tf_a, b, tf_b, 0.0)
        self._add_manifold(a, tf_a, b, tf_b, kind, t1, fallback, out,
                           separation_now=separation_now)

    def _sweep(self, a: int, b: int, previous: BodyStates, current: BodyStates,
               out: '_ContactLists') -> None:
        """Conservative advancement over the step for a pair apart at both ends."""
        motion = (np.linalg.norm((current.position[b] - previous.position[b])
                                 - (current.position[a] - previous.position[a]))
                  + _angle(previous.orientation[a], current.orientation[a]) * self._radius[a]
                  + _angle(previous.orientation[b], current.orientation[b]) * self._radius[b])
        if not np.isfinite(motion) or motion <= 0.0:
            return
        pose_a, pose_b = self._poses(a, b, previous, current)
        tolerance = max(1e-9, min(self.settings.toi_tolerance * motion,
                                  0.5 * self.settings.linear_slop))
        t = 0.0
        for _ in range(4 * self.settings.toi_max_iterations):
            gap = self._distance(a, pose_a.at(t), b, pose_b.at(t))
            if gap <= tolerance:
                break
            t += gap / motion
            if t >= 1.0:
                return
        else:
            return
        # overlap just after the advancement's stop: refine by bisection
        t1 = min(1.0, t + 4.0 * tolerance / motion)
        while not self._collide(a, pose_a.at(t1), b, pose_b.at(t1), 0.0):
            if t1 >= 1.0:
                return
            t1 = min(1.0, t1 + (t1 - t))
        self._collide(a, self._tf_curr[a], b, self._tf_curr[b], 0.0)
        self._time_of_impact(a, b, previous, current, t, t1, ContactKind.TUNNELLED,
                             0.0, out)

    def _add_manifold(self, a: int, tf_a: coal.Transform3s, b: int, tf_b: coal.Transform3s,
                      kind: ContactKind, toi: float, normal_override: np.ndarray | None,
                      out: '_ContactLists', separation_now: float | None = None) -> None:
        """Contact points of the current collision result (several for face contacts)."""
        contact = self._res.getContact(0)
        normal = np.array(contact.normal) if normal_override is None else normal_override
        self._patch_res.clear()
        points: list[tuple[np.ndarray, float]] = []
        if normal_override is None:
            coal.computeContactPatch(self._geoms[a], tf_a, self._geoms[b], tf_b, self._res,
                                     self._patch_req, self._patch_res)
            if self._patch_res.numContactPatches() > 0:
                patch = self._patch_res.getContactPatch(0)
                for k in range(patch.size()):
                    p1, p2 = patch.getPointShape1(k), patch.getPointShape2(k)
                    points.append((0.5 * (p1 + p2), float(np.dot(p2 - p1, normal))))
        if not points:
            points.append((np.array(contact.pos), float(contact.penetration_depth)))
        for k, (point, separation) in enumerate(points):
            if separation_now is not None:
                separation = min(separation, separation_now)
            out.add(a, b, point, normal, separation, toi, int(kind), k)


def _angle(q0: np.ndarray, q1: np.ndarray) -> float:
    """Rotation angle (rad) between two unit quaternions."""
    return float(2.0 * np.arccos(np.clip(abs(np.dot(q0, q1)), 0.0, 1.0)))


class _ContactLists:
    """Column lists gathered during the narrow phase, turned into arrays once."""

    def __init__(self) -> None:
        self.rows: list[tuple] = []

    def add(self, a: int, b: int, point: np.ndarray, normal: np.ndarray, separation: float,
            toi: float, kind: int, feature: int) -> None:
        self.rows.append((a, b, point, normal, separation, toi, kind, feature))

    def to_set(self) -> ContactSet:
        if not self.rows:
            return ContactSet.empty()
        a, b, point, normal, sep, toi, kind, feature = zip(*self.rows)
        normal_arr = np.array(normal, dtype=float)
        normal_arr /= np.linalg.norm(normal_arr, axis=1, keepdims=True)
        return ContactSet(np.array(a, np.int64), np.array(b, np.int64),
                          np.array(point, dtype=float), normal_arr, np.array(sep, dtype=float),
                          np.array(toi, dtype=float), np.array(kind, np.int8),
                          np.array(feature, np.int64))
