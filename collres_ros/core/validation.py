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
* ``time_backwards``: the stamp is older than the body's last one (a timing glitch:
  nothing changes), unless the step before was refused so at an older stamp: then the
  source's clock runs on from an earlier time (a new run) and the input is used, as a
  fresh start (the Resolver decides: ``StampCheck.backwards``).

History notice (the input is used, as a fresh start: previous = current): ``large_gap``
(more than ``max_dt`` since the body's last state). ``stale`` marks a known
body that has not been updated for longer than a timeout.

Pure functions over numpy arrays (the usual step's test in one pass of the compiled core,
``_native.usual_inputs``); no ROS, no coal.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field
from typing import Mapping, Sequence

import numpy as np

from collres_ros.core import _native
from collres_ros.core.config import POSITION_LIMIT, VELOCITY_LIMIT
from collres_ros.core.rotation import to_matrix
from collres_ros.core.types import BodyInput, InputBatch, Rejection

ZERO_NORM = 1e-6              # quaternion norms below this are 'zero'
QUATERNION_TOLERANCE = 1e-3   # |norm - 1| up to this is normalised silently
NO_STAMP = -1                 # last-stamp value of a body never seen
NAME_SHOWN = 40               # characters of a name shown in a detail line
# |value| limits of an input row in check_inputs' usual step (position, orientation x, y, z,
# w, linear, angular), (1, 13); a row beyond them takes the detailed checks
_LIMITS = np.array([[POSITION_LIMIT] * 3 + [2.0] * 4 + [VELOCITY_LIMIT] * 6])


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
    # the scene rows of the K inputs as ``index``, or as the slice ``index`` is (the inputs
    # are a run of consecutive scene bodies in scene order): scatters and gathers by it
    # then move blocks instead of indexed rows
    rows: np.ndarray | slice | None = None
    # (K, 13) the same rows as one array (position, orientation, linear, angular): the four
    # fields above are its column views
    values: np.ndarray = field(default_factory=lambda: np.zeros((0, 13)))

    def __post_init__(self) -> None:
        if self.rows is None:
            self.rows = self.index

    @staticmethod
    def of(index: np.ndarray, values: np.ndarray, twist_in_body: np.ndarray,
           rejected: list[Rejection], rows: np.ndarray | slice | None = None
           ) -> 'CheckedInputs':
        """The accepted inputs of (K, 13) ``values``, the four fields views of it."""
        return CheckedInputs(index, values[:, 0:3], values[:, 3:7], values[:, 7:10],
                             values[:, 10:13], twist_in_body, rejected, rows, values)


def _per_body(frames: str | Sequence[str], count: int) -> list[str]:
    return [frames] * count if isinstance(frames, str) else list(frames)


class NameIndex:
    """Scene index of body names that remembers the last name list it looked up.

    A stream sends the same names in the same order every step: its lookup is then one
    comparison of the lists, not Python per body.
    """

    def __init__(self, index_of: Mapping[str, int]) -> None:
        self._index_of = dict(index_of)
        self._names: tuple[str, ...] | None = None
        self._answer: tuple[np.ndarray, Counter[str] | None] = (np.zeros(0, np.int64), None)
        self.plain = False   # the last list looked up: every name known, none repeated
        # the last list's index as a slice, when it is consecutive scene rows in order
        self.span: slice | None = None
        self.none = np.zeros(0, bool)   # (K,) False, read-only: a mask for the last list

    def lookup(self, names: Sequence[str]) -> tuple[np.ndarray, Counter[str] | None]:
        """(K,) index of each name (-1: unknown; read-only) and the repeated names' counts
        (None when every name is once)."""
        key = tuple(names)
        if key != self._names:
            index = np.array([self._index_of.get(n, -1) for n in key], np.int64)
            index.flags.writeable = False
            repeats = Counter(key) if len(set(key)) < len(key) else None
            self._names, self._answer = key, (index, repeats)
            self.plain = repeats is None and bool((index >= 0).all())
            run = len(index) > 0 and self.plain and bool(
                (index == np.arange(index[0], index[0] + len(index))).all())
            self.span = slice(int(index[0]), int(index[0]) + len(index)) if run else None
            self.none = np.zeros(len(index), bool)
            self.none.flags.writeable = False
        return self._answer


def check_inputs(inputs: Sequence[BodyInput] | InputBatch,
                 index_of: Mapping[str, int] | NameIndex, world_frame: str,
                 quaternion_tolerance: float = QUATERNION_TOLERANCE) -> CheckedInputs:
    """Validate one step's inputs; body-frame twists are rotated into the world frame.

    The checks run over whole arrays; a refused input gets the first reason of
    the module docstring's list that applies to it. ``index_of``: a ``NameIndex``
    to keep across steps (a mapping is looked up afresh).
    """
    batch = inputs if isinstance(inputs, InputBatch) else InputBatch.of(inputs)
    names = batch.names
    count = len(names)
    numbers = np.asarray(batch.values, dtype=float).reshape(count, 13)
    world = ('', world_frame)
    lookup = index_of if isinstance(index_of, NameIndex) else NameIndex(index_of)
    index, repeats = lookup.lookup(names)
    quaternion = numbers[:, 3:7]
    # the stream's usual step (nothing refused: the checks below would refuse nothing):
    # every name known and once, the world frame, then in one compiled pass every number
    # within its limit (NaN and Inf are not) and unit quaternions (the limit keeps their
    # squares finite), normalised as below (the same bits)
    if lookup.plain and count and isinstance(batch.frame_id, str) and batch.frame_id in world \
            and isinstance(batch.twist_frame_id, str) and batch.twist_frame_id in world:
        values = _native.usual_inputs(numbers, _LIMITS, min(quaternion_tolerance, 0.5))
        if values is not None:
            # the index and the mask are the lookup's, read-only
            return CheckedInputs.of(index, values, lookup.none, [], lookup.span)
    duplicate = np.array([repeats[n] > 1 for n in names], bool) if repeats \
        else np.zeros(count, bool)
    if isinstance(batch.frame_id, str):
        pose_ok = np.full(count, batch.frame_id in world)
    else:
        pose_ok = np.array([f in world for f in batch.frame_id], bool).reshape(count)
    twist_frames = batch.twist_frame_id
    if isinstance(twist_frames, str) and twist_frames in world:
        twist_in_body = np.zeros(count, bool)
        twist_ok = np.ones(count, bool)
    else:
        frames = _per_body(twist_frames, count)
        twist_in_body = np.array([f == n and n not in world for f, n in zip(frames, names)],
                                 bool).reshape(count)
        twist_ok = twist_in_body | np.array([f in world for f in frames], bool).reshape(count)
    finite = np.isfinite(numbers).all(axis=1)
    with np.errstate(over='ignore', invalid='ignore'):   # a huge quaternion: infinite norm
        norm = np.linalg.norm(quaternion, axis=1)
        magnitude = np.abs(numbers)   # NaN and Inf rows are refused as non_finite first
        too_far = (magnitude[:, 0:3] > POSITION_LIMIT).any(axis=1)
        too_fast = (magnitude[:, 7:13] > VELOCITY_LIMIT).any(axis=1)
        failing = [index < 0, duplicate, ~pose_ok, ~twist_ok, ~finite, too_far | too_fast,
                   norm < ZERO_NORM, np.abs(norm - 1.0) > quaternion_tolerance]
    refused = np.logical_or.reduce(failing) if count else np.zeros(0, bool)
    rejected: list[Rejection] = []
    if refused.any():
        code = np.select(failing, np.arange(len(failing)), -1)
        for k in np.flatnonzero(refused):
            name = names[k]
            reason, detail = _refusal(int(code[k]), k, name, batch, repeats, world_frame,
                                      bool(too_far[k]), float(norm[k]), quaternion_tolerance)
            rejected.append(Rejection(name, reason, f'{shown_name(name)}: {detail}'))
        keep = ~refused
        good, norm, index, in_body = numbers[keep], norm[keep], index[keep], twist_in_body[keep]
    else:
        good, in_body = numbers, twist_in_body
    values = good.copy()
    values[:, 3:7] /= norm[:, None]
    if in_body.any():
        rotation = to_matrix(values[in_body, 3:7])
        values[in_body, 7:10] = np.einsum('kij,kj->ki', rotation, good[in_body, 7:10])
        values[in_body, 10:13] = np.einsum('kij,kj->ki', rotation, good[in_body, 10:13])
    return CheckedInputs.of(np.array(index), values, in_body, rejected)


def _refusal(code: int, k: int, name: str, batch: InputBatch, repeats: Counter[str] | None,
             world_frame: str, too_far: bool, norm: float, tolerance: float
             ) -> tuple[str, str]:
    """(reason, detail) of refusal ``code`` (the order of ``check_inputs``' checks)."""
    if code == 0:
        return 'unknown_body', 'not in the parameter `bodies`'
    if code == 1:
        return 'duplicate_body', f'appears {repeats[name] if repeats else 2} times in one step'
    if code == 2:
        frame = _per_body(batch.frame_id, batch.count)[k]
        return 'wrong_frame', (f'pose frame {_quoted(frame)} is not the world frame '
                               f'{world_frame!r}')
    if code == 3:
        frame = _per_body(batch.twist_frame_id, batch.count)[k]
        return 'wrong_frame', (f'twist frame {_quoted(frame)} is neither {world_frame!r} nor '
                               f'the body frame {shown_name(name)!r}')
    if code == 4:
        return 'non_finite', 'NaN or Inf in pose or twist'
    if code == 5:
        return 'out_of_range', (f'position beyond {POSITION_LIMIT:g} m' if too_far else
                                f'velocity beyond {VELOCITY_LIMIT:g} m/s or rad/s')
    if code == 6:
        return 'zero_quaternion', 'orientation has zero norm'
    return 'non_unit_quaternion', (f'orientation norm {norm:.6g} is off 1 by more than '
                                   f'{tolerance:g}')


@dataclass
class StampCheck:
    """History of each accepted input against the step stamp (masks over the K inputs)."""

    repeated: np.ndarray    # stamp == last stamp: refuse (dt would be 0)
    fresh: np.ndarray       # start fresh: previous = current, warm start forgotten
    backwards: np.ndarray   # stamp < last stamp (subset of fresh)
    gap: np.ndarray         # stamp - last > max_dt (subset of fresh)
    usual: bool = False     # the stream's usual step: every mask all False


def check_stamps(last_stamp: np.ndarray, stamp_ns: int, max_dt_ns: int,
                 previous_step_ns: int, all_previous: bool = False) -> StampCheck:
    """Classify inputs by their body's last stamp (ns; ``NO_STAMP`` if never seen).

    A body is fresh when first seen, when time went backwards, after a gap
    longer than ``max_dt_ns``, or when its last state is not from the previous
    step (``previous_step_ns``): the interpolated motion would span a different
    interval than the step's dt. ``all_previous``: the caller knows that every
    ``last_stamp`` is ``previous_step_ns`` (they are not compared again).
    """
    if previous_step_ns != NO_STAMP and 0 < stamp_ns - previous_step_ns <= max_dt_ns \
            and (all_previous or (last_stamp == previous_step_ns).all()):   # the usual step
        none = _NONE.get(len(last_stamp))
        if none is None:
            if len(_NONE) > 16:
                _NONE.clear()
            none = _NONE[len(last_stamp)] = np.zeros(len(last_stamp), bool)
            none.flags.writeable = False
        return StampCheck(none, none, none, none, usual=True)
    seen = last_stamp != NO_STAMP
    repeated = seen & (last_stamp == stamp_ns)
    backwards = seen & (last_stamp > stamp_ns)
    gap = seen & (stamp_ns - last_stamp > max_dt_ns)
    fresh = ~repeated & (~seen | backwards | gap | (last_stamp != previous_step_ns))
    return StampCheck(repeated, fresh, backwards, gap)


_NONE: dict[int, np.ndarray] = {}   # (K,) False, read-only, by K: the usual step's masks


def stale_bodies(last_stamp: np.ndarray, stamp_ns: int, timeout_ns: int,
                 dynamic: np.ndarray) -> np.ndarray:
    """Mask of dynamic bodies seen before but not updated for longer than ``timeout_ns``."""
    return dynamic & (last_stamp != NO_STAMP) & (stamp_ns - last_stamp > timeout_ns)
