"""Data types shared by the stages of the contact-resolution core.

Conventions used everywhere in ``collres_ros.core``:

* Frames: every pose, velocity, point and normal is in the world frame.
* Quaternions are ``x, y, z, w`` as in ROS, unit length.
* A body's origin is its centre of mass; ``linear`` is the velocity of that
  origin (m/s), ``angular`` the angular velocity (rad/s), both world frame.
* Arrays are indexed by body index (the order of the body specs given to the
  world) or by contact index; units are SI (m, s, kg, N s).
* Normals are unit vectors pointing from body A towards body B.

This module holds data only: no coal, no ROS.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import IntEnum
from typing import Sequence

import numpy as np

from collres_ros.core.config import (ALL_COLLISION_BITS, DEFAULT_COLLISION_GROUP,
                                     ROLLING_RESISTANCE, TORSIONAL_FRICTION)


class ContactState(IntEnum):
    """What a contact did this step (values equal the Contact.msg constants)."""

    IMPACT = 1    # approach faster than its resting speed: it bounced
    RESTING = 2   # slower, no tangential motion, no friction needed
    SLIDING = 3   # friction at the cone limit (kinetic coefficient)
    STICKING = 4  # friction inside the static cone held the contact still
    SLEEPING = 5  # a contact of a sleeping island, held as it was when the island fell asleep


class ContactKind(IntEnum):
    """How the narrow phase classified a contact's pair (see ``collision.py``)."""

    PERSISTENT = 0  # overlapping (or within the speculative margin) at the previous state
    IMPACT = 1      # separated before, overlapping now: time of impact by bisection
    TUNNELLED = 2   # separated at both ends, the sweep hits: advancement + bisection


@dataclass
class BodyStates:
    """States of all N bodies at one time; world frame, SI units."""

    position: np.ndarray      # (N, 3) m, centre of mass
    orientation: np.ndarray   # (N, 4) unit quaternion x, y, z, w
    linear: np.ndarray        # (N, 3) m/s
    angular: np.ndarray       # (N, 3) rad/s

    @property
    def count(self) -> int:
        return int(self.position.shape[0])

    def copy(self) -> 'BodyStates':
        return BodyStates(self.position.copy(), self.orientation.copy(),
                          self.linear.copy(), self.angular.copy())

    @staticmethod
    def zeros(count: int) -> 'BodyStates':
        orientation = np.zeros((count, 4))
        orientation[:, 3] = 1.0
        return BodyStates(np.zeros((count, 3)), orientation,
                          np.zeros((count, 3)), np.zeros((count, 3)))


