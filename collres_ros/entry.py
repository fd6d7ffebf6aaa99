"""Console-script entry points: each imports its main lazily, so that a Ctrl-C while the
executable is still importing (rclpy, numpy, coal: a second or more) ends it quietly with
the shell's Ctrl-C status 130, never a KeyboardInterrupt traceback."""

from __future__ import annotations

import importlib
import sys

INTERRUPTED = 130   # 128 + SIGINT, what a shell reports for Ctrl-C


def _main(module: str) -> int:
    try:
        return int(importlib.import_module(module).main() or 0)
    except KeyboardInterrupt:
        print(file=sys.stderr)
        return INTERRUPTED


def node() -> int:
    return _main('collres_ros.node')


def sim() -> int:
    return _main('collres_ros.sim')


def replay() -> int:
    return _main('collres_ros.replay')


def demo() -> int:
    return _main('collres_ros.demo')


def decompose() -> int:
    return _main('collres_ros.decompose')
