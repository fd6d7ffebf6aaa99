"""Group per-body pose and twist messages into resolution steps by stamp.

A step is complete when every required body has both a pose and a twist for
the same stamp (or, with a slop, stamps within ``slop_ns`` of the group's
first stamp, which becomes the step stamp). Required: every dynamic body that
is not stale; a body is stale when the newest stamp received from any body is
more than ``stale_timeout_ns`` past its own last one (a body never heard
from counts from the first stamp received). Static bodies join a step when
their pose arrived in time (their twist is optional: zero when absent).

A part never replaces a queued part of another stamp: a second pose of a body
within the slop of a group that already holds one starts a group of its own
(as message_filters' ApproximateTime never merges two messages of one topic).
A slop of half the observed publishing period or more cannot tell
neighbouring steps apart: ``slop_problem`` says so (the node warns).

Clock jumps. A stamp more than ``jump_ns`` (default: the stale timeout)
before or after the newest one is held as a *suspect*, not used: one stray
stamp must neither make every other body stale (far future) nor reset the
synchroniser (far past). When a second body (or the same body's next message
of the same kind) confirms the new time, it is used. Confirmed backwards, the
source's clock has jumped (a simulator restart, a bag played again): every
pending group and every body's history is forgotten. Confirmed forwards (a
pause, or messages lost upstream), nothing is forgotten: bodies left behind
turn stale. Either way ``time_jumps`` counts it and ``take_jump`` reports it
once so the caller can reset its own history. A suspect that is contradicted
(its body sends a normal stamp again) or never confirmed is refused and
counted in ``refused`` (``future_stamp`` or ``past_stamp``).

When a group completes, older pending groups can no longer be used and are
dropped (counted in ``dropped``), as are the oldest groups beyond
``max_pending``. ``unpaired`` says in words why nothing completes (poses
without twists, stamps that never match, silent bodies). No ROS import:
messages are opaque here.
"""

from __future__ import annotations

from collections import Counter, deque
from dataclasses import dataclass, field
from statistics import median
from typing import Any, Optional, Sequence

KINDS = ('pose', 'twist')
PERIOD_SAMPLES = 32        # stamp differences kept to estimate the publishing period
NAMES_SHOWN = 5            # names listed in a reason text, then "+N more"


@dataclass(eq=False)
class Group:
    """Messages of one step: ``parts[name] = {'pose': msg, 'twist': msg}``.

    ``stamps[name][kind]`` is the stamp (ns) each part came with.
    """

    stamp_ns: int
    parts: dict[str, dict[str, Any]] = field(default_factory=dict)
    stamps: dict[str, dict[str, int]] = field(default_factory=dict)
    paired: set[str] = field(default_factory=set)   # the names with both parts here

    def holds(self, name: str, kind: str) -> Optional[int]:
        """The stamp of the queued ``kind`` part of ``name``, None when there is none."""
        return self.stamps.get(name, {}).get(kind)


@dataclass(frozen=True)
class TimeJump:
    """A confirmed jump of the source's clock: the newest stamp before and the new one (ns)."""

    before_ns: int
    after_ns: int

    def text(self) -> str:
        delta = (self.after_ns - self.before_ns) * 1e-9
        way = 'backwards' if delta < 0 else 'forwards'
        return (f'input clock jumped {way} by {abs(delta):.6g} s (newest stamp '
                f'{self.before_ns * 1e-9:.9f} s, now {self.after_ns * 1e-9:.9f} s)')


def names_text(names: Sequence[str], limit: int = NAMES_SHOWN) -> str:
    """``a, b, c`` or ``a, b, c, d, e +3 more``: names in a log line stay short."""
    shown = ', '.join(cut(n) for n in names[:limit])
    return shown + (f' +{len(names) - limit} more' if len(names) > limit else '')


def cut(text: str, limit: int = 40) -> str:
    """``text`` cut to ``limit`` characters (with ``...``) for a log line."""
    return text if len(text) <= limit else text[:limit - 3] + '...'


