"""Detection of one step: the compiled detector (``src/detection.h``) behind a thin facade.

``Detection.detect(previous, current, active)`` returns the step's ContactSet (world
frame, normals unit from body A to body B, A < B, rows grouped by pair in increasing
(A, B) order). The C++ side does, with the GIL released: swept-bounds broad phase (sort
and sweep; half-spaces tested against every finite body), reuse of the stored manifolds
of flat-faced pairs that barely moved, coal narrow phase and contact patches reduced to
at most four points with stable feature ids, and the classification of each pair:

* PERSISTENT: within the speculative margin at the previous state too (or within it now
  and apart before without a hit: a speculative contact); rows at the current state
  (toi 0, separation > 0 for a speculative gap, < 0 for a penetration);
* IMPACT: apart before and overlapping now (also from within the margin when the pair
  closes faster than its resting speed, the solver's: ``restitution_threshold`` where the
  step's external change acts on one of the two): time of impact by bisection on the
  interpolated motion (lerp position, slerp orientation) to ``toi_tolerance``; point and
  normal at the time of impact, separation min(separation there, signed distance now);
* TUNNELLED: apart at both ends but conservative advancement (coal distances) finds a
  hit, then the same bisection; point, normal and separation (about 0) at the impact.

Internal faces of overlapping static shapes (boxes and half-spaces; a wall's end buried in
the wall it meets, as bins are built): a moving body's row with a static shape whose point
on that shape lies inside another static shape the body also has a row with, the two
normals opposed (cosine below -0.5: they would push the body against each other), is
dropped (when the body's point at its previous pose, on that face's plane, lies inside the
other shape too: a ball carried out past a corner beside a third wall keeps the face it
touched), so the other shape's row alone stops the body in the corner; so is such a row
whose point on the body lay behind that face at the body's previous pose (it reached the
face only through the other shape: a ball driven out past a corner where two walls end
together, to their end faces); when every such row of a body is buried, the least buried
one stays (``Detector::drop_buried_faces``).

A pair touching at the previous state that the step carried past each other keeps the
contact of the previous state, carried along with each body: when they are apart by more
than the margin now, or when the contact now faces more than 60 deg away from the one they
touched at (a ball driven into a wall it touches, farther in a step than half the wall is
thick, out of its far face or its end: it bounces off the face it touched).

A step budget (``max_pairs``, ``max_contacts``, as MuJoCo's nconmax) bounds each step's
work and memory: beyond it the pairs whose bounding spheres overlap deepest, then the
deepest rows, are kept (``budget`` says how many were dropped).

Pairs the collision filter drops (``CollisionFilter``: group and mask bits, ignored
pairs) are removed in the broad phase, half-spaces included: they never reach the narrow
phase, give no rows, and keep no stored manifold (the store holds the last step's pairs
only), so no warm-start impulse of theirs survives either.

The detector reads each body's current twist only to tell a fast approach from a slow
one; poses are the whole input otherwise.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from collres_ros.core import _native
from collres_ros.core.config import SOLVER_TUNING, SolverSettings
from collres_ros.core.shapes import (bounding_radius, collision_numbers, piece_spec,
                                     triangle_corners)
from collres_ros.core.types import (COMPOUND, SHAPE_KINDS, TRIANGLE_MESH, BodySpec,
                                    BodyStates, CollisionFilter, ContactSet)

IDENTITY = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0)   # a piece frame on the body frame

# What detection reads, named as in SolverSettings and in the compiled DetectionSettings.
DETECTION_FIELDS = ('speculative_margin', 'toi_tolerance', 'toi_max_iterations', 'ccd',
                    'linear_slop', 'restitution_threshold', 'max_pairs', 'max_contacts',
                    'max_contacts_per_pair')
# ... and the SOLVER_TUNING entries it reads, by the same names: the solver reads them
# too, all but DETECTION_ONLY's (the compiled solver has no field of their name).
DETECTION_TUNING = ('resting_factor', 'reuse_shift', 'margin_speed')
DETECTION_ONLY = ('reuse_shift', 'margin_speed')


class Detection:
    """The compiled detector of a fixed list of bodies, and the settings it reads."""

    def __init__(self, bodies: Sequence[BodySpec], settings: SolverSettings,
                 collision_filter: CollisionFilter | None = None) -> None:
        """``collision_filter`` default: every pair collides."""
        self.specs = list(bodies)
        shapes = [_shapes(index, spec) for index, spec in enumerate(self.specs)]
        columns = list(zip(*(row for rows in shapes for row in rows)))
        self._native = _native.Detector(*(list(column) for column in columns),
                                        bodies=len(self.specs))
        self.settings = settings
        self.collision_filter = collision_filter or CollisionFilter.default(len(self.specs))

    @property
    def settings(self) -> SolverSettings:
        return self._settings

    @settings.setter
    def settings(self, settings: SolverSettings) -> None:
        """New settings take effect at the next step (a new margin forgets the manifolds)."""
        self._settings = settings
        self._native.settings = detection_settings(settings)

    @property
    def collision_filter(self) -> CollisionFilter:
        return self._filter

    @collision_filter.setter
    def collision_filter(self, value: CollisionFilter) -> None:
        """A new filter takes effect at the next step (ValueError: not one entry per body)."""
        if len(value.group) != len(self.specs):
            raise ValueError(f'collision filter: {len(value.group)} bodies, the detector has '
                             f'{len(self.specs)}')
        self._native.set_filter(list(value.group), list(value.mask), list(value.ignored))
        self._filter = value

    def detect(self, previous: BodyStates, current: BodyStates,
               active: np.ndarray | None = None, threads: int = 1,
               dt: float = 0.0) -> ContactSet:
        """Contacts of the step ``previous`` -> ``current`` (see the module docstring).

        ``active`` (N,) bool: False marks a frozen body, held at its current pose over
        the whole step (its previous pose is ignored); it still collides. ``threads`` 1
        or 2 (``SOLVER_TUNING`` ``threads``): the pairs shared by two threads give the
        same bits. ``dt`` (s) the step's period: a pair at rest keeps at least
        ``margin_speed`` times it of the margin (0: a quarter of the margin alone).
        """
        rows = self._native.detect(*self._arrays(previous, current, active), threads=threads,
                                   dt=dt)
        return ContactSet(*rows)

    def hold_back(self, previous: BodyStates, answer: BodyStates,
                  active: np.ndarray | None = None) -> np.ndarray:
        """(N,) per body, the fraction of its motion from ``previous`` to ``answer`` (its
        corrected state) that it keeps against fixed shapes: 1 unless the answer took it
        deeper into one than it was at ``previous`` by more than the slop, else the latest
        fraction before that (as Box2D v3's continuous step; ``Detector::hold_back``)."""
        return self._native.hold_back(*self._arrays(previous, answer, active))

    @property
    def budget(self) -> tuple[int, int]:
        """What the step budget dropped in the last ``detect``: (broad-phase pairs never
        queried, contact rows beyond ``max_contacts``); (0, 0) within the budget."""
        pairs, rows = self._native.budget()
        return int(pairs), int(rows)

    @property
    def thread_runs(self) -> tuple[int, int, int, int]:
        """The second thread's part in the detects so far (``threads`` 2, 64 shapes or more):
        (detects posted for two threads, of those run paired, their chunks, of those the
        chunks the second thread ran); ``World.thread_runs``."""
        paired, runs = self._native.runs
        helped, chunks = self._native.helped
        return int(runs), int(paired), int(chunks), int(helped)

    def candidate_pairs(self, previous: BodyStates, current: BodyStates,
                        active: np.ndarray | None = None) -> list[tuple[int, int]]:
        """Broad-phase pairs (a < b) whose swept bounds overlap (for tests and tools)."""
        return self._native.candidate_pairs(*self._arrays(previous, current, active))

    def reset(self) -> None:
        """Forget the stored manifolds (e.g. after bodies were teleported)."""
        self._native.reset()

    @staticmethod
    def _arrays(previous: BodyStates, current: BodyStates,
                active: np.ndarray | None) -> tuple:
        # float64 as they are: strided views (of (N, 13) rows) are gathered by the binding
        mask = None if active is None else np.ascontiguousarray(active, dtype=np.uint8)
        return (*(np.asarray(a, np.float64) for a in (
            previous.position, previous.orientation, current.position, current.orientation,
            current.linear, current.angular, previous.linear, previous.angular)), mask)


def detection_settings(settings: SolverSettings) -> _native.DetectionSettings:
    """The compiled detector's settings from the solver settings: each of its fields by name
    (SolverSettings has a field of every name but DETECTION_TUNING's, SOLVER_TUNING's)."""
    native = _native.DetectionSettings()
    for name in DETECTION_FIELDS:
        setattr(native, name, getattr(settings, name))
    for spec in SOLVER_TUNING:
        if spec.name in DETECTION_TUNING:
            setattr(native, spec.name, spec.default)
    return native


def _shapes(index: int, spec: BodySpec) -> list[tuple]:
    """The compiled detector's shapes of body ``index``: one, or one per piece of a compound
    or per triangle of a triangle mesh (kind, sizes, vertices, bounding radius about the
    body origin, static, body, piece, piece pose in the body frame)."""
    fixed = bool(spec.static or spec.shape == 'plane')
    if spec.shape == TRIANGLE_MESH:
        corners = triangle_corners(spec)
        reach = np.linalg.norm(corners, axis=2).max(axis=1)
        kind = SHAPE_KINDS.index('triangle')
        return [(kind, [], triangle.reshape(-1).tolist(), float(r), fixed, index, number,
                 IDENTITY) for number, (triangle, r) in enumerate(zip(corners, reach))]
    if spec.shape != COMPOUND:
        size, points = collision_numbers(spec)
        return [(SHAPE_KINDS.index(spec.shape), size, points, bounding_radius(spec), fixed,
                 index, 0, IDENTITY)]
    rows = []
    for number, piece in enumerate(spec.pieces):
        alone = piece_spec(spec, piece)
        size, points = collision_numbers(alone)
        reach = float(np.linalg.norm(piece.position)) + bounding_radius(alone)
        rows.append((SHAPE_KINDS.index(piece.shape), size, points, reach, fixed, index, number,
                     (*piece.position, *piece.orientation)))
    return rows
