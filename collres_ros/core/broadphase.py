"""Broad phase: pairs of bodies whose bounds, swept over the step, overlap.

Bounds are world-frame axis-aligned boxes (m) covering a body at its previous
and current pose and along the interpolated motion in between, padded by
half the speculative margin so that two bodies closer than the margin always
form a pair. Two backends give the same pairs:

* ``overlapping_pairs``: sort and sweep in numpy along the axis of largest
  spread, then an exact test on the two other axes. Cost grows with the
  number of near pairs along that axis; no per-pair Python.
* ``TreeBroadPhase``: coal's DynamicAABBTreeCollisionManager over the same
  boxes. coal cannot hand the pairs of its tree back to Python without a
  narrow-phase query and two wrapper look-ups per pair (coal.md gotchas 1-3),
  which measured several times slower than the numpy sweep, so the
  world uses it only on request (and tests use it as a cross-check).
"""

from __future__ import annotations

import coal
import numpy as np


def world_boxes(rotation: np.ndarray, origin: np.ndarray, local_lo: np.ndarray,
                local_hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """World AABBs (N, 3) min/max of local boxes under poses (R (N, 3, 3), origin (N, 3))."""
    centre = 0.5 * (local_lo + local_hi)
    half = 0.5 * (local_hi - local_lo)
    world_centre = np.einsum('nij,nj->ni', rotation, centre) + origin
    world_half = np.einsum('nij,nj->ni', np.abs(rotation), half)
    return world_centre - world_half, world_centre + world_half


def swept_bounds(lo0: np.ndarray, hi0: np.ndarray, lo1: np.ndarray, hi1: np.ndarray,
                 bulge: np.ndarray, pad: float) -> tuple[np.ndarray, np.ndarray]:
    """Union of the boxes at both ends, grown by ``bulge`` (N,) m (the arc of a rotation
    away from its chord) plus ``pad`` m on every side."""
    grow = (bulge + pad)[:, None]
    return np.minimum(lo0, lo1) - grow, np.maximum(hi0, hi1) + grow


def overlapping_pairs(lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Index pairs (i < j) of boxes (N, 3) that overlap or touch; int64 arrays, sorted."""
    count = lo.shape[0]
    if count < 2:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    axis = int(np.argmax(np.var(lo + hi, axis=0)))
    order = np.argsort(lo[:, axis], kind='stable')
    start = lo[order, axis]
    # for the k-th box in sweep order, the boxes after it that start before it ends
    stop = np.searchsorted(start, hi[order, axis], side='right')
    length = np.maximum(stop - np.arange(1, count + 1), 0)
    total = int(length.sum())
    if total == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    left = np.repeat(np.arange(count), length)
    right = left + 1 + (np.arange(total) - np.repeat(np.cumsum(length) - length, length))
    keep = np.ones(total, bool)
    for other in {0, 1, 2} - {axis}:   # the sweep axis overlaps by construction
        low, high = lo[order, other], hi[order, other]
        keep &= (low[left] <= high[right]) & (low[right] <= high[left])
    i, j = order[left[keep]], order[right[keep]]
    a, b = np.minimum(i, j), np.maximum(i, j)
    key = np.lexsort((b, a))
    return a[key].astype(np.int64), b[key].astype(np.int64)


class FatPairs:
    """Temporal coherence for ``overlapping_pairs``: pairs of boxes grown by a skin.

    Each body gets a fat box (its box plus ``skin`` m on every side); the pairs
    of fat boxes are kept while every box stays inside its fat box, and each
    step only filters them with the exact test. Bodies that leave their fat
    box get a new one and their pairs are recomputed against all the others.
    """

    def __init__(self, skin: float) -> None:
        self.skin = skin
        self._lo: np.ndarray | None = None
        self._hi: np.ndarray | None = None
        self._i = np.zeros(0, np.int64)
        self._j = np.zeros(0, np.int64)

    def pairs(self, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Same contract as ``overlapping_pairs``."""
        if self._lo is None or self._lo.shape != lo.shape:
            self._rebuild(lo, hi)
        else:
            escaped = np.flatnonzero(np.any((lo < self._lo) | (hi > self._hi), axis=1))
            if escaped.shape[0] * lo.shape[0] > 32 * max(self._i.shape[0], lo.shape[0]):
                self._rebuild(lo, hi)
            elif escaped.shape[0]:
                self._update(escaped, lo, hi)
        i, j = self._i, self._j
        keep = np.all((lo[i] <= hi[j]) & (lo[j] <= hi[i]), axis=1)
        return i[keep], j[keep]

    def _rebuild(self, lo: np.ndarray, hi: np.ndarray) -> None:
        self._lo, self._hi = lo - self.skin, hi + self.skin
        self._i, self._j = overlapping_pairs(self._lo, self._hi)

    def _update(self, escaped: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> None:
        assert self._lo is not None and self._hi is not None
        self._lo[escaped], self._hi[escaped] = lo[escaped] - self.skin, hi[escaped] + self.skin
        moved = np.zeros(lo.shape[0], bool)
        moved[escaped] = True
        stay = ~(moved[self._i] | moved[self._j])
        touch = np.all((self._lo[escaped, None, :] <= self._hi[None, :, :])
                       & (self._lo[None, :, :] <= self._hi[escaped, None, :]), axis=2)
        e, other = np.nonzero(touch)
        e = escaped[e]
        new = (e != other) & ~(moved[other] & (other < e))   # each escaped pair once
        a = np.minimum(e[new], other[new])
        b = np.maximum(e[new], other[new])
        i = np.concatenate((self._i[stay], a))
        j = np.concatenate((self._j[stay], b))
        key = np.lexsort((j, i))
        self._i, self._j = i[key], j[key]


class TreeBroadPhase:
    """coal DynamicAABBTree over given boxes (the issue's AABB-tree manager)."""

    def __init__(self, count: int) -> None:
        # one unit-sphere geometry per slot: its id names the slot; the AABB is set by hand
        self._geometries = [coal.Sphere(1.0) for _ in range(count)]
        self._objects = [coal.CollisionObject(g, coal.Transform3s()) for g in self._geometries]
        self._slot = {g.id(): k for k, g in enumerate(self._geometries)}
        self._manager = coal.DynamicAABBTreeCollisionManager()
        for obj in self._objects:
            obj.computeAABB()
            self._manager.registerObject(obj)
        self._manager.setup()
        self._collect = coal.CollisionCallBackDefault()
        request = self._collect.data.request
        request.num_max_contacts = 10 ** 9
        request.security_margin = 1e300  # every box-overlapping pair yields one contact

    def pairs(self, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Same contract as ``overlapping_pairs``, answered by coal's tree."""
        for obj, low, high in zip(self._objects, lo, hi):
            box = obj.getAABB()
            box.min_ = low
            box.max_ = high
        self._manager.update()
        self._collect.data.result.clear()
        self._manager.collide(self._collect)
        slot = self._slot
        found = [(slot[c.o1.id()], slot[c.o2.id()])
                 for c in self._collect.data.result.getContacts()]
        if not found:
            return np.zeros(0, np.int64), np.zeros(0, np.int64)
        both = np.array(found, dtype=np.int64)
        a, b = both.min(axis=1), both.max(axis=1)
        key = np.lexsort((b, a))
        return a[key], b[key]
