"""Narrow phase: coal GJK/EPA queries on pairs of shapes, returning numpy arrays.

Every query takes coal geometries and ``coal.Transform3s`` poses (world
frame) and answers in our conventions: signed distance in m (negative when
the shapes interpenetrate, from EPA), unit normal from the first shape to
the second, and the witness point on each shape (world, m).

Speed: one ``coal.collide`` per pair is unavoidable, but reading a contact
back field by field costs several coal calls per pair. ``NarrowPhase.batch``
therefore runs all pairs into one CollisionResult and reads it in one go
from coal's binary serialisation: a fixed 120-byte record per contact after
the first (the first carries boost's class preamble and is read field by
field), checked against the field-by-field answer on first use; if the
layout ever differs, it falls back to the field-by-field read.
"""

from __future__ import annotations

import os
import tempfile
import weakref

import coal
import numpy as np

_RECORD = np.dtype([('b', '<i4', (2,)), ('normal', '<f8', (3,)), ('count', '<u8'),
                    ('p1', '<f8', (3,)), ('p2', '<f8', (3,)), ('pos', '<f8', (3,)),
                    ('distance', '<f8')])
_TAIL = 8 + 8 + 48 + 24  # distance_lower_bound, nearest_points (count + 2 points), normal
PATCH_TOLERANCE = 0.01  # m, points within this of the separating plane join a patch
_BIG = 1e300             # security margin that makes every queried pair report a contact


def _remove(path: str) -> None:
    try:
        os.unlink(path)
    except OSError:
        pass


