"""Test-side ROS helpers: a private rclpy context spinning in a thread, collecting messages."""

from __future__ import annotations

import threading
import time
from collections import defaultdict
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Callable, Iterator, Sequence

import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import QoSProfile, ReliabilityPolicy

from collres_ros.ros import processes

QOS = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
DIAGNOSTICS = '/diagnostics'


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


@contextmanager
def node_and_peer(domain_id: int, scene: Path, log: Path,
                  listen: Sequence[tuple[Any, ...]] = (),
                  answering: Sequence[str] = ('/body_states/corrected',)
                  ) -> Iterator[tuple[Peer, Any]]:
    """``collres_node`` on the params file ``scene`` (its output in ``log``) and a ``Peer``
    connected both ways: (peer, node process), stopped at exit (a node left running would
    answer the next test's steps on this domain).

    The peer listens to ``listen`` ((topic, type) or (topic, type, QoS)), then to
    ``/diagnostics``, and publishes ``body_states``; it is up when the node subscribes to
    that, the node publishes every topic of ``answering`` (absolute names: a loaded machine
    can match ``contacts`` well after ``body_states/corrected``, and a step published before
    it would lose its contacts), and a ``/diagnostics`` report has arrived. Both counts are
    the peer's side of each match; the node's side of its writers' matches comes later
    under load, and an answer the node published before its writer knew the peer's reader
    never reaches it (a volatile writer sends a late reader nothing older: "no answer for
    stamp ...", once in 100 starts at load 2). The node learns of the peer's readers in the
    order they were created, so a report received on the last one says the node matched the
    others before; the report also says that the node's ``body_states`` subscription has
    matched the peer's publisher (``node_publishers``: a message sent before can be lost).
    """
    from collres_ros.msg import BodyStateArray
    from diagnostic_msgs.msg import DiagnosticArray
    node = processes.start('collres_node', ['--ros-args', '--params-file', str(scene)],
                           env=processes.ros_env(domain_id), log=log)
    peer = Peer(domain_id)
    try:
        for topic, kind, *qos in listen:
            if topic != DIAGNOSTICS:
                peer.listen(topic, kind, *qos)
        peer.listen(DIAGNOSTICS, DiagnosticArray)   # last: see above
        peer.advertise('body_states', BodyStateArray)
        up = peer.wait(lambda: peer.connected('body_states') and all(
            any(s.get_publisher_count() for s in peer.node.subscriptions
                if s.topic_name == topic) for topic in answering)
            and node_publishers(peer) >= 1, 30.0)
        assert up, f'node did not come up: {node.output()}'
        yield peer, node
    finally:
        peer.close()
        if node.poll() is None:
            processes.stop(node)


def node_publishers(peer: Peer) -> int:
    """The publishers of ``body_states`` the node has matched, by its last /diagnostics
    report (-1 before one arrived)."""
    reports = peer.messages(DIAGNOSTICS)
    if not reports:
        return -1
    values = {kv.key: kv.value for kv in reports[-1].status[0].values}
    return int(values.get('body_states_publishers', -1))


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


def answered(peer: Peer, send: Callable[[], Any], timeout: float = 30.0,
             every: float = 2.0) -> Any:
    """The result of a service request, ``send()`` (returns its future), sent again every
    ``every`` s until one is answered: for requests that may be repeated (a get, a set to
    the same value). A server drops a response that it cannot send to the client's reader
    within 100 ms (rmw_fastrtps: its writer has not matched that reader yet), which a loaded
    machine exceeds right after the client was discovered; the client is then never
    answered."""
    deadline = time.monotonic() + timeout
    while True:
        future = send()
        if peer.wait(future.done, every):
            return future.result()
        assert time.monotonic() < deadline, 'the service never answered'


def set_parameter(peer: Peer, name: str, value: Any, kind: Any = None,
                  node: str = 'collres_node') -> Any:
    """Set one parameter of ``node`` through its parameter service: the SetParametersResult."""
    from rclpy.parameter import Parameter
    from rclpy.parameter_client import AsyncParameterClient
    client = AsyncParameterClient(peer.node, node)
    assert client.wait_for_services(10.0)
    parameter = Parameter(name, kind, value) if kind else Parameter(name, value=value)
    return answered(peer, lambda: client.set_parameters([parameter])).results[0]
