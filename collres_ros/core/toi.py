"""Time of impact over one step: bisection and conservative advancement.

Time is the fraction s of the step in [0, 1]: s = 0 is the previous state,
s = 1 the current one. A body moves by lerp of its position and slerp of its
orientation (``Motion``). Both searches take the pair query as a function of
s, so they are pure and testable without coal.
"""

from __future__ import annotations

import math
from typing import Callable

import coal
import numpy as np

from collres_ros.core import rotation


class Motion:
    """Interpolated pose of one body over the step, as a reusable coal transform."""

    __slots__ = ('p0', 'p1', 'q0', 'q1', 'r0', 'r1', 'offset', 'transform', '_theta')

    def __init__(self, p0: np.ndarray, p1: np.ndarray, q0: np.ndarray, q1: np.ndarray,
                 offset: np.ndarray, r0: np.ndarray | None = None,
                 r1: np.ndarray | None = None) -> None:
        """Positions (3,) m, unit quaternions (4,) x, y, z, w at s = 0 and s = 1; the coal
        geometry's origin at ``offset`` (3,) m in the body frame; rotations if known."""
        self.p0, self.p1, self.offset = p0, p1, offset
        self.q0 = q0
        self.q1 = -q1 if float(np.dot(q0, q1)) < 0.0 else q1   # the shorter arc
        self.r0 = rotation.to_matrix(q0) if r0 is None else r0
        self.r1 = rotation.to_matrix(q1) if r1 is None else r1
        self._theta = math.acos(min(1.0, abs(float(np.dot(q0, q1)))))
        self.transform = coal.Transform3s()

    def rotation_at(self, s: float) -> np.ndarray:
        """Rotation (3, 3) at fraction ``s`` of the step (slerp)."""
        if s <= 0.0 or self._theta < 1e-12:
            return self.r0 if s < 1.0 or self._theta < 1e-12 else self.r1
        if s >= 1.0:
            return self.r1
        theta = self._theta
        if theta < 1e-6:
            w0, w1 = 1.0 - s, s
        else:
            w0 = math.sin((1.0 - s) * theta) / math.sin(theta)
            w1 = math.sin(s * theta) / math.sin(theta)
        q = w0 * self.q0 + w1 * self.q1
        return rotation.to_matrix(q / np.linalg.norm(q))

    def position_at(self, s: float) -> np.ndarray:
        """Position (3,) m of the body origin at fraction ``s`` (lerp)."""
        return self.p0 + s * (self.p1 - self.p0)

    def at(self, s: float) -> coal.Transform3s:
        """Pose of the body's coal geometry at fraction ``s`` (world frame)."""
        r = self.rotation_at(s)
        self.transform.setTransform(r, self.position_at(s) + r @ self.offset)
        return self.transform


def bisect(overlaps: Callable[[float], bool], s0: float, s1: float, tolerance: float,
           max_iterations: int) -> tuple[float, float]:
    """Shrink [s0, s1] (apart at s0, overlapping at s1) until shorter than ``tolerance``
    or after ``max_iterations`` halvings; returns the final (s0, s1)."""
    for _ in range(max_iterations):
        if s1 - s0 <= tolerance:
            break
        middle = 0.5 * (s0 + s1)
        if overlaps(middle):
            s1 = middle
        else:
            s0 = middle
    return s0, s1


def advance(distance: Callable[[float], float], overlaps: Callable[[float], bool],
            motion_bound: float, tolerance: float, max_iterations: int
            ) -> tuple[float, float] | None:
    """Conservative advancement from s = 0 for a pair apart at s = 0.

    ``motion_bound`` (m) bounds how far any point of one body moves relative to
    the other over the whole step, so the pair cannot touch before
    s + distance(s) / motion_bound. Returns a bracket (s0, s1), apart at s0 and
    overlapping at s1, or None when the pair stays apart over the step.
    """
    if not motion_bound > 0.0 or not np.isfinite(motion_bound):
        return None
    s = 0.0
    probe = max(4.0 * tolerance / motion_bound, 1e-12)
    for _ in range(max_iterations):
        gap = distance(s)
        if gap <= tolerance:
            # within ``tolerance`` of contact: a little later they overlap, or they graze
            s1 = min(1.0, s + probe)
            if overlaps(s1):
                return s, s1
            s = s1
        else:
            s += gap / motion_bound
        if s >= 1.0:
            return None
    return None
