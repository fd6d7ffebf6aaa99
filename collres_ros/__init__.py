"""collres_ros: rigid-body contact resolution for ROS 2 topic pipelines.

``collres_ros.core`` is the ROS-free physics core (numpy + coal); the node,
the simulator, the replay tool and the demo are thin adapters around it.
"""

import ctypes
import glob
import os
import sys

__version__ = '0.1.0'  # as package.xml and setup.py (a test keeps them equal)


def _preload_interface_libraries() -> None:
    """Load the package's own rosidl libraries when they live inside the package.

    A pip/venv install keeps ``libcollres_ros__rosidl_*.so`` in ``collres_ros/_lib``
    (no ROS ``lib/`` on the loader path for them). rmw dlopen()s typesupport
    libraries by bare name, which resolves to an already-loaded library of that
    name, so loading them here once makes publishing work. A colcon/apt install
    has no ``_lib`` and the ROS environment's loader path finds them.
    """
    pending = sorted(glob.glob(os.path.join(os.path.dirname(__file__), '_lib', '*.so')))
    while pending:  # dependency order is not known up front: retry until no progress
        failed = []
        for path in pending:
            try:
                ctypes.CDLL(path, mode=ctypes.RTLD_GLOBAL)
            except OSError:
                failed.append(path)
        if len(failed) == len(pending):
            return  # ROS libraries unavailable (e.g. the core used without ROS): skip
        pending = failed


def _generated_interfaces() -> None:
    """Put the interfaces the build generated where the environment lacks them on the
    import path, after everything installed: ``tf2_msgs`` (TFMessage) is not on PyPI, so
    a pip/venv install builds it into ``collres_ros/_interfaces`` (its libraries in
    ``_lib``); a ROS install has none there and uses the system's."""
    folder = os.path.join(os.path.dirname(__file__), '_interfaces')
    if os.path.isdir(folder) and folder not in sys.path:
        sys.path.append(folder)


_preload_interface_libraries()
_generated_interfaces()
