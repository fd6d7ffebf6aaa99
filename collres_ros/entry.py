"""The executables' mains (``scripts/collres_*``, installed by pip and by colcon alike).

A Ctrl-C must end an executable quietly at any moment of its start. Importing collres_ros,
numpy, rclpy and the compiled core takes a second or more, and compiled modules turn a
KeyboardInterrupt raised while they initialise into an ImportError (numpy: "Importing the
numpy C-extensions failed"; pybind11 modules: "initialization failed") with a traceback. So a
script gives SIGINT its OS default before its first import, ``_main`` imports the main's module
and the compiled modules it will use, then gives Ctrl-C back to Python: before that point a
Ctrl-C ends the process at once (killed by SIGINT: the shell's status 130, no output); after
it, it is a KeyboardInterrupt the mains handle (``collres_node`` exits 0, the others 130).
"""

from __future__ import annotations

import importlib
import signal
import sys
from typing import Sequence

INTERRUPTED = 130   # 128 + SIGINT, what a shell reports for Ctrl-C
# the compiled modules imported before Ctrl-C is Python's (the mains import them lazily)
ROS = ('numpy', 'rclpy', 'collres_ros.core._native')


def _main(module: str, compiled: Sequence[str]) -> int:
    main = importlib.import_module(module).main
    for name in compiled:
        importlib.import_module(name)
    try:
        signal.signal(signal.SIGINT, signal.default_int_handler)
        return int(main() or 0)
    except KeyboardInterrupt:
        print(file=sys.stderr)
        return INTERRUPTED


def node() -> int:
    return _main('collres_ros.node', ROS)


def sim() -> int:
    return _main('collres_ros.sim', ROS)


def replay() -> int:
    return _main('collres_ros.replay', ROS)


def demo() -> int:
    return _main('collres_ros.demo', ROS)


def decompose() -> int:
    return _main('collres_ros.decompose', ('numpy',))