class StampSync:
    """Exact (or approximate, within a slop) stamp synchroniser of per-body topics."""

    def __init__(self, dynamic: Sequence[str], static: Sequence[str] = (), slop_ns: int = 0,
                 stale_timeout_ns: int = 1_000_000_000, max_pending: int = 64,
                 jump_ns: Optional[int] = None) -> None:
        self.dynamic = list(dynamic)
        self.static = list(static)
        self.slop_ns = int(slop_ns)
        self.stale_timeout_ns = int(stale_timeout_ns)
        self._jump_ns = None if jump_ns is None else int(jump_ns)
        self.max_pending = max_pending
        self.dropped = 0
        self.time_jumps = 0
        self.refused: Counter[str] = Counter()
        self._jump: Optional[TimeJump] = None
        self._suspects: list[tuple[str, str, int, Any]] = []
        self._normal_since_suspect = 0
        self._last_of: dict[tuple[str, str], int] = {}
        self._differences: deque[int] = deque(maxlen=PERIOD_SAMPLES)
        self._dynamic_set = frozenset(self.dynamic)
        # stale() of the newest stamp it was computed at: a message of a body in it, or a
        # newer stamp, computes it again (no pass over every body per message)
        self._stale: Optional[tuple[int, frozenset[str]]] = None
        self._forget()

    def _forget(self) -> None:
        self.pending: list[Group] = []
        self.last_seen: dict[str, int] = {}
        self.first_ns: Optional[int] = None
        self.newest_ns: Optional[int] = None
        self._last_of.clear()
        self._stale = None

    @property
    def jump_ns(self) -> int:
        """Largest stamp distance from the newest stamp taken without confirmation (ns)."""
        return self.stale_timeout_ns if self._jump_ns is None else self._jump_ns

    # --- state ------------------------------------------------------------------------------

    def stale(self) -> list[str]:
        """Dynamic bodies silent for longer than the stale timeout (by message stamps)."""
        if self.newest_ns is None:
            return []
        return [n for n in self.dynamic
                if self.newest_ns - self.last_seen.get(n, self.first_ns or 0)
                > self.stale_timeout_ns]

    def take_jump(self) -> Optional[TimeJump]:
        """The clock jump confirmed since the last call (None if none); reported once."""
        jump, self._jump = self._jump, None
        return jump

    def observed_period_ns(self) -> Optional[int]:
        """Median stamp step of consecutive messages of one topic (ns), None before 3 samples."""
        if len(self._differences) < 3:
            return None
        return int(median(self._differences))

    def slop_problem(self) -> Optional[str]:
        """Why the slop cannot work against the observed period (None when it can)."""
        period = self.observed_period_ns()
        if self.slop_ns <= 0 or period is None or 2 * self.slop_ns < period:
            return None
        return (f'sync_slop {self.slop_ns * 1e-9:g} s is not below half the observed '
                f'publishing period {period * 1e-9:g} s: neighbouring steps cannot be told '
                f'apart (use sync_slop < {period * 0.5e-9:g} s, or 0 for exact stamps)')

    def unpaired(self) -> str:
        """Why the pending parts complete no step, in words ('' when nothing is pending)."""
        stale = set(self.stale())
        required = [n for n in self.dynamic if n not in stale]
        poses_only, twists_only, apart, silent = [], [], [], []
        for name in required:
            poses = [g.holds(name, 'pose') for g in self.pending if g.holds(name, 'pose')
                     is not None]
            twists = [g.holds(name, 'twist') for g in self.pending if g.holds(name, 'twist')
                      is not None]
            if poses and not twists:
                poses_only.append(name)
            elif twists and not poses:
                twists_only.append(name)
            elif poses and twists:
                gap = min(abs(p - t) for p in poses for t in twists)   # type: ignore[operator]
                apart.append(f'{cut(name)} ({_duration_text(gap)} apart)')
            else:
                silent.append(name)
        if not (poses_only or twists_only or apart):
            return ''
        reasons = []
        if poses_only:
            reasons.append('poses without twists for: ' + names_text(poses_only))
        if twists_only:
            reasons.append('twists without poses for: ' + names_text(twists_only))
        if apart:
            reasons.append('pose and twist stamps never match for: '
                           + ', '.join(apart[:NAMES_SHOWN])
                           + (f' +{len(apart) - NAMES_SHOWN} more'
                              if len(apart) > NAMES_SHOWN else '')
                           + (f' (sync_slop {self.slop_ns * 1e-9:g} s)'))
        if silent:
            reasons.append('nothing pending from: ' + names_text(silent))
        return '; '.join(reasons)

    # --- input ------------------------------------------------------------------------------

    def add(self, name: str, kind: str, stamp_ns: int, msg: Any) -> list[Group]:
        """Add one message (kind 'pose' or 'twist'); returns the groups it completed."""
        stamp_ns = int(stamp_ns)
        if self.newest_ns is not None and abs(stamp_ns - self.newest_ns) > self.jump_ns:
            return self._suspect(name, kind, stamp_ns, msg)
        if self._suspects:
            self._normal_since_suspect += 1
            self._discard_suspects(name)
        return self._use(name, kind, stamp_ns, msg)

    def _use(self, name: str, kind: str, stamp_ns: int, msg: Any) -> list[Group]:
        if self.first_ns is None:
            self.first_ns = stamp_ns
        self.newest_ns = stamp_ns if self.newest_ns is None else max(self.newest_ns, stamp_ns)
        self.last_seen[name] = max(self.last_seen.get(name, stamp_ns), stamp_ns)
        if self._stale is not None and name in self._stale[1]:
            self._stale = None
        last = self._last_of.get((name, kind))
        if last is not None and stamp_ns > last:
            self._differences.append(stamp_ns - last)
        self._last_of[(name, kind)] = stamp_ns
        group = self._group_for(name, kind, stamp_ns)
        parts = group.parts.setdefault(name, {})
        parts[kind] = msg
        group.stamps.setdefault(name, {})[kind] = stamp_ns
        if len(parts) == len(KINDS):
            group.paired.add(name)
        return self._complete()

    def _suspect(self, name: str, kind: str, stamp_ns: int, msg: Any) -> list[Group]:
        """Hold a stamp far from the newest; a jump when another message confirms it."""
        if self._suspects and abs(stamp_ns - self._suspects[0][2]) > self.jump_ns:
            self._discard_suspects()   # a different stray stamp: the old ones were strays
        if not self._suspects:
            self._normal_since_suspect = 0
        confirms = any(n != name or (k == kind and s != stamp_ns)
                       for n, k, s, _ in self._suspects)
        self._suspects.append((name, kind, stamp_ns, msg))
        if not confirms:
            if len(self._suspects) > 4 * len(KINDS) * max(1, len(self.dynamic)
                                                          + len(self.static)):
                self._discard_suspects()
            return []
        before = self.newest_ns if self.newest_ns is not None else stamp_ns
        suspects, self._suspects = self._suspects, []
        if suspects[0][2] < before:
            # backwards: a new run of the source; its history means nothing now
            self.dropped += len(self.pending)
            self._forget()
        # forwards: time went on (a pause, or messages lost upstream); nothing is
        # forgotten, the bodies that did not come along turn stale by the usual rule
        self.time_jumps += 1
        self._jump = TimeJump(before, suspects[0][2])
        done: list[Group] = []
        for n, k, s, m in suspects:
            done += self._use(n, k, s, m)
        return done

    def _discard_suspects(self, name: Optional[str] = None) -> None:
        """Refuse the suspects (of ``name`` only, unless every body had its chance)."""
        limit = 2 * len(KINDS) * max(1, len(self.dynamic) + len(self.static))
        every = name is None or self._normal_since_suspect > limit
        kept = []
        for suspect in self._suspects:
            if every or suspect[0] == name:
                ahead = self.newest_ns is not None and suspect[2] > self.newest_ns
                self.refused['future_stamp' if ahead else 'past_stamp'] += 1
            else:
                kept.append(suspect)
        self._suspects = kept

    def _group_for(self, name: str, kind: str, stamp_ns: int) -> Group:
        """The nearest pending group within the slop that has no other-stamp part here."""
        near = [g for g in self.pending if abs(g.stamp_ns - stamp_ns) <= self.slop_ns
                and g.holds(name, kind) in (None, stamp_ns)]
        if near:
            return min(near, key=lambda g: (abs(g.stamp_ns - stamp_ns), g.stamp_ns))
        group = Group(stamp_ns)
        self.pending.append(group)
        self.pending.sort(key=lambda g: g.stamp_ns)
        while len(self.pending) > self.max_pending:
            self.pending.pop(0)
            self.dropped += 1
        return group

    def _stale_now(self) -> frozenset[str]:
        """``stale()`` as a set, computed again only when it may have changed."""
        if self._stale is None or self._stale[0] != self.newest_ns:
            self._stale = (self.newest_ns or 0, frozenset(self.stale()))
        return self._stale[1]

    def _complete(self) -> list[Group]:
        stale = self._stale_now() & self._dynamic_set
        needed = len(self.dynamic) - len(stale)
        done: list[Group] = []
        for group in self.pending:
            if needed and len(group.paired) >= needed and (
                    not stale and self._dynamic_set <= group.paired
                    or all(n in group.paired for n in self.dynamic if n not in stale)):
                done.append(group)
        if not done:
            return []
        newest = done[-1].stamp_ns
        kept = []
        for group in self.pending:
            if group in done:
                continue
            if group.stamp_ns < newest:
                self.dropped += 1
            else:
                kept.append(group)
        self.pending = kept
        return done


def _duration_text(ns: int) -> str:
    """A stamp difference in the unit that reads best (ns, us, ms or s)."""
    for unit, scale in (('s', 10**9), ('ms', 10**6), ('us', 10**3)):
        if ns >= scale:
            return f'{ns / scale:g} {unit}'
    return f'{ns} ns'
