"""Input checks at the edge of the core: refuse bad body states before the broad phase.

Every refused input becomes a ``Rejection`` with a stable reason key (counted
in /diagnostics and in replay summaries):

* ``unknown_body``: the name is not in the scene's ``bodies``.
* ``duplicate_body``: the name appears more than once in one step (every copy is
  refused: there is no telling which one is right).
* ``wrong_frame``: the pose is not in the world frame, or the twist is neither
  in the world frame nor in the body's own frame (frame_id = the body name).
  An empty frame_id counts as the world frame.
* ``non_finite``: NaN or Inf anywhere in the pose or twist.
* ``out_of_range``: a position coordinate beyond ``POSITION_LIMIT`` (1e9 m) or a
  velocity component beyond ``VELOCITY_LIMIT`` (1e9 m/s, rad/s): far outside any
  scene, and products of such numbers would overflow.
* ``zero_quaternion``: orientation norm below ``ZERO_NORM``.
* ``non_unit_quaternion``: norm off 1 by more than the tolerance (within it the
  quaternion is normalised silently).
* ``repeated_stamp``: the body already has a state at this very stamp (dt = 0).

History notices (the input is used, as a fresh start: previous = current):
``time_backwards`` (stamp older than the body's last one) and ``large_gap``
(more than ``max_dt`` since the body's last state). ``stale`` marks a known
body that has not been updated for longer than a timeout.

Pure functions over numpy arrays; no ROS, no coal.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field
from typing import Mapping, Sequence

import numpy as np

from collres_ros.core.config import POSITION_LIMIT, VELOCITY_LIMIT
from collres_ros.core.rotation import to_matrix
from collres_ros.core.types import BodyInput, Rejection

ZERO_NORM = 1e-6              # quaternion norms below this are 'zero'
QUATERNION_TOLERANCE = 1e-3   # |norm - 1| up to this is normalised silently
NO_STAMP = -1                 # last-stamp value of a body never seen
NAME_SHOWN = 40               # characters of a name shown in a detail line


def shown_name(name: str, limit: int = NAME_SHOWN) -> str:
    """A body name as it goes into a log line: printable, one line, at most ``limit`` chars.

    A plain name (letters, digits, ``_``) is shown as is; anything else as its
    ``repr`` (so a newline cannot start a forged log line); both cut with ``...``.
    """
    text = name if name.isascii() and (name.replace('_', '').isalnum() or not name) \
        else repr(name)
    return text if len(text) <= limit else text[:limit - 3] + '...'


def _quoted(text: str, limit: int = NAME_SHOWN) -> str:
    shown = repr(text)
    return shown if len(shown) <= limit else shown[:limit - 3] + '...'


@dataclass
class CheckedInputs:
    """The accepted inputs of one step (K of them, in input order), world frame."""

    index: np.ndarray          # (K,) int64 body index
    position: np.ndarray       # (K, 3) m
    orientation: np.ndarray    # (K, 4) unit quaternion x, y, z, w (normalised)
    linear: np.ndarray         # (K, 3) m/s, world frame
    angular: np.ndarray        # (K, 3) rad/s, world frame
    twist_in_body: np.ndarray  # (K,) bool: the twist came (and goes back) in the body frame
    rejected: list[Rejection] = field(default_factory=list)


def check_inputs(inputs: Sequence[BodyInput], index_of: Mapping[str, int], world_frame: str,
                 quaternion_tolerance: float = QUATERNION_TOLERANCE) -> CheckedInputs:
    """Validate one step's inputs; body-frame twists are rotated into the world frame."""
    count = len(inputs)
    numbers = np.array([i.position + i.orientation + i.linear + i.angular for i in inputs],
                       dtype=float).reshape(count, 13)
    names = [i.name for i in inputs]
    repeats = Counter(names)
    world = ('', world_frame)
    twist_in_body = np.array([i.twist_frame_id == i.name and i.name not in world
                              for i in inputs], bool)
    finite = np.isfinite(numbers).all(axis=1)
    with np.errstate(over='ignore'):      # a huge quaternion has an infinite norm: refused
        norm = np.linalg.norm(np.where(np.isfinite(numbers[:, 3:7]), numbers[:, 3:7], 0.0),
                              axis=1)
    magnitude = np.abs(np.where(np.isfinite(numbers), numbers, 0.0))
    too_far = magnitude[:, 0:3].max(axis=1, initial=0.0) > POSITION_LIMIT
    too_fast = magnitude[:, 7:13].max(axis=1, initial=0.0) > VELOCITY_LIMIT

    rejected: list[Rejection] = []
    keep = np.zeros(count, bool)
    for k, item in enumerate(inputs):
        reason = ''
        if item.name not in index_of:
            reason, detail = 'unknown_body', 'not in the parameter `bodies`'
        elif repeats[item.name] > 1:
            reason, detail = 'duplicate_body', f'appears {repeats[item.name]} times in one step'
        elif item.frame_id not in world:
            reason, detail = 'wrong_frame', (f'pose frame {_quoted(item.frame_id)} is not the '
                                             f'world frame {world_frame!r}')
        elif item.twist_frame_id not in world and not twist_in_body[k]:
            reason, detail = 'wrong_frame', (f'twist frame {_quoted(item.twist_frame_id)} is '
                                             f'neither {world_frame!r} nor the body frame '
                                             f'{shown_name(item.name)!r}')
        elif not finite[k]:
            reason, detail = 'non_finite', 'NaN or Inf in pose or twist'
        elif too_far[k] or too_fast[k]:
            reason, detail = 'out_of_range', (
                f'position beyond {POSITION_LIMIT:g} m' if too_far[k] else
                f'velocity beyond {VELOCITY_LIMIT:g} m/s or rad/s')
        elif norm[k] < ZERO_NORM:
            reason, detail = 'zero_quaternion', 'orientation has zero norm'
        elif abs(norm[k] - 1.0) > quaternion_tolerance:
            reason, detail = 'non_unit_quaternion', (f'orientation norm {norm[k]:.6g} is off 1 '
                                                     f'by more than {quaternion_tolerance:g}')
        if reason:
            rejected.append(Rejection(item.name, reason, f'{shown_name(item.name)}: {detail}'))
        else:
            keep[k] = True

    good = numbers[keep]
    orientation = good[:, 3:7] / norm[keep, None]
    linear, angular = good[:, 7:10], good[:, 10:13]
    in_body = twist_in_body[keep]
    if in_body.any():
        rotation = to_matrix(orientation[in_body])
        linear = linear.copy()
        angular = angular.copy()
        linear[in_body] = np.einsum('kij,kj->ki', rotation, linear[in_body])
        angular[in_body] = np.einsum('kij,kj->ki', rotation, angular[in_body])
    index = np.array([index_of[n] for n, ok in zip(names, keep) if ok], np.int64)
    return CheckedInputs(index, good[:, 0:3].copy(), orientation, linear.copy(),
                         angular.copy(), in_body, rejected)