@dataclass
class ContactSet:
    """Contact points found by the narrow phase, M of them, before solving.

    ``point`` is in the world frame at the contact configuration (the time of
    impact for IMPACT/TUNNELLED contacts, the current state for PERSISTENT), midway
    between the two surfaces: for a PERSISTENT contact against an immovable body the
    solver moves it to the movable body's own surface (``point - separation / 2 *
    normal`` for A, ``point + separation / 2 * normal`` for B: friction's and the spin
    rows' levers).
    ``separation`` is the signed gap along the normal at the current state
    (negative when penetrating, m); ``depth = max(0, -separation)``.
    ``toi`` is the time of impact as a fraction of the step in [0, 1]
    (0 for PERSISTENT contacts: they touch from the start of the step).
    ``feature`` identifies the point within its pair across steps for warm
    starting (e.g. the index in a face-on-face manifold); the pair itself is
    identified by (body_a, body_b) with body_a < body_b.
    ``manifolds`` (K, 4) int64, one row (body_a, body_b, first, count) per manifold:
    the rows ``first .. first + count - 1``, all of that pair, found together (1-4
    points sharing a contact patch); the manifolds tile the M rows in order, and the
    solver solves each as one constraint. One pair may have several manifolds (e.g.
    pieces of compound bodies). Hand-made sets take ``pair_manifolds``. ``piece_a`` /
    ``piece_b``: the index of the touching piece among each compound body's
    ``BodySpec.pieces`` (0 for a body of one shape; None: all 0).
    """

    body_a: np.ndarray        # (M,) int64
    body_b: np.ndarray        # (M,) int64
    point: np.ndarray         # (M, 3) m, world
    normal: np.ndarray        # (M, 3) unit, world, from A to B
    separation: np.ndarray    # (M,) m, signed, < 0 when penetrating
    toi: np.ndarray           # (M,) fraction of the step in [0, 1]
    kind: np.ndarray          # (M,) int8, ContactKind
    feature: np.ndarray       # (M,) int64
    manifolds: np.ndarray     # (K, 4) int64: body_a, body_b, first row, row count
    piece_a: np.ndarray | None = None   # (M,) int32, or None: every piece 0
    piece_b: np.ndarray | None = None

    @property
    def count(self) -> int:
        return int(self.body_a.shape[0])

    def pieces(self) -> tuple[np.ndarray, np.ndarray]:
        """(piece_a, piece_b) as (M,) int32 arrays (zeros when not given)."""
        zeros = np.zeros(self.count, np.int32)
        return (zeros if self.piece_a is None else self.piece_a,
                zeros if self.piece_b is None else self.piece_b)

    def select(self, keep: np.ndarray) -> 'ContactSet':
        """The rows where the (M,) bool mask ``keep`` is true, copied; each manifold keeps
        its kept rows (none: it goes)."""
        keep = np.asarray(keep, bool)
        counts = self.manifolds[:, 3] if self.count else np.zeros(0, np.int64)
        owner = np.repeat(np.arange(len(counts)), counts)
        kept = np.bincount(owner[keep], minlength=len(counts)).astype(np.int64)
        spans = self.manifolds[kept > 0].copy()
        spans[:, 3] = kept[kept > 0]
        spans[:, 2] = np.cumsum(spans[:, 3]) - spans[:, 3]
        piece_a, piece_b = self.pieces()
        return ContactSet(self.body_a[keep], self.body_b[keep], self.point[keep],
                          self.normal[keep], self.separation[keep], self.toi[keep],
                          self.kind[keep], self.feature[keep], spans, piece_a[keep],
                          piece_b[keep])

    @staticmethod
    def joined(a: 'ContactSet', b: 'ContactSet') -> 'ContactSet':
        """The rows (and manifolds) of ``a`` then those of ``b``."""
        shifted = b.manifolds.copy()
        shifted[:, 2] += a.count
        pieces = [np.concatenate([x, y]) for x, y in zip(a.pieces(), b.pieces())]
        return ContactSet(*(np.concatenate([getattr(a, f), getattr(b, f)])
                            for f in ('body_a', 'body_b', 'point', 'normal', 'separation',
                                      'toi', 'kind', 'feature')),
                          np.concatenate([a.manifolds, shifted]), *pieces)

    @property
    def depth(self) -> np.ndarray:
        return np.maximum(0.0, -self.separation)

    @staticmethod
    def empty() -> 'ContactSet':
        return ContactSet(
            np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((0, 3)),
            np.zeros((0, 3)), np.zeros(0), np.zeros(0), np.zeros(0, np.int8),
            np.zeros(0, np.int64), np.zeros((0, 4), np.int64))


def pair_manifolds(body_a: np.ndarray, body_b: np.ndarray) -> np.ndarray:
    """``ContactSet.manifolds`` of a hand-made set: each run of consecutive rows of one
    pair is one manifold, (K, 4) int64 (body_a, body_b, first, count)."""
    a, b = np.asarray(body_a, np.int64), np.asarray(body_b, np.int64)
    if a.shape[0] == 0:
        return np.zeros((0, 4), np.int64)
    first = np.flatnonzero(np.r_[True, (a[1:] != a[:-1]) | (b[1:] != b[:-1])])
    count = np.diff(np.r_[first, a.shape[0]])
    return np.stack([a[first], b[first], first, count], axis=1).astype(np.int64)


@dataclass
class ContactReport:
    """Solved contacts of one step, M of them (ContactSet plus results)."""

    contacts: ContactSet
    normal_impulse: np.ndarray    # (M,) N s, >= 0, applied to B along +normal (to A along -normal)
    # (M, 3) N s, world, applied to B (opposite on A), perpendicular to `normal`
    friction_impulse: np.ndarray
    state: np.ndarray             # (M,) uint8, ContactState

    @staticmethod
    def empty() -> 'ContactReport':
        return ContactReport(ContactSet.empty(), np.zeros(0), np.zeros((0, 3)),
                             np.zeros(0, np.uint8))


