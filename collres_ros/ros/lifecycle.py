"""``collres_node --lifecycle``: collres_node as a managed (lifecycle) node, as in nav2.

The parameters are declared and the scene validated when the process starts
(unconfigured: a bad file still stops it with exit 1); then, through the
standard lifecycle services (``<node>/change_state``, ``get_state``, ...):

* configure: the resolver, the codecs, every publisher and subscription and the
  diagnostics timer are created (parameters changed meanwhile are used);
* activate: inputs are resolved and answered, /diagnostics is published;
* deactivate: inputs are dropped (not counted: nobody asked the node to serve),
  nothing is published; the topics stay;
* cleanup (and shutdown): every topic, the timer and the resolver are freed;
  configure starts again from the params state.

An input stream paused by deactivate resumes as any pause does: a step more
than ``solver.max_dt`` after its predecessor is a fresh start.
"""

from __future__ import annotations

import time
from typing import Any

from rclpy.lifecycle import LifecycleNode, LifecycleState, TransitionCallbackReturn

from collres_ros.ros.node import CollresNode

SUCCESS = TransitionCallbackReturn.SUCCESS


class ManagedCollresNode(CollresNode, LifecycleNode):
    """CollresNode whose resolution is created, served and freed by lifecycle transitions."""

    MANAGED = True

    def on_configure(self, state: LifecycleState) -> Any:
        self.configure_resolution()
        return super().on_configure(state)

    def on_activate(self, state: LifecycleState) -> Any:
        self.serving_since_ns = time.time_ns()   # what arrived while inactive is not served
        self.serving = True
        return super().on_activate(state)

    def on_deactivate(self, state: LifecycleState) -> Any:
        self.serving = False
        return super().on_deactivate(state)

    def on_cleanup(self, state: LifecycleState) -> Any:
        self.release_resolution()
        return super().on_cleanup(state)

    def on_shutdown(self, state: LifecycleState) -> Any:
        if self.configured:
            self.release_resolution()
        return super().on_shutdown(state)
