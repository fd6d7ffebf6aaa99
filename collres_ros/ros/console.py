"""Progress lines for the command-line tools: shown on a terminal only.

A progress line is redrawn in place with carriage returns; in a log file or a
pipe that would be one long line glued together, so it is printed only when
both stdout and stderr (where it goes) are terminals. Summaries and errors
are printed as usual.
"""

from __future__ import annotations

import sys
import time
from typing import Callable, TextIO


def interactive(stream: TextIO | None = None) -> bool:
    """Whether progress may be drawn: stdout and ``stream`` (default stderr) are terminals."""
    stream = sys.stderr if stream is None else stream

    def tty(s: TextIO) -> bool:
        try:
            return bool(s.isatty())
        except (AttributeError, ValueError):   # replaced or closed streams
            return False
    return tty(sys.stdout) and tty(stream)


def progress_printer(label: str, unit: str = 'steps', period: float = 0.5,
                     stream: TextIO | None = None) -> Callable[[int, int], None] | None:
    """``show(done, total)`` redrawing ``label: done/total unit (p %)`` at most every
    ``period`` s and ending the line at ``total``; None when not ``interactive``."""
    stream = sys.stderr if stream is None else stream
    if not interactive(stream):
        return None
    last = [0.0]

    def show(done: int, total: int) -> None:
        now = time.monotonic()
        if done != total and now - last[0] < period:
            return
        last[0] = now
        percent = 100.0 * done / total if total else 100.0
        print(f'\r{label}: {done}/{total} {unit} ({percent:.0f} %)', end='', file=stream,
              flush=True)
        if done >= total:
            print(file=stream, flush=True)
    return show
