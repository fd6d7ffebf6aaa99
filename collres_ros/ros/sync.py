"""Group per-body pose and twist messages into resolution steps by stamp.

A step is complete when every required body has both a pose and a twist for
the same stamp (or, with a slop, stamps within ``slop_ns`` of the group's
first stamp, which becomes the step stamp). Required: every dynamic body that
is not stale; a body is stale when the newest stamp received from any body is
more than ``stale_timeout_ns`` past its own last one (a body never heard
from counts from the first stamp received). Static bodies join a step when
their pose arrived in time (their twist is optional: zero when absent).

When a group completes, older pending groups can no longer be used and are
dropped (counted in ``dropped``), as are the oldest groups beyond
``max_pending``. No ROS import: messages are opaque here.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Optional, Sequence


@dataclass(eq=False)
class Group:
    """Messages of one step: ``parts[name] = {'pose': msg, 'twist': msg}``."""

    stamp_ns: int
    parts: dict[str, dict[str, Any]] = field(default_factory=dict)


class StampSync:
    """Exact (or approximate, within a slop) stamp synchroniser of per-body topics."""

    def __init__(self, dynamic: Sequence[str], static: Sequence[str] = (), slop_ns: int = 0,
                 stale_timeout_ns: int = 1_000_000_000, max_pending: int = 64) -> None:
        self.dynamic = list(dynamic)
        self.static = list(static)
        self.slop_ns = int(slop_ns)
        self.stale_timeout_ns = int(stale_timeout_ns)
        self.max_pending = max_pending
        self.pending: list[Group] = []
        self.last_seen: dict[str, int] = {}
        self.first_ns: Optional[int] = None
        self.newest_ns: Optional[int] = None
        self.dropped = 0

    def stale(self) -> list[str]:
        """Dynamic bodies silent for longer than the stale timeout (by message stamps)."""
        if self.newest_ns is None:
            return []
        return [n for n in self.dynamic
                if self.newest_ns - self.last_seen.get(n, self.first_ns or 0)
                > self.stale_timeout_ns]

    def add(self, name: str, kind: str, stamp_ns: int, msg: Any) -> list[Group]:
        """Add one message (kind 'pose' or 'twist'); returns the groups it completed."""
        stamp_ns = int(stamp_ns)
        if self.first_ns is None:
            self.first_ns = stamp_ns
        self.newest_ns = stamp_ns if self.newest_ns is None else max(self.newest_ns, stamp_ns)
        self.last_seen[name] = max(self.last_seen.get(name, stamp_ns), stamp_ns)
        group = self._group_for(stamp_ns)
        if group is None:
            return []
        group.parts.setdefault(name, {})[kind] = msg
        return self._complete()

    def _group_for(self, stamp_ns: int) -> Optional[Group]:
        near = [g for g in self.pending if abs(g.stamp_ns - stamp_ns) <= self.slop_ns]
        if near:
            return min(near, key=lambda g: (abs(g.stamp_ns - stamp_ns), g.stamp_ns))
        group = Group(stamp_ns)
        self.pending.append(group)
        self.pending.sort(key=lambda g: g.stamp_ns)
        while len(self.pending) > self.max_pending:
            self.pending.pop(0)
            self.dropped += 1
        return group

    def _complete(self) -> list[Group]:
        stale = set(self.stale())
        required = [n for n in self.dynamic if n not in stale]
        done: list[Group] = []
        for group in list(self.pending):
            if required and all(len(group.parts.get(n, {})) == 2 for n in required):
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