@dataclass(frozen=True)
class Rejection:
    """One input that was refused, and why (reason is a short stable key)."""

    body: str      # body name ('' when the whole input was refused)
    reason: str    # e.g. 'non_finite', 'zero_quaternion', 'unknown_body', 'time_backwards'
    detail: str    # one human-readable line


@dataclass
class StepResult:
    """Output of one world step."""

    states: BodyStates                 # corrected, non-penetrating states of all N bodies
    report: ContactReport
    rejected: list[Rejection] = field(default_factory=list)
    # (N,) bool: answered as asleep (held pose, zero twist; ``core.sleep``); None: none
    sleeping: np.ndarray | None = None
    # the report is the last step's, array for array (every island that touches anything
    # asleep, the same ones held: ``core.sleep``): what was built from the last one holds
    unchanged: bool = False
    # (N, 13) the corrected states as rows (position, orientation, linear, angular);
    # ``states`` are its column views (None: ``states`` stand alone)
    values: np.ndarray | None = None


SHAPE_KINDS = ('sphere', 'box', 'capsule', 'cylinder', 'cone', 'plane', 'convex', 'triangle')
# A body of several convex pieces (``BodySpec.pieces``); not a code of the compiled core.
COMPOUND = 'compound'
# A static body that is the surface of a triangle mesh (``BodySpec.points``: three corners a
# triangle); each triangle is a 'triangle' of the compiled core, one-sided (src/shapes.h).
TRIANGLE_MESH = 'triangle_mesh'


@dataclass(frozen=True)
class CollisionFilter:
    """Which pairs of the N bodies may collide: bitmasks and ignored pairs.

    As Box2D's category and mask bits and Gazebo's collide_bitmask: bodies a
    and b collide when ``group[a] & mask[b]`` and ``group[b] & mask[a]`` are
    both non-zero (both must accept the other; MuJoCo's contype/conaffinity
    needs only one side); and, as MoveIt's allowed collision matrix, never
    when (a, b) is in ``ignored``. Bits are integers in [0, ALL_COLLISION_BITS];
    ``ignored`` holds body indices (a < b), sorted, each pair once. The
    default (every group DEFAULT_COLLISION_GROUP, every mask all bits, nothing
    ignored) lets every pair collide.
    """

    group: tuple[int, ...]                    # (N,) the bits a body is in
    mask: tuple[int, ...]                     # (N,) the bits it collides with
    ignored: tuple[tuple[int, int], ...] = ()

    def __post_init__(self) -> None:
        if len(self.group) != len(self.mask):
            raise ValueError('collision filter: one group and one mask per body')
        for bits in self.group + self.mask:
            if isinstance(bits, bool) or not isinstance(bits, int) \
                    or not 0 <= bits <= ALL_COLLISION_BITS:
                raise ValueError(f'collision filter: bits must be integers in '
                                 f'[0, {ALL_COLLISION_BITS:#x}] (got {bits!r})')
        count = len(self.group)
        pairs = sorted({(min(a, b), max(a, b)) for a, b in self.ignored})
        if any(a == b or a < 0 or b >= count for a, b in pairs):
            raise ValueError(f'collision filter: ignored pairs must be two distinct bodies of '
                             f'{count} (got {list(self.ignored)})')
        object.__setattr__(self, 'ignored', tuple(pairs))

    @staticmethod
    def default(count: int) -> 'CollisionFilter':
        """Every pair of ``count`` bodies collides."""
        return CollisionFilter((DEFAULT_COLLISION_GROUP,) * count, (ALL_COLLISION_BITS,) * count)

    def collides(self, a: int, b: int) -> bool:
        """Whether bodies ``a`` != ``b`` may collide (the compiled broad phase's rule)."""
        return (self.group[a] & self.mask[b] != 0 and self.group[b] & self.mask[a] != 0
                and (min(a, b), max(a, b)) not in self.ignored)

    def with_body(self, index: int, group: int | None = None,
                  mask: int | None = None) -> 'CollisionFilter':
        """A copy with one body's group and/or mask changed."""
        groups, masks = list(self.group), list(self.mask)
        groups[index] = groups[index] if group is None else group
        masks[index] = masks[index] if mask is None else mask
        return CollisionFilter(tuple(groups), tuple(masks), self.ignored)

    def ignoring(self, *pairs: tuple[int, int]) -> 'CollisionFilter':
        """A copy that also ignores these pairs of body indices (either order)."""
        return CollisionFilter(self.group, self.mask, self.ignored + tuple(pairs))


