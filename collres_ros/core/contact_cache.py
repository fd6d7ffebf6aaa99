"""Warm-start cache: last step's impulses keyed by (body_a, body_b, feature).

Vectorised: keys are kept sorted, lookups are one ``searchsorted``. The
friction impulse is stored as a world vector so it can be projected onto
next step's tangent basis, whatever that basis is. A contact whose feature
id changed (e.g. a rolling sphere) falls back to the stored point of the
same pair nearest to it, within ``match_radius``.
"""

from __future__ import annotations

import numpy as np


class ContactCache:
    """Impulses of the last solved step, for warm starting the next one."""

    def __init__(self) -> None:
        self._a = np.zeros(0, np.int64)
        self._b = np.zeros(0, np.int64)
        self._feature = np.zeros(0, np.int64)
        self._normal = np.zeros(0)          # N s, >= 0
        self._friction = np.zeros((0, 3))   # N s, world, applied to B
        self._point = np.zeros((0, 3))      # m, world, where the impulse acted

    def __len__(self) -> int:
        return int(self._a.shape[0])

    @staticmethod
    def _keys(a: np.ndarray, b: np.ndarray, feature: np.ndarray) -> np.ndarray:
        """Lexicographic sort keys as a structured array (exact, no hashing)."""
        keys = np.empty(a.shape[0], dtype=[('a', np.int64), ('b', np.int64), ('f', np.int64)])
        keys['a'], keys['b'], keys['f'] = a, b, feature
        return keys

    def store(self, a: np.ndarray, b: np.ndarray, feature: np.ndarray,
              normal: np.ndarray, friction: np.ndarray, point: np.ndarray | None = None) -> None:
        """Replace the cache with these contacts' impulses (later duplicates win)."""
        keys = self._keys(np.asarray(a, np.int64), np.asarray(b, np.int64),
                          np.asarray(feature, np.int64))
        order = np.argsort(keys, kind='stable')
        keys = keys[order]
        keep = np.ones(keys.shape[0], bool)
        keep[:-1] = keys[1:] != keys[:-1]   # last of each run of equal keys
        order = order[keep]
        self._a, self._b = keys['a'][keep], keys['b'][keep]
        self._feature = keys['f'][keep]
        self._normal = np.asarray(normal, float)[order]
        self._friction = np.asarray(friction, float).reshape(-1, 3)[order]
        self._point = np.full((order.shape[0], 3), np.inf) if point is None else \
            np.asarray(point, float).reshape(-1, 3)[order]

    def lookup(self, a: np.ndarray, b: np.ndarray, feature: np.ndarray,
               point: np.ndarray | None = None,
               match_radius: float = 0.02) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(normal impulse (M,), friction impulse (M, 3), found (M,) bool); zeros where absent.

        Exact (a, b, feature) first; then, with ``point`` (M, 3) given, the
        nearest stored point of the same pair within ``match_radius`` m.
        """
        count = np.asarray(a).shape[0]
        normal = np.zeros(count)
        friction = np.zeros((count, 3))
        if count == 0 or len(self) == 0:
            return normal, friction, np.zeros(count, bool)
        a, b = np.asarray(a, np.int64), np.asarray(b, np.int64)
        stored = self._keys(self._a, self._b, self._feature)
        query = self._keys(a, b, np.asarray(feature, np.int64))
        where = np.minimum(np.searchsorted(stored, query), len(self) - 1)
        hit = stored[where] == query
        if point is not None and not hit.all():
            where, hit = self._nearest(a, b, np.asarray(point, float), where, hit, match_radius)
        normal[hit] = self._normal[where[hit]]
        friction[hit] = self._friction[where[hit]]
        return normal, friction, hit

    def _nearest(self, a: np.ndarray, b: np.ndarray, point: np.ndarray, where: np.ndarray,
                 hit: np.ndarray, radius: float) -> tuple[np.ndarray, np.ndarray]:
        """Fill misses with the nearest stored point of the same pair (each used once at most)."""
        miss = np.flatnonzero(~hit)
        pair = self._keys(self._a, self._b, np.full(len(self), -(2 ** 62)))
        first = np.searchsorted(pair, self._keys(a[miss], b[miss], np.full(miss.size, -(2 ** 62))))
        best = np.full(miss.size, -1)
        best_d = np.full(miss.size, radius)
        taken = np.zeros(len(self), bool)
        taken[where[hit]] = True
        for k in range(8):      # the stored points of a pair are contiguous: try a few
            at = first + k
            ok = at < len(self)
            at = np.minimum(at, len(self) - 1)
            ok &= (self._a[at] == a[miss]) & (self._b[at] == b[miss]) & ~taken[at]
            dist = np.linalg.norm(self._point[at] - point[miss], axis=1)
            better = ok & (dist < best_d)
            best[better], best_d[better] = at[better], dist[better]
        found = best >= 0
        where, hit = where.copy(), hit.copy()
        where[miss[found]] = best[found]
        hit[miss[found]] = True
        return where, hit

    def forget(self, bodies: np.ndarray) -> None:
        """Drop every entry that involves one of these body indices."""
        bodies = np.asarray(bodies, np.int64).ravel()
        drop = np.isin(self._a, bodies) | np.isin(self._b, bodies)
        keep = ~drop
        self._a, self._b, self._feature = self._a[keep], self._b[keep], self._feature[keep]
        self._normal, self._friction = self._normal[keep], self._friction[keep]
        self._point = self._point[keep]

    def clear(self) -> None:
        """Forget everything (a fresh start)."""
        self.__init__()
