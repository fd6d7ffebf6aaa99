"""/diagnostics: what the node reports, as ``diagnostic_msgs/DiagnosticArray``.

``DiagnosticsSnapshot`` holds the figures of one report (the node fills it from
its counters, ``OfflineDiagnostics`` from a replay's steps on the stamps'
clock); ``diagnostics_bytes`` builds the message (``diagnostics_array``: the same as an
rclpy message). The level and message come from ``health.Health``: a recent window (5
reports) that returns to OK when a fault is over, with ERROR and STALE where they apply;
the totals since start stay in the values (``count.<reason>``, ``steps``,
``inputs_received``, ...).
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field
from typing import Any, Mapping, Optional, Sequence

from collres_ros.ros.health import LEVEL_NAMES, Health, Status
from collres_ros.ros.stamps import seconds_ns, to_stamp

STATUS_TASK = 'resolver'
HARDWARE_ID = 'collres_ros'


def status_name(node_name: str) -> str:
    """The status name of a node: its full name (``/ns/collres_node``) and the task."""
    return f'{node_name}: {STATUS_TASK}'


@dataclass
class DiagnosticsSnapshot:
    """What /diagnostics reports; counts are cumulative since start, by reason key.

    ``status``: the verdict over the recent window (``Health.status``); without
    it the level is judged from ``counts`` alone (WARN when any is non-zero).
    """

    stamp_ns: int
    steps: int = 0
    rate_hz: float = 0.0              # steps per second of wall time since the last report
    step_time_mean_ms: float = 0.0
    step_time_max_ms: float = 0.0
    contacts: int = 0                 # in the last step
    counts: Mapping[str, int] = field(default_factory=dict)   # rejections/resets by reason
    stale: Sequence[str] = ()
    extra: Mapping[str, Any] = field(default_factory=dict)
    name: str = status_name('collres_node')
    status: Optional[Status] = None


def _level_and_message(snapshot: DiagnosticsSnapshot) -> tuple[int, str]:
    if snapshot.status is not None:
        return snapshot.status.level, snapshot.status.message
    problems = {k: v for k, v in snapshot.counts.items() if v}
    level = 0
    message = f'{snapshot.steps} steps, {snapshot.rate_hz:.1f} Hz'
    if snapshot.stale:
        level = 1
        message += f'; stale: {", ".join(snapshot.stale)}'
    if problems:
        level = 1
        message += '; refused/reset inputs: ' + ', '.join(
            f'{k} {v}' for k, v in sorted(problems.items()))
    return level, message


def _status(snapshot: DiagnosticsSnapshot) -> tuple[int, str, dict[str, str]]:
    """(level, message, values) of the one DiagnosticStatus: the window's level and
    message, the totals as values."""
    level, message = _level_and_message(snapshot)
    recent = snapshot.status.recent if snapshot.status is not None else {}
    values = {
        'level': LEVEL_NAMES.get(level, str(level)),
        'steps': snapshot.steps, 'rate_hz': f'{snapshot.rate_hz:.3f}',
        'step_time_mean_ms': f'{snapshot.step_time_mean_ms:.3f}',
        'step_time_max_ms': f'{snapshot.step_time_max_ms:.3f}',
        'contacts_last_step': snapshot.contacts,
        'stale_bodies': ','.join(snapshot.stale),
        **{f'count.{k}': v for k, v in sorted(snapshot.counts.items())},
        **{f'window.{k}': v for k, v in sorted(recent.items())},
        **snapshot.extra}
    return level, message, {k: str(v) for k, v in values.items()}


def diagnostics_bytes(snapshot: DiagnosticsSnapshot) -> bytes:
    """The DiagnosticArray of ``snapshot`` as CDR bytes (``codec``'s rules; what rclpy
    serialises ``diagnostics_array`` to, built without rclpy message objects)."""
    from collres_ros.ros.codec import Writer, string_bytes
    level, message, values = _status(snapshot)
    w = Writer()
    w.header(snapshot.stamp_ns, '')
    w.u32(1)
    w.u8(level)
    for text in (snapshot.name, message, HARDWARE_ID):
        w.string(text)
    w.u32(len(values))
    parts, offset = [bytes(w.buf)], w.offset
    for text in (t for pair in values.items() for t in pair):   # key, value, key, ...
        pad = -offset % 4   # each string's length is a uint32, on 4
        data = string_bytes(text)
        parts.append(b'\x00' * pad + data)
        offset += pad + len(data)
    return b''.join(parts)


def diagnostics_array(snapshot: DiagnosticsSnapshot) -> Any:
    """``diagnostics_bytes`` as an rclpy DiagnosticArray (for tests and Python users)."""
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
    from std_msgs.msg import Header
    level, message, values = _status(snapshot)
    status = DiagnosticStatus(level=bytes([level]), name=snapshot.name, message=message,
                              hardware_id=HARDWARE_ID,
                              values=[KeyValue(key=k, value=v) for k, v in values.items()])
    return DiagnosticArray(header=Header(stamp=to_stamp(snapshot.stamp_ns)), status=[status])


def sleep_values(resolver: Any) -> dict[str, Any]:
    """/diagnostics values of sleeping: ``sleeping`` on/off, then (when on) dynamic bodies
    awake and asleep, islands awake (in the last step) and asleep."""
    counts = resolver.sleep_counts()
    return {'sleeping': 'on' if counts else 'off', **counts}


class OfflineDiagnostics:
    """/diagnostics of an offline run, as collres_node reports them, on the stamps' clock.

    A snapshot every ``period`` s of stamp time (the node's
    ``diagnostics_period``) with the node's fields: steps, rate (steps per
    second of stamp time here), contacts of the last step, the resolver's
    totals by reason, stale bodies, and the extras (bodies, sync_dropped,
    contacts_total, ``sleep_values``). Step times are wall-clock figures: reported only with
    ``timings=True``, otherwise 0, so that a replay is deterministic.
    """

    def __init__(self, period: float, timings: bool = False) -> None:
        self.period_ns = seconds_ns(period)
        self.timings = timings
        self.steps = 0
        self._last_ns: Optional[int] = None
        self._steps_at_last = 0
        self._times: list[float] = []
        self._health = Health()
        self._inputs = 0
        self._served = 0

    def update(self, resolved: Any, resolver: Any,
               sync_dropped: int = 0) -> Optional[DiagnosticsSnapshot]:
        """Account for one ResolvedStep; a DiagnosticsSnapshot when one is due, else None."""
        self.steps += 1
        self._inputs += 1
        self._served += len(getattr(resolved, 'names', ()))
        self._times.append(float(getattr(resolved, 'step_time_s', 0.0)))
        stamp = int(resolved.stamp_ns)
        if self._last_ns is None:
            self._last_ns = stamp
        elapsed = stamp - self._last_ns
        if elapsed < self.period_ns and self.steps > 1:
            return None
        rate = (self.steps - self._steps_at_last) / (elapsed * 1e-9) if elapsed > 0 else 0.0
        times = self._times if self.timings else [0.0]
        totals = resolver.totals
        counts: Counter[str] = Counter(totals)
        counts.update({'inputs': self._inputs, 'served': self._served,
                       'sync_dropped': sync_dropped})
        self._health.update(stamp * 1e-9, counts, elapsed * 1e-9)
        stale = sorted(getattr(resolved, 'stale', []))
        status = self._health.status(stamp * 1e-9, float('inf'), stale=stale)
        snapshot = DiagnosticsSnapshot(
            stamp_ns=stamp, steps=int(totals.get('steps', self.steps)), rate_hz=rate,
            step_time_mean_ms=1000.0 * sum(times) / len(times),
            step_time_max_ms=1000.0 * max(times), contacts=int(resolved.report.contacts.count),
            counts={k: v for k, v in totals.items() if k not in ('steps', 'contacts')},
            stale=stale, status=status,
            extra={'bodies': len(resolver.bodies), 'sync_dropped': sync_dropped,
                   'contacts_total': int(totals.get('contacts', 0)),
                   **sleep_values(resolver)})
        self._last_ns, self._steps_at_last, self._times = stamp, self.steps, []
        return snapshot