@dataclass
class StampCheck:
    """History of each accepted input against the step stamp (masks over the K inputs)."""

    repeated: np.ndarray    # stamp == last stamp: refuse (dt would be 0)
    fresh: np.ndarray       # start fresh: previous = current, warm start forgotten
    backwards: np.ndarray   # stamp < last stamp (subset of fresh)
    gap: np.ndarray         # stamp - last > max_dt (subset of fresh)


def check_stamps(last_stamp: np.ndarray, stamp_ns: int, max_dt_ns: int,
                 previous_step_ns: int) -> StampCheck:
    """Classify inputs by their body's last stamp (ns; ``NO_STAMP`` if never seen).

    A body is fresh when first seen, when time went backwards, after a gap
    longer than ``max_dt_ns``, or when its last state is not from the previous
    step (``previous_step_ns``): the interpolated motion would span a different
    interval than the step's dt.
    """
    seen = last_stamp != NO_STAMP
    repeated = seen & (last_stamp == stamp_ns)
    backwards = seen & (last_stamp > stamp_ns)
    gap = seen & (stamp_ns - last_stamp > max_dt_ns)
    fresh = ~repeated & (~seen | backwards | gap | (last_stamp != previous_step_ns))
    return StampCheck(repeated, fresh, backwards, gap)


def stale_bodies(last_stamp: np.ndarray, stamp_ns: int, timeout_ns: int,
                 dynamic: np.ndarray) -> np.ndarray:
    """Mask of dynamic bodies seen before but not updated for longer than ``timeout_ns``."""
    return dynamic & (last_stamp != NO_STAMP) & (stamp_ns - last_stamp > timeout_ns)
