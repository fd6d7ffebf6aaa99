"""Collision detection of one step with coal: the contacts the solver resolves.

The one place that talks to coal for queries; it returns our own ContactSet
(world frame, normals unit from body A to body B, A < B). One step:

1. Motion: each body moves from its previous pose (s = 0) to its current pose
   (s = 1) by lerp of position and slerp of orientation. ``motion_bound``
   bounds how far any point of a body travels over the step.
2. Broad phase (``broadphase``): boxes swept over the step and padded by half
   the speculative margin give the candidate pairs; half-spaces are tested
   against every body's swept box directly. Pairs of two fixed bodies (static
   or inactive) are skipped.
3. Persistent manifolds: a pair that was in contact last step and whose
   relative pose has barely changed keeps its contact points, stored in the
   two body frames, and only their gaps are recomputed (numpy, no coal call):
   a settled pile costs almost nothing.
4. Narrow phase of the other pairs (``narrowphase``, one batched coal call per
   pair at the current state, after dropping pairs whose bounding spheres are
   farther apart than both the margin and their relative motion), then per
   pair:
   PERSISTENT when within the margin at the previous state too (or within it
   now and apart before without a hit: a speculative contact); IMPACT when
   apart before and overlapping now: bisection for the time of impact
   (``toi``); TUNNELLED when apart at both ends but the conservative
   advancement finds a hit, then the same bisection; none otherwise.
5. Manifolds: coal contact patches where faces touch (four points for a box
   face on a floor), with a ``feature`` id that is the same every step for
   the same corner, edge or face of the two bodies.

ContactSet fields (see types.ContactSet): PERSISTENT rows are at the current
state (toi 0, separation > 0 for a speculative gap, < 0 for a penetration).
IMPACT rows have point and normal at the time of impact and separation
min(separation there, signed distance now) < 0; TUNNELLED rows have point,
normal and separation (about 0) at the time of impact.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import coal
import numpy as np

from collres_ros.core import rotation
from collres_ros.core.broadphase import FatPairs, TreeBroadPhase, swept_bounds, world_boxes
from collres_ros.core.config import SolverSettings
from collres_ros.core.narrowphase import NarrowPhase
from collres_ros.core.shapes import (bounding_radius, local_aabb, make_geometry,
                                     plane_normal_offset, shape_offset)
from collres_ros.core.toi import Motion, advance, bisect
from collres_ros.core.types import BodySpec, BodyStates, ContactKind, ContactSet

DEEP_FRACTION = 0.25        # EPA's normal is not trusted deeper than this part of the thinner body
REUSE_TRANSLATION = 1e-3    # m: a manifold is reused while its pair has moved less than this ...
REUSE_ROTATION = 1e-2       # rad: ... and turned less than this relative to each other


@dataclass
class _Step:
    """Poses of all bodies at both ends of the step (see the module docstring)."""

    p0: np.ndarray       # (N, 3) m, previous centre of mass
    p1: np.ndarray       # (N, 3) m, current centre of mass
    q0: np.ndarray       # (N, 4) previous orientation x, y, z, w
    q1: np.ndarray       # (N, 4) current orientation
    r0: np.ndarray       # (N, 3, 3) previous rotation
    r1: np.ndarray       # (N, 3, 3) current rotation
    turn: np.ndarray     # (N,) rad, rotation over the step
    moved: np.ndarray    # (N,) m, bound on any point's travel over the step
    fixed: np.ndarray    # (N,) bool, static or inactive: never moved by the solver
    valid: np.ndarray    # (N,) bool, finite poses: bodies without them get no contacts


@dataclass
class _Manifolds:
    """Contact points of the pairs in contact at the end of the last step, in body frames."""

    key: np.ndarray       # (P,) int64, a * N + b, sorted
    rel_p: np.ndarray     # (P, 3) m, B's origin in A's frame when computed
    rel_q: np.ndarray     # (P, 4) B's orientation in A's frame when computed
    row_pair: np.ndarray  # (R,) index into the pairs
    local_a: np.ndarray   # (R, 3) m, point on A in A's frame
    local_b: np.ndarray   # (R, 3) m, point on B in B's frame
    normal_a: np.ndarray  # (R, 3) unit normal A->B in A's frame
    feature: np.ndarray   # (R,) int64

    @staticmethod
    def empty() -> '_Manifolds':
        z3 = np.zeros((0, 3))
        return _Manifolds(np.zeros(0, np.int64), z3, np.zeros((0, 4)), np.zeros(0, np.int64),
                          z3, z3, z3, np.zeros(0, np.int64))


class CollisionWorld:
    """coal geometries, broad phase and narrow phase for a fixed list of bodies."""

    def __init__(self, bodies: Sequence[BodySpec], settings: SolverSettings,
                 broad_phase: str = 'sweep') -> None:
        """``broad_phase``: 'sweep' (numpy sort and sweep) or 'tree' (coal AABB tree)."""
        if broad_phase not in ('sweep', 'tree'):
            raise ValueError(f'broad_phase must be sweep or tree (got {broad_phase!r})')
        self.specs = list(bodies)
        self.settings = settings
        count = len(self.specs)
        self._geoms = [make_geometry(s) for s in self.specs]
        self._offset = np.array([shape_offset(s) for s in self.specs]).reshape(count, 3)
        self._radius = np.array([bounding_radius(s) for s in self.specs], dtype=float)
        self._static = np.array([s.static or s.shape == 'plane' for s in self.specs], bool)
        self._round = np.array([s.shape == 'sphere' for s in self.specs], bool)
        plane = np.array([s.shape == 'plane' for s in self.specs], bool)
        self._planes = np.flatnonzero(plane)
        self._finite = np.flatnonzero(~plane)
        self._local_lo = np.zeros((count, 3))
        self._local_hi = np.zeros((count, 3))
        self._half = np.full((count, 3), np.inf)   # local half extents (feature ids)
        for k in self._finite:
            self._local_lo[k], self._local_hi[k] = local_aabb(self.specs[k], self._geoms[k])
            self._half[k] = 0.5 * (self._local_hi[k] - self._local_lo[k])
        self._thickness = np.where(plane, np.inf, np.min(self._half, axis=1))
        self._plane_n = np.zeros((count, 3))
        self._plane_d = np.zeros(count)
        for k in self._planes:
            self._plane_n[k], self._plane_d[k] = plane_normal_offset(self.specs[k])
        self._transforms = [coal.Transform3s() for _ in self.specs]
        self._narrow = NarrowPhase()
        self._broad: FatPairs | TreeBroadPhase = (
            TreeBroadPhase(len(self._finite)) if broad_phase == 'tree'
            else FatPairs(skin=2.0 * settings.speculative_margin + 1e-3))
        self._manifolds = _Manifolds.empty()
        self._manifold_margin = settings.speculative_margin

    # -- public ------------------------------------------------------------------------------

    def detect(self, previous: BodyStates, current: BodyStates,
               active: np.ndarray | None = None) -> ContactSet:
        """Contacts of the step ``previous`` -> ``current`` (see the module docstring).

        ``active`` (N,) bool: False marks a frozen body, held at its current pose
        over the whole step (its previous pose is ignored); it still collides.
        """
        if self._manifold_margin != self.settings.speculative_margin:
            self.reset()
            self._manifold_margin = self.settings.speculative_margin
        step = self._step(previous, current, active)
        a, b = self._pairs(step)
        out = _Rows()
        kept = self._reuse_manifolds(step, a, b, out)
        self._narrow_phase(step, a[~kept], b[~kept], out)
        self._manifolds = out.manifolds(len(self.specs))
        return out.contact_set()

    def candidate_pairs(self, previous: BodyStates, current: BodyStates,
                        active: np.ndarray | None = None) -> list[tuple[int, int]]:
        """Broad-phase pairs (a < b) whose swept bounds overlap (for tests and tools)."""
        a, b = self._pairs(self._step(previous, current, active))
        return list(zip(a.tolist(), b.tolist()))

    def reset(self) -> None:
        """Forget the stored manifolds (e.g. after bodies were teleported)."""
        self._manifolds = _Manifolds.empty()

    # -- motion and broad phase --------------------------------------------------------------

    def _step(self, previous: BodyStates, current: BodyStates,
              active: np.ndarray | None) -> _Step:
        p0, q0 = previous.position, previous.orientation
        p1, q1 = current.position, current.orientation
        valid = np.ones(len(self.specs), bool)
        for array in (p0, p1, q0, q1):
            valid &= np.all(np.isfinite(array), axis=1)
        for q in (q0, q1):
            valid &= np.linalg.norm(np.where(np.isfinite(q), q, 0.0), axis=1) > 0.5
        if not np.all(valid):   # the caller validates; this only keeps NaN out of coal
            p0, p1 = (np.where(valid[:, None], p, 0.0) for p in (p0, p1))
            q0, q1 = (np.where(valid[:, None], q, [0.0, 0.0, 0.0, 1.0]) for q in (q0, q1))
        q0, q1 = rotation.normalize(q0), rotation.normalize(q1)
        fixed = self._static.copy()
        if active is not None:
            frozen = ~np.asarray(active, dtype=bool)
            p0 = np.where(frozen[:, None], p1, p0)
            q0 = np.where(frozen[:, None], q1, q0)
            fixed |= frozen
        turn = 2.0 * np.arccos(np.clip(np.abs(np.sum(q0 * q1, axis=1)), 0.0, 1.0))
        moved = (np.linalg.norm(p1 - p0, axis=1)
                 + turn * np.where(self._static, 0.0, self._radius))
        moved = np.where(np.isfinite(moved), moved, 0.0)
        return _Step(p0, p1, q0, q1, rotation.to_matrix(q0), rotation.to_matrix(q1),
                     turn, moved, fixed, valid)

    def _pairs(self, step: _Step) -> tuple[np.ndarray, np.ndarray]:
        """Candidate pairs (a < b), sorted, with at least one movable body."""
        pad = 0.5 * self.settings.speculative_margin
        fin = self._finite
        # local boxes are in the body frame (cone offset included): place them by the pose
        lo0, hi0 = world_boxes(step.r0[fin], step.p0[fin], self._local_lo[fin],
                               self._local_hi[fin])
        lo1, hi1 = world_boxes(step.r1[fin], step.p1[fin], self._local_lo[fin],
                               self._local_hi[fin])
        # a point at radius r turning by angle t leaves its chord by r (1 - cos(t / 2))
        bulge = self._radius[fin] * (1.0 - np.cos(0.5 * np.minimum(step.turn[fin], np.pi)))
        lo, hi = swept_bounds(lo0, hi0, lo1, hi1, bulge, pad)
        i, j = self._broad.pairs(lo, hi)
        a, b = fin[i], fin[j]
        found_a, found_b = [a], [b]
        for k in self._planes:   # half-space n.x <= d against each swept box
            for r, p in ((step.r0[k], step.p0[k]), (step.r1[k], step.p1[k])):
                normal = r @ self._plane_n[k]
                offset = self._plane_d[k] + normal @ p
                lowest = 0.5 * (lo + hi) @ normal - 0.5 * (hi - lo) @ np.abs(normal)
                near = fin[lowest <= offset + pad]
                found_a.append(np.minimum(near, k))
                found_b.append(np.maximum(near, k))
        a, b = np.concatenate(found_a), np.concatenate(found_b)
        keep = ~(step.fixed[a] & step.fixed[b]) & step.valid[a] & step.valid[b]
        key = np.unique(a[keep] * len(self.specs) + b[keep])
        return key // len(self.specs), key % len(self.specs)

    # -- persistent manifolds ----------------------------------------------------------------

    def _reuse_manifolds(self, step: _Step, a: np.ndarray, b: np.ndarray,
                         out: '_Rows') -> np.ndarray:
        """Refresh the stored manifolds of pairs that barely moved; mask of pairs done."""
        stored = self._manifolds
        kept = np.zeros(a.shape[0], bool)
        if stored.key.shape[0] == 0 or a.shape[0] == 0:
            return kept
        key = a * len(self.specs) + b
        where = np.minimum(np.searchsorted(stored.key, key), stored.key.shape[0] - 1)
        hit = stored.key[where] == key
        if not np.any(hit):
            return kept
        rel_p, rel_q = _relative(step, a[hit], b[hit])
        slow = ((step.moved[a[hit]] + step.moved[b[hit]] <= self.settings.speculative_margin)
                & (np.linalg.norm(rel_p - stored.rel_p[where[hit]], axis=1)
                   <= REUSE_TRANSLATION)
                & (_angle(rel_q, stored.rel_q[where[hit]]) <= REUSE_ROTATION))
        kept[np.flatnonzero(hit)[slow]] = True
        if not np.any(kept):
            return kept
        # rows of the reused pairs (stored rows are grouped by pair)
        reused = np.zeros(stored.key.shape[0], bool)
        reused[where[kept]] = True
        rows = np.flatnonzero(reused[stored.row_pair])
        pair = stored.row_pair[rows]
        ra, rb = stored.key[pair] // len(self.specs), stored.key[pair] % len(self.specs)
        turn_a = step.r1[ra]
        on_a = np.einsum('nij,nj->ni', turn_a, stored.local_a[rows]) + step.p1[ra]
        on_b = np.einsum('nij,nj->ni', step.r1[rb], stored.local_b[rows]) + step.p1[rb]
        normal = np.einsum('nij,nj->ni', turn_a, stored.normal_a[rows])
        separation = np.einsum('ni,ni->n', on_b - on_a, normal)
        # a pair whose every point left the margin is no longer in contact
        starts = np.flatnonzero(np.r_[True, pair[1:] != pair[:-1]])
        gap = np.minimum.reduceat(separation, starts)
        counts = np.diff(np.r_[starts, pair.shape[0]])
        alive = np.repeat(gap <= self.settings.speculative_margin, counts)
        rows, pair = rows[alive], pair[alive]
        out.add_block(ra[alive], rb[alive], on_a[alive], on_b[alive], normal[alive],
                      separation[alive], np.zeros(rows.shape[0]), ContactKind.PERSISTENT,
                      stored.feature[rows], stored.local_a[rows], stored.local_b[rows],
                      stored.normal_a[rows], stored.rel_p[pair], stored.rel_q[pair])
        return kept

    # -- narrow phase and time of impact -----------------------------------------------------

    def _narrow_phase(self, step: _Step, a: np.ndarray, b: np.ndarray, out: '_Rows') -> None:
        if a.shape[0] == 0:
            return
        settings = self.settings
        margin = settings.speculative_margin
        relative = (np.linalg.norm((step.p1[b] - step.p0[b]) - (step.p1[a] - step.p0[a]), axis=1)
                    + step.turn[a] * self._radius_or_zero(a)
                    + step.turn[b] * self._radius_or_zero(b))
        # bounding spheres: farther apart than the margin and than the relative motion,
        # the pair can neither touch now nor have met during the step
        bound = (np.linalg.norm(step.p1[b] - step.p1[a], axis=1)
                 - self._radius[a] - self._radius[b])
        keep = ~((bound > margin) & (bound >= relative))
        a, b, relative = a[keep], b[keep], relative[keep]
        if a.shape[0] == 0:
            return
        self._push(step, np.unique(np.concatenate((a, b))))
        geoms, tfs = self._geoms, self._transforms
        al, bl = a.tolist(), b.tolist()
        distance, normal, on_a, on_b = self._narrow.batch(
            [geoms[i] for i in al], [tfs[i] for i in al],
            [geoms[j] for j in bl], [tfs[j] for j in bl])
        near = distance <= margin
        # touching at the previous state for sure: it cannot have been farther than this
        persistent = near & (distance + relative <= margin)
        maybe_hit = settings.ccd & (relative > distance)
        raw = _Raw()
        single = persistent & (self._round[a] | self._round[b])   # a sphere touches at a point
        raw.singles = (a[single], b[single], on_a[single], on_b[single], normal[single])
        for k in np.flatnonzero(persistent & ~single).tolist():
            self._narrow.load(k)
            a_k, b_k = al[k], bl[k]
            on_a_k, on_b_k, normal_k = self._narrow.manifold(
                geoms[a_k], tfs[a_k], geoms[b_k], tfs[b_k], (normal[k], on_a[k], on_b[k]))
            raw.add(a_k, b_k, on_a_k, on_b_k, normal_k, 0.0, ContactKind.PERSISTENT)
        for k in np.flatnonzero(~persistent & (near | maybe_hit)):
            self._classify(step, al[k], bl[k], float(distance[k]), float(relative[k]),
                           bool(near[k]), raw)
        self._finish(step, raw, out)

    def _classify(self, step: _Step, a: int, b: int, distance_now: float, relative: float,
                  near: bool, raw: '_Raw') -> None:
        """One pair that moved too much to know its previous state without a query."""
        settings = self.settings
        narrow = self._narrow
        ga, gb = self._geoms[a], self._geoms[b]
        ma, mb = self._motion(step, a), self._motion(step, b)
        before, _, _ = narrow.distance(ga, ma.at(0.0), gb, mb.at(0.0))
        if before <= settings.speculative_margin:
            if near:   # in contact at both ends
                self._current_manifold(a, b, raw)
            return
        if distance_now < 0.0:   # apart before, overlapping now
            self._time_of_impact(a, b, ma, mb, 0.0, 1.0, ContactKind.IMPACT, distance_now, raw)
            return
        if settings.ccd:
            tolerance = max(1e-9, min(settings.toi_tolerance * relative,
                                      0.5 * settings.linear_slop))
            bracket = advance(lambda s: narrow.distance(ga, ma.at(s), gb, mb.at(s))[0],
                              lambda s: narrow.overlaps(ga, ma.at(s), gb, mb.at(s)),
                              relative, tolerance, 4 * settings.toi_max_iterations)
            if bracket is not None:
                self._time_of_impact(a, b, ma, mb, bracket[0], bracket[1],
                                     ContactKind.TUNNELLED, None, raw)
                return
        if near:   # approaching, not touching yet: a speculative contact
            self._current_manifold(a, b, raw)

    def _time_of_impact(self, a: int, b: int, ma: Motion, mb: Motion, s0: float, s1: float,
                        kind: ContactKind, distance_now: float | None, raw: '_Raw') -> None:
        """Bisection on [s0, s1] (apart at s0, overlapping at s1), then contacts at s1."""
        settings, narrow = self.settings, self._narrow
        ga, gb = self._geoms[a], self._geoms[b]
        s0, s1 = bisect(lambda s: narrow.overlaps(ga, ma.at(s), gb, mb.at(s)), s0, s1,
                        settings.toi_tolerance, settings.toi_max_iterations)
        found = narrow.contact(ga, ma.at(s1), gb, mb.at(s1), 0.0)
        if found is None:   # only for a degenerate bracket: the end of the step overlaps
            s1 = 1.0
            found = narrow.contact(ga, ma.at(s1), gb, mb.at(s1), 0.0)
            if found is None:
                return
        override = None
        if -found[0] > DEEP_FRACTION * min(self._thickness[a], self._thickness[b]):
            # EPA on a deep overlap is not trusted: the classic direction from the
            # closest points of the last separated configuration
            gap, point_a, point_b = narrow.distance(ga, ma.at(s0), gb, mb.at(s0))
            direction = np.asarray(point_b) - np.asarray(point_a)
            length = float(np.linalg.norm(direction))
            if gap > 0.0 and length > 0.0:
                override = direction / length
            narrow.contact(ga, ma.at(s1), gb, mb.at(s1), 0.0)
        on_a, on_b, normal = narrow.manifold(ga, ma.at(s1), gb, mb.at(s1))
        pose = (ma.rotation_at(s1), ma.position_at(s1), mb.rotation_at(s1), mb.position_at(s1))
        raw.add(a, b, on_a, on_b, normal if override is None else override, s1, kind,
                distance_now, pose)

    def _current_manifold(self, a: int, b: int, raw: '_Raw') -> None:
        """Contact points of a pair at the current state (several where faces touch)."""
        narrow = self._narrow
        ga, ta, gb, tb = self._geoms[a], self._transforms[a], self._geoms[b], self._transforms[b]
        if narrow.contact(ga, ta, gb, tb, self.settings.speculative_margin) is not None:
            on_a, on_b, normal = narrow.manifold(ga, ta, gb, tb)
            raw.add(a, b, on_a, on_b, normal, 0.0, ContactKind.PERSISTENT)

    def _finish(self, step: _Step, raw: '_Raw', out: '_Rows') -> None:
        """Turn the raw coal points into contact rows, all pairs at once."""
        s_a, s_b, s_on_a, s_on_b, s_normal = raw.singles
        m = s_a.shape[0]
        if m + len(raw.a) == 0:
            return
        a = np.concatenate((s_a, np.array(raw.a, np.int64))).astype(np.int64)
        b = np.concatenate((s_b, np.array(raw.b, np.int64))).astype(np.int64)
        count = np.concatenate((np.ones(m, np.int64), np.array(raw.count, np.int64)))
        ra, pa, rb, pb = step.r1[a], step.p1[a], step.r1[b], step.p1[b]
        for k, (r_a, p_a, r_b, p_b) in raw.poses.items():   # contacts at a time of impact
            ra[m + k], pa[m + k], rb[m + k], pb[m + k] = r_a, p_a, r_b, p_b
        normal = np.concatenate((s_normal, np.array(raw.normal, dtype=float).reshape(-1, 3)))
        normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-300)
        row = np.repeat(np.arange(a.shape[0]), count)
        on_a, on_b = np.concatenate([s_on_a] + raw.on_a), np.concatenate([s_on_b] + raw.on_b)
        normal_rows = normal[row]
        separation = np.einsum('ni,ni->n', on_b - on_a, normal_rows)
        cap = np.concatenate((np.full(m, np.nan), raw.cap))   # nan: no cap
        separation = np.fmin(separation, cap[row])
        local_a = np.einsum('nji,nj->ni', ra[row], on_a - pa[row])
        local_b = np.einsum('nji,nj->ni', rb[row], on_b - pb[row])
        feature = _features(row, local_a, local_b, self._half[a[row]], self._half[b[row]])
        rel_p, rel_q = _relative(step, a, b)
        kind = np.concatenate((np.full(m, ContactKind.PERSISTENT, np.int8),
                               np.array(raw.kind, np.int8)))
        toi = np.concatenate((np.zeros(m), raw.toi))
        out.add_block(a[row], b[row], on_a, on_b, normal_rows, separation,
                      toi[row], kind[row], feature, local_a, local_b,
                      np.einsum('nji,nj->ni', ra[row], normal_rows), rel_p[row], rel_q[row],
                      cache=(kind == ContactKind.PERSISTENT)[row])

    # -- helpers -----------------------------------------------------------------------------

    def _push(self, step: _Step, bodies: np.ndarray) -> None:
        """Set the coal transforms of ``bodies`` to their current pose."""
        origin = step.p1[bodies] + np.einsum('nij,nj->ni', step.r1[bodies], self._offset[bodies])
        rotations = step.r1[bodies]
        transforms = self._transforms
        for k, body in enumerate(bodies.tolist()):
            transforms[body].setTransform(rotations[k], origin[k])

    def _motion(self, step: _Step, body: int) -> Motion:
        return Motion(step.p0[body], step.p1[body], step.q0[body], step.q1[body],
                      self._offset[body], step.r0[body], step.r1[body])

    def _radius_or_zero(self, bodies: np.ndarray) -> np.ndarray:
        return np.where(np.isfinite(self._radius[bodies]), self._radius[bodies], 0.0)


def _relative(step: _Step, a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """B's origin (M, 3) m and orientation (M, 4) in A's frame, at the current state."""
    rel_p = np.einsum('nji,nj->ni', step.r1[a], step.p1[b] - step.p1[a])
    qa = step.q1[a] * np.array([-1.0, -1.0, -1.0, 1.0])
    return rel_p, rotation.multiply(qa, step.q1[b])


def _angle(q0: np.ndarray, q1: np.ndarray) -> np.ndarray:
    """Rotation angle (rad) between unit quaternions, row by row."""
    return 2.0 * np.arccos(np.clip(np.abs(np.sum(q0 * q1, axis=-1)), 0.0, 1.0))


def _features(group: np.ndarray, local_a: np.ndarray, local_b: np.ndarray,
              half_a: np.ndarray, half_b: np.ndarray) -> np.ndarray:
    """Feature ids (M,) of contact points: which corner/edge/face of A and of B they are on.

    Each coordinate of a point in a body's frame (local_*, (M, 3) m) is coded -1, 0
    or +1 by whether it lies in the outer quarter of the body's half extent (half_*,
    (M, 3) m) on that side; repeated codes within one ``group`` (one pair) are made
    distinct by their rank.
    """
    def code(local: np.ndarray, half: np.ndarray) -> np.ndarray:
        side = np.where(local > 0.5 * half, 2, np.where(local < -0.5 * half, 1, 0))
        return side @ np.array([1, 3, 9])

    key = (27 * code(local_a, half_a) + code(local_b, half_b)).astype(np.int64)
    combined = group.astype(np.int64) * 729 + key
    order = np.argsort(combined, kind='stable')
    ordered = combined[order]
    start = np.r_[True, ordered[1:] != ordered[:-1]]
    index = np.arange(ordered.shape[0])
    rank = np.empty_like(key)
    rank[order] = index - np.maximum.accumulate(np.where(start, index, 0))
    return key + 729 * rank


class _Raw:
    """Contact points straight from coal, one entry per pair, before vectorised post-work."""

    def __init__(self) -> None:
        self.a: list[int] = []
        self.b: list[int] = []
        self.count: list[int] = []
        self.on_a: list[np.ndarray] = []
        self.on_b: list[np.ndarray] = []
        self.normal: list[np.ndarray] = []
        self.toi: list[float] = []
        self.kind: list[int] = []
        self.cap: list[float] = []
        self.poses: dict[int, tuple[np.ndarray, ...]] = {}
        z3 = np.zeros((0, 3))
        # single-point persistent pairs straight from the batch: (a, b, on_a, on_b, normal)
        self.singles: tuple[np.ndarray, ...] = (np.zeros(0, np.int64), np.zeros(0, np.int64),
                                                z3, z3, z3)

    def add(self, a: int, b: int, on_a: np.ndarray, on_b: np.ndarray, normal: np.ndarray,
            toi: float, kind: ContactKind, cap: float | None = None,
            pose: tuple[np.ndarray, ...] | None = None) -> None:
        """Points (k, 3) on A and on B (world, m) with their normal A->B; ``cap`` bounds
        the separation (IMPACT); ``pose`` (R_a, p_a, R_b, p_b) when not the current one."""
        if pose is not None:
            self.poses[len(self.a)] = pose
        self.a.append(a)
        self.b.append(b)
        self.count.append(on_a.shape[0])
        self.on_a.append(on_a)
        self.on_b.append(on_b)
        self.normal.append(normal)
        self.toi.append(toi)
        self.kind.append(int(kind))
        self.cap.append(np.nan if cap is None else cap)


class _Rows:
    """Contact rows gathered during one detect(), turned into arrays once."""

    def __init__(self) -> None:
        self.blocks: list[tuple] = []

    def add_block(self, a: np.ndarray, b: np.ndarray, on_a: np.ndarray, on_b: np.ndarray,
                  normal: np.ndarray, separation: np.ndarray, toi: np.ndarray,
                  kind: np.ndarray | int, feature: np.ndarray, local_a: np.ndarray,
                  local_b: np.ndarray, normal_a: np.ndarray, rel_p: np.ndarray,
                  rel_q: np.ndarray, cache: np.ndarray | bool = True) -> None:
        count = a.shape[0]
        if count:
            self.blocks.append((a, b, on_a, on_b, normal, separation, toi,
                                np.broadcast_to(np.asarray(kind, np.int8), (count,)), feature,
                                local_a, local_b, normal_a, rel_p, rel_q,
                                np.broadcast_to(np.asarray(cache, bool), (count,))))

    def _columns(self) -> list[np.ndarray]:
        if len(self.blocks) == 1:
            return list(self.blocks[0])
        return [np.concatenate(column) for column in zip(*self.blocks)]

    def contact_set(self) -> ContactSet:
        if not self.blocks:
            return ContactSet.empty()
        a, b, on_a, on_b, normal, separation, toi, kind, feature = self._columns()[:9]
        # rows come grouped by pair: stored manifolds in pair order, then new pairs
        return ContactSet(a.astype(np.int64), b.astype(np.int64), 0.5 * (on_a + on_b),
                          normal, separation.astype(float), toi.astype(float),
                          kind.astype(np.int8), feature.astype(np.int64))

    def manifolds(self, count: int) -> _Manifolds:
        """The persistent rows, grouped by pair, stored for reuse next step."""
        if not self.blocks:
            return _Manifolds.empty()
        (a, b, _, _, _, _, _, _, feature, local_a, local_b, normal_a, rel_p, rel_q,
         cache) = self._columns()
        rows = np.flatnonzero(cache)
        if rows.shape[0] == 0:
            return _Manifolds.empty()
        row_key = a[rows].astype(np.int64) * count + b[rows]
        order = np.argsort(row_key, kind='stable')
        rows, row_key = rows[order], row_key[order]
        key, first, row_pair = np.unique(row_key, return_index=True, return_inverse=True)
        return _Manifolds(key, rel_p[rows[first]], rel_q[rows[first]], row_pair.reshape(-1),
                          local_a[rows], local_b[rows], normal_a[rows], feature[rows])
