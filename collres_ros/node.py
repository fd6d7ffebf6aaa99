"""collres_node: resolve rigid-body contacts in a topic pipeline.

The node, its topics, parameters and QoS: ``collres_ros/ros/node.py``; the
managed (lifecycle) variant: ``collres_ros/ros/lifecycle.py``.
"""

from __future__ import annotations

import sys
from typing import Optional, Sequence


def main(args: Optional[Sequence[str]] = None) -> int:
    """Console script ``collres_node``: 0 on a clean shutdown, 1 on a bad configuration."""
    from collres_ros.ros.node import run
    return run(list(sys.argv if args is None else args))


if __name__ == '__main__':
    sys.exit(main())
