"""Stamps: ``builtin_interfaces/Time`` and ``Duration`` to and from integer nanoseconds.

The one home of the conversion (node, sim, replay, analysis, codec and
benchmarks use it). Integer nanoseconds are exact; seconds as floats are not.
"""

from __future__ import annotations

from typing import Any

NS_PER_S = 1_000_000_000


def stamp_ns(stamp: Any) -> int:
    """builtin_interfaces/Time (or anything with ``sec``, ``nanosec``) -> integer ns."""
    return int(stamp.sec) * NS_PER_S + int(stamp.nanosec)


def split_ns(ns: int) -> tuple[int, int]:
    """Integer ns -> (sec, nanosec) with 0 <= nanosec < 1e9 (negative times clamp to 0)."""
    return divmod(max(int(ns), 0), NS_PER_S)


def to_stamp(ns: int) -> Any:
    """Integer ns -> builtin_interfaces/Time (negative times clamp to 0)."""
    from builtin_interfaces.msg import Time
    sec, nanosec = split_ns(ns)
    return Time(sec=sec, nanosec=nanosec)


def seconds_ns(seconds: float) -> int:
    """Seconds -> integer ns, rounded to the nearest."""
    return int(round(float(seconds) * 1e9))


def to_duration(seconds: float) -> Any:
    """Seconds -> builtin_interfaces/Duration (nanosec in [0, 1e9))."""
    from builtin_interfaces.msg import Duration
    sec, nanosec = divmod(seconds_ns(seconds), NS_PER_S)
    return Duration(sec=sec, nanosec=nanosec)
