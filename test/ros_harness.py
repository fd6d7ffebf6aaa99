"""Test-side ROS helpers: a private rclpy context spinning in a thread, collecting messages."""

from __future__ import annotations

import threading
from collections import defaultdict
from pathlib import Path
from typing import Any, Callable

import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import QoSProfile, ReliabilityPolicy

from collres_ros.ros import processes

QOS = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)


class Peer:
    """An rclpy node in its own context and domain, spun in a background thread."""

    def __init__(self, domain_id: int, name: str = 'collres_test_peer') -> None:
        self.context = rclpy.Context()
        rclpy.init(context=self.context, domain_id=domain_id)
        self.node = rclpy.create_node(name, context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.lock = threading.Lock()
        self.received: dict[str, list[Any]] = defaultdict(list)
        self.publishers: dict[str, Any] = {}
        self.thread = threading.Thread(target=self._spin, daemon=True)
        self.thread.start()

    def _spin(self) -> None:
        try:
            self.executor.spin()
        except Exception:  # context shut down at close
            pass

    def listen(self, topic: str, kind: type, qos: Any = QOS) -> None:
        def store(msg: Any) -> None:
            with self.lock:
                self.received[topic].append(msg)
        self.node.create_subscription(kind, topic, store, qos)

    def messages(self, topic: str) -> list[Any]:
        with self.lock:
            return list(self.received[topic])

    def advertise(self, topic: str, kind: type) -> None:
        if topic not in self.publishers:
            self.publishers[topic] = self.node.create_publisher(kind, topic, QOS)

    def publish(self, topic: str, msg: Any) -> None:
        self.advertise(topic, type(msg))
        self.publishers[topic].publish(msg)

    def connected(self, topic: str) -> bool:
        """A subscriber of our publisher on ``topic`` was discovered."""
        pub = self.publishers.get(topic)
        return pub is not None and pub.get_subscription_count() > 0

    def wait(self, predicate: Callable[[], bool], timeout: float = 10.0) -> bool:
        return processes.wait_for(predicate, timeout)

    def close(self) -> None:
        self.executor.shutdown(timeout_sec=1.0)
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.context)
        self.thread.join(2.0)


def write_scene(path: Path, extra_node: str = '', ball: str = '') -> Path:
    """A floor + ball + box scene file with fast diagnostics."""
    path.write_text(f'''/**:
  ros__parameters:
    world_frame: world
    bodies: [floor, ball, box]
    body:
      floor: {{shape: box, size: [10.0, 10.0, 0.2], static: true, position: [0.0, 0.0, -0.1]}}
      ball: {{shape: sphere, size: [0.1], restitution: 0.8, position: [0.0, 0.0, 1.0]{ball}}}
      box: {{shape: box, size: [0.2, 0.2, 0.2], position: [1.0, 0.0, 0.1]}}
collres_node:
  ros__parameters:
    diagnostics_period: 0.1
    stale_timeout: 0.2
{extra_node}''')
    return path