class NarrowPhase:
    """Reusable coal request/result objects for pair queries."""

    def __init__(self) -> None:
        self._request = coal.CollisionRequest()
        self._request.num_max_contacts = 10 ** 9
        self._result = coal.CollisionResult()
        self._batch_request = coal.CollisionRequest()
        self._batch_request.num_max_contacts = 10 ** 9
        self._batch_request.security_margin = _BIG
        self._batch_result = coal.CollisionResult()
        self._distance_request = coal.DistanceRequest()
        self._distance_result = coal.DistanceResult()
        self._patch_request = coal.ContactPatchRequest()
        # coal's default 1 mm keeps a single point for box faces tilted a few degrees,
        # so tilted piles rock and lose their warm starts; 1 cm keeps the face manifold
        self._patch_request.setPatchTolerance(PATCH_TOLERANCE)
        self._patch_result = coal.ContactPatchResult()
        fd, self._dump = tempfile.mkstemp(prefix='collres_', suffix='.bin',
                                          dir='/dev/shm' if os.path.isdir('/dev/shm') else None)
        os.close(fd)
        weakref.finalize(self, _remove, self._dump)   # when collected, or at exit
        self._binary_ok: bool | None = None

    def batch(self, geom_a: list, tf_a: list, geom_b: list, tf_b: list
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Signed distance (M,), normal (M, 3) A->B, witness points on A and on B (M, 3)."""
        count = len(geom_a)
        if count == 0:
            empty = np.zeros((0, 3))
            return np.zeros(0), empty, empty.copy(), empty.copy()
        result = self._batch_result
        result.clear()
        request = self._batch_request
        collide = coal.collide
        for ga, ta, gb, tb in zip(geom_a, tf_a, geom_b, tf_b):
            collide(ga, ta, gb, tb, request, result)
        if result.numContacts() != count:  # e.g. a mesh pair with several contacts
            return self._batch_slow(geom_a, tf_a, geom_b, tf_b)
        return self._read(result, count)

    def _batch_slow(self, geom_a: list, tf_a: list, geom_b: list, tf_b: list
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        rows = [self.contact(ga, ta, gb, tb, _BIG) for ga, ta, gb, tb
                in zip(geom_a, tf_a, geom_b, tf_b)]
        return (np.array([r[0] for r in rows]), np.array([r[1] for r in rows]),
                np.array([r[2] for r in rows]), np.array([r[3] for r in rows]))

    def _read(self, result: coal.CollisionResult, count: int
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        first = result.getContact(0)
        distance = np.empty(count)
        normal, on_a, on_b = np.empty((count, 3)), np.empty((count, 3)), np.empty((count, 3))
        distance[0], normal[0] = first.penetration_depth, first.normal
        on_a[0], on_b[0] = first.getNearestPoint1(), first.getNearestPoint2()
        if count == 1:
            return distance, normal, on_a, on_b
        records = None
        if self._binary_ok is not False:
            try:
                records = self._read_binary(result, count - 1)
            except (OSError, ValueError):
                records = None
            if records is not None and self._binary_ok is None:
                self._binary_ok = self._agrees(records, result)
            if not self._binary_ok:
                self._binary_ok, records = False, None
        if records is not None:
            distance[1:], normal[1:] = records['distance'], records['normal']
            on_a[1:], on_b[1:] = records['p1'], records['p2']
            return distance, normal, on_a, on_b
        for k in range(1, count):
            c = result.getContact(k)
            distance[k], normal[k] = c.penetration_depth, c.normal
            on_a[k], on_b[k] = c.getNearestPoint1(), c.getNearestPoint2()
        return distance, normal, on_a, on_b

    def _read_binary(self, result: coal.CollisionResult, last: int) -> np.ndarray | None:
        """The ``last`` contacts of ``result`` as records (contacts 1.., not the first)."""
        result.saveToBinary(self._dump)
        with open(self._dump, 'rb') as stream:
            data = stream.read()
        start = len(data) - _TAIL - last * _RECORD.itemsize
        if start < 0:
            return None
        records = np.frombuffer(data, dtype=_RECORD, count=last, offset=start)
        if not np.all(records['count'] == 2):
            return None
        return records

    @staticmethod
    def _agrees(records: np.ndarray, result: coal.CollisionResult) -> bool:
        for k in (0, len(records) - 1):
            c = result.getContact(k + 1)
            expected = np.concatenate(([c.penetration_depth], c.normal,
                                       c.getNearestPoint1(), c.getNearestPoint2()))
            got = np.concatenate(([records['distance'][k]], records['normal'][k],
                                  records['p1'][k], records['p2'][k]))
            if not np.array_equal(expected, got):
                return False
        return True

    def contact(self, ga: coal.CollisionGeometry, ta: coal.Transform3s,
                gb: coal.CollisionGeometry, tb: coal.Transform3s, margin: float
                ) -> tuple[float, np.ndarray, np.ndarray, np.ndarray] | None:
        """(signed distance, normal A->B, point on A, point on B) when closer than
        ``margin`` m, else None. The result stays loaded for ``manifold``."""
        self._request.security_margin = margin
        self._result.clear()
        if coal.collide(ga, ta, gb, tb, self._request, self._result) == 0:
            return None
        c = self._result.getContact(0)
        return c.penetration_depth, c.normal, c.getNearestPoint1(), c.getNearestPoint2()

    def load(self, index: int) -> None:
        """Make contact ``index`` of the last ``batch`` the one ``manifold`` works on
        (instead of querying the pair again)."""
        self._result.clear()
        self._result.addContact(self._batch_result.getContact(index))

    def overlaps(self, ga: coal.CollisionGeometry, ta: coal.Transform3s,
                 gb: coal.CollisionGeometry, tb: coal.Transform3s) -> bool:
        """True when the shapes interpenetrate (distance < 0)."""
        self._request.security_margin = 0.0
        self._result.clear()
        return coal.collide(ga, ta, gb, tb, self._request, self._result) > 0

    def distance(self, ga: coal.CollisionGeometry, ta: coal.Transform3s,
                 gb: coal.CollisionGeometry, tb: coal.Transform3s
                 ) -> tuple[float, np.ndarray, np.ndarray]:
        """(distance >= 0 m, closest point on A, on B); 0 when they overlap (GJK)."""
        self._distance_result.clear()
        gap = coal.distance(ga, ta, gb, tb, self._distance_request, self._distance_result)
        result = self._distance_result
        return max(0.0, float(gap)), result.getNearestPoint1(), result.getNearestPoint2()

    def manifold(self, ga: coal.CollisionGeometry, ta: coal.Transform3s,
                 gb: coal.CollisionGeometry, tb: coal.Transform3s,
                 known: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Points on A (k, 3), on B (k, 3) and the normal A->B of the contact last found
        by ``contact`` (or ``load``) on the same pair: several points where faces touch
        (coal patch). ``known``: that contact's (normal, point on A, point on B), if read."""
        if known is None:
            c = self._result.getContact(0)
            known = (np.asarray(c.normal, dtype=float),
                     np.asarray(c.getNearestPoint1(), dtype=float),
                     np.asarray(c.getNearestPoint2(), dtype=float))
        normal = known[0]
        patches = self._patch_result
        patches.clear()
        coal.computeContactPatch(ga, ta, gb, tb, self._result, self._patch_request, patches)
        if patches.numContactPatches() > 0:
            patch = patches.getContactPatch(0)
            size = patch.size()
            if size > 1:
                # the patch is a polygon on the separating plane, at one signed depth:
                # each body's point is half of it along the normal from there
                middle = np.array([patch.getPoint(k) for k in range(size)])
                half = 0.5 * patch.penetration_depth * normal
                return middle - half, middle + half, normal
        return known[1][None, :], known[2][None, :], normal
