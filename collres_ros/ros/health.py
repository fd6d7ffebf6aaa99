"""The level and message of /diagnostics, from a recent window of counts (no ROS import).

As diagnostic_updater's frequency and timestamp statuses do, the level says
what is wrong *now*: it is computed from the counts of the last
``window_reports`` reports (5 diagnostics periods), so it returns to OK once
a fault is over. The totals since start stay available as values (the
caller reports them). Levels (``diagnostic_msgs/DiagnosticStatus``):

* ``STALE`` (3): no input for longer than the stale timeout (or none yet):
  there is nothing current to judge (with ``min_rate`` set this is an
  ``ERROR`` instead: inputs were expected);
* ``ERROR`` (2): the solver produced a non-finite result in the window, or
  inputs arrived and no body was served (every input refused), or no step at
  all while ``min_rate`` expects them;
* ``WARN`` (1): inputs refused or lost in the window, per-body steps dropped,
  stale bodies, per-body inputs that never pair, a slop that cannot work,
  or a step rate below ``min_rate``;
* ``OK`` (0) otherwise.

Fresh starts (``time_backwards``, ``large_gap``) and clock jumps are
notices, not faults: they are named in the message but leave the level OK,
unless they are sustained: fresh starts in at least ``TIME_JUMP_WARN_FRACTION``
of the window's steps (two clocks interleaved on one topic, a source whose time
keeps jumping) are a WARN naming that cause, since every such step runs
without a sweep or a warm start (as tf2 and robot_localization warn on
repeated time jumps).
"""

from __future__ import annotations

from collections import Counter, deque
from dataclasses import dataclass
from typing import Mapping, Optional, Sequence

from collres_ros.core.config import TIME_JUMP_WARN_FRACTION

OK, WARN, ERROR, STALE = 0, 1, 2, 3
LEVEL_NAMES = {OK: 'OK', WARN: 'WARN', ERROR: 'ERROR', STALE: 'STALE'}
WINDOW_REPORTS = 5
# Keys of the totals that are not refusals
ACTIVITY = ('steps', 'contacts', 'inputs', 'served', 'lost', 'sync_dropped')
NOTICES = ('time_backwards', 'large_gap', 'time_jump')
ERRORS = ('non_finite_result',)
JUMP_MIN_STEPS = 10   # steps in the window before sustained time jumps are judged


@dataclass(frozen=True)
class Status:
    """One report's verdict: level (OK..STALE), a one-line message, the window's counts."""

    level: int
    message: str
    recent: Mapping[str, int]
    window_s: float
    rate_hz: float


def _counts_text(counts: Mapping[str, int]) -> str:
    return ', '.join(f'{k} {v}' for k, v in sorted(counts.items()))


class Health:
    """Window of per-report count increments, and the verdict over it."""

    def __init__(self, window_reports: int = WINDOW_REPORTS) -> None:
        self.window_reports = window_reports
        self._window: deque[tuple[float, Counter[str]]] = deque(maxlen=window_reports)
        self._previous: Counter[str] = Counter()
        self._last_input_s: Optional[float] = None
        self._started_s: Optional[float] = None

    def update(self, now_s: float, totals: Mapping[str, int], elapsed_s: float) -> None:
        """Add one report period: ``totals`` since start (steps, inputs, served, lost,
        refusals and notices by reason), ``elapsed_s`` the period's length (s)."""
        if self._started_s is None:
            self._started_s = now_s - elapsed_s
        delta: Counter[str] = Counter()
        for key, value in totals.items():
            step = int(value) - self._previous.get(key, 0)
            if step > 0:
                delta[key] = step
        self._previous = Counter({k: int(v) for k, v in totals.items()})
        self._window.append((max(float(elapsed_s), 0.0), delta))
        if delta.get('inputs', 0) > 0:
            self._last_input_s = now_s

    def recent(self) -> Counter[str]:
        """The counts of the window (sum of its reports' increments)."""
        total: Counter[str] = Counter()
        for _, delta in self._window:
            total.update(delta)
        return total

    def status(self, now_s: float, stale_after_s: float, min_rate: float = 0.0,
               stale: Sequence[str] = (), unpaired: str = '', slop_problem: str = '',
               names: str = '') -> Status:
        """The verdict at ``now_s`` (see module docstring); ``names``: stale bodies, cut."""
        recent = self.recent()
        window_s = sum(e for e, _ in self._window)
        rate = recent['steps'] / window_s if window_s > 0 else 0.0
        refused = {k: v for k, v in recent.items() if k not in ACTIVITY + NOTICES}
        notices = {k: v for k, v in recent.items() if k in NOTICES}
        errors: list[str] = []
        warnings: list[str] = []
        since = now_s - (self._last_input_s if self._last_input_s is not None
                         else (self._started_s if self._started_s is not None else now_s))
        silent = since > stale_after_s or self._last_input_s is None
        if any(k in ERRORS for k in refused):
            errors.append('the solver produced non-finite states')
        if recent['inputs'] and recent['steps'] and not recent['served']:
            errors.append('every input was refused')
        if min_rate > 0.0 and not recent['steps'] and window_s > 0:
            errors.append(f'no step for {window_s:.1f} s (min_rate {min_rate:g} Hz)')
        elif min_rate > 0.0 and rate < min_rate and window_s > 0:
            warnings.append(f'rate {rate:.1f} Hz below min_rate {min_rate:g} Hz')
        if unpaired and not recent['steps']:
            warnings.append(unpaired)
        if slop_problem:
            warnings.append(slop_problem)
        if refused:
            warnings.append('refused: ' + _counts_text(refused))
        if recent['lost']:
            warnings.append(f'lost before taken: {recent["lost"]}')
        if recent['sync_dropped']:
            warnings.append(f'incomplete per-body steps dropped: {recent["sync_dropped"]}')
        if stale:
            warnings.append('stale: ' + (names or ', '.join(stale)))
        jumps = sum(notices.values())
        steps = recent['steps']
        if steps >= JUMP_MIN_STEPS and jumps >= TIME_JUMP_WARN_FRACTION * steps:
            warnings.append(f'time jumps: {jumps} fresh starts in {recent["steps"]} steps, the '
                            'stamps come from more than one clock (two publishers on one '
                            'topic?) or keep jumping; no sweep or warm start for them')
        message = f'{recent["steps"]} steps in the last {window_s:.1f} s, {rate:.1f} Hz'
        if silent and not (min_rate > 0.0):
            level = STALE
            what = 'no input yet' if self._last_input_s is None else f'no input for {since:.1f} s'
            parts = [what] + errors + warnings
        elif errors:
            level, parts = ERROR, errors + warnings
        elif warnings:
            level, parts = WARN, warnings
        else:
            level, parts = OK, []
        if notices:
            parts.append('fresh starts: ' + _counts_text(notices))
        if parts:
            message += '; ' + '; '.join(parts)
        return Status(level, message, dict(recent), window_s, rate)