@dataclass(frozen=True)
class Piece:
    """One convex piece of a compound body, placed in the body frame.

    ``shape``, ``size`` and ``points`` as a ``BodySpec``'s (any shape but a
    plane); the piece's own frame (its shape frame: origin at its centre, a
    cone's at its centre of mass) sits at ``position`` (m) with ``orientation``
    (unit quaternion x, y, z, w) in the body frame. ``name`` names it in
    contacts and errors.
    """

    name: str
    shape: str
    size: tuple[float, ...] = ()
    points: tuple[tuple[float, float, float], ...] = ()
    position: tuple[float, float, float] = (0.0, 0.0, 0.0)
    orientation: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 1.0)


@dataclass(frozen=True)
class BodySpec:
    """What a body is: shape, mass properties and material (body frame = shape frame).

    ``size`` by shape: sphere (r,); box (x, y, z) full edges; capsule, cylinder,
    cone (r, length) along the body z axis; plane (nx, ny, nz, d): the
    half-space n.x <= d in the body frame (static only); convex: ``points``
    (K, 3) in the body frame, ``size`` unused; compound (``COMPOUND``): the
    convex ``pieces``, ``size`` and ``points`` unused (uniform density over the
    pieces' volumes); triangle mesh (``TRIANGLE_MESH``, static only): ``points``
    (3 T, 3) the corners of its T triangles, three by three, counter-clockwise seen
    from the front (the side bodies touch: a bin's inside). ``mass`` in kg is ignored for
    static bodies (infinite mass). ``inertia`` (ixx, iyy, izz) in kg m^2 about
    the origin in the body frame, or None to derive it from shape and mass.
    """

    name: str
    shape: str
    size: tuple[float, ...] = ()
    static: bool = False
    mass: float = 1.0
    inertia: tuple[float, float, float] | None = None
    restitution: float = 0.5
    static_friction: float = 0.5
    kinetic_friction: float = 0.3
    points: tuple[tuple[float, float, float], ...] = ()
    rolling_resistance: float = ROLLING_RESISTANCE      # see config.BODY_PARAMS
    torsional_friction: float = TORSIONAL_FRICTION
    pieces: tuple[Piece, ...] = ()


@dataclass(frozen=True)
class BodyInput:
    """One body's published state for one step, as received (not yet validated).

    ``frame_id``: frame of the pose (must be the world frame; '' counts as the
    world frame). ``twist_frame_id``: frame of the twist: the world frame (or
    '') for a world-frame twist, the body's own name for a body-frame twist
    (linear velocity of the origin and angular velocity, both expressed in the
    body axes). Position m, orientation x, y, z, w, linear m/s, angular rad/s.
    """

    name: str
    position: tuple[float, float, float]
    orientation: tuple[float, float, float, float]
    linear: tuple[float, float, float]
    angular: tuple[float, float, float]
    frame_id: str = ''
    twist_frame_id: str = ''


@dataclass
class InputBatch:
    """K bodies' published states for one step as arrays (what the CDR codec decodes).

    ``values`` (K, 13): position (m), orientation (x, y, z, w), linear (m/s),
    angular (rad/s); ``frame_id`` / ``twist_frame_id``: one frame for all
    bodies or one per body, with the meaning of ``BodyInput``'s fields.
    """

    names: Sequence[str]
    values: np.ndarray
    frame_id: str | Sequence[str] = ''
    twist_frame_id: str | Sequence[str] = ''

    @property
    def count(self) -> int:
        return len(self.names)

    def __len__(self) -> int:
        return len(self.names)

    @staticmethod
    def of(inputs: Sequence[BodyInput]) -> 'InputBatch':
        """The batch of a list of BodyInputs (same order)."""
        values = np.array([i.position + i.orientation + i.linear + i.angular for i in inputs],
                          dtype=float).reshape(len(inputs), 13)
        return InputBatch([i.name for i in inputs], values, [i.frame_id for i in inputs],
                          [i.twist_frame_id for i in inputs])
