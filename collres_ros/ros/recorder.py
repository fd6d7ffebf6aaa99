"""A small rclpy recorder: every topic of the graph into a rosbag2 bag (no rosbag2_py here).

It subscribes to each topic it discovers (re-scanning the graph periodically),
takes the serialized CDR bytes as rclpy receives them (``raw=True``) and
writes them with ``collres_ros.ros.bag`` at the receive time (ns since the epoch),
as ``ros2 bag record`` does, with the publishers' QoS profiles as the
topic's ``offered_qos_profiles``. Run it in an executor of the caller's choosing;
all writes happen in subscription callbacks of that one executor. Messages a publisher
sent that never reached the bag (its history dropped them before the recorder
acknowledged them) are counted per topic in ``losses`` (``losses.py``: publication
sequence numbers).
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any, Iterable, Mapping

from rclpy.node import Node
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy

from collres_ros.ros.bag import BagError, BagWriter, message_class
from collres_ros.ros.losses import LossCounter

IGNORED = frozenset({'/rosout', '/parameter_events'})


class Recorder:
    """Record the topics of the ROS graph seen by ``node`` into a new bag at ``path``."""

    def __init__(self, node: Node, path: str | Path, storage: str = 'mcap',
                 scan_period: float = 0.1, ignore: Iterable[str] = IGNORED,
                 custom_data: Mapping[str, str] | None = None) -> None:
        self.node = node
        self.writer = BagWriter(path, storage, custom_data=custom_data).open()
        self.ignore = set(ignore)
        self.counts: dict[str, int] = {}
        self.losses = LossCounter()   # messages lost before they were recorded, by topic
        self._publishers: dict[str, int] = {}   # topic -> its publishers at the last scan
        self._subscriptions: dict[str, Any] = {}
        self._closed = False
        self.scan()
        self._timer = node.create_timer(scan_period, self.scan)

    def scan(self) -> None:
        """Subscribe to every not yet recorded topic with a known message type."""
        for topic, types in self.node.get_topic_names_and_types():
            if topic in self._subscriptions:
                self._publishers[topic] = self.node.count_publishers(topic)
                continue
            if topic in self.ignore or len(types) != 1:
                continue
            try:
                cls = message_class(types[0])
            except BagError:
                continue
            publishers = self.node.get_publishers_info_by_topic(topic)
            if not publishers:
                continue  # only subscribers so far: the publisher's QoS decides ours
            reliable = all(info.qos_profile.reliability == ReliabilityPolicy.RELIABLE
                           for info in publishers)
            # keep all: a sample is acknowledged once it is in our queue, however far the
            # callbacks lag; what the publishers' history dropped before then is lost
            qos = QoSProfile(history=HistoryPolicy.KEEP_ALL,
                             reliability=ReliabilityPolicy.RELIABLE if reliable
                             else ReliabilityPolicy.BEST_EFFORT)
            # the bag's offered_qos_profiles: what the publishers offer (ros2 bag record's rule)
            self.writer.add_topic(topic, types[0], [info.qos_profile for info in publishers])
            self._subscriptions[topic] = self.node.create_subscription(
                cls, topic, self._callback(topic, types[0]), qos, raw=True)
            self.counts.setdefault(topic, 0)
            self._publishers[topic] = len(publishers)

    def _callback(self, topic: str, msgtype: str) -> Any:
        def write(data: bytes, info: Any) -> None:   # two arguments: rclpy passes the info
            if not self._closed:
                self.writer.write_raw(topic, msgtype, time.time_ns(), data)
                self.counts[topic] += 1
                self.losses.count(topic, info, self._publishers.get(topic, 1))
        return write

    def subscription(self, topic: str) -> Any | None:
        """Return the subscription of ``topic`` (absolute name), None before discovery."""
        return self._subscriptions.get(topic)

    @property
    def topics(self) -> list[str]:
        return sorted(self._subscriptions)

    def close(self) -> None:
        """Stop recording and finish the bag (idempotent)."""
        if self._closed:
            return
        self._closed = True
        self._timer.cancel()
        for subscription in self._subscriptions.values():
            self.node.destroy_subscription(subscription)
        self.writer.close()
