"""The node's inputs, served by threads of their own instead of rclpy's executor.

rclpy's executor (Jazzy) rebuilds its wait set in Python at every wake-up, over every entity
of its nodes (the parameter services, the timer, each publisher's QoS-event handler), takes
one message per wake-up and wraps each callback in a task. Measured on ``body_states`` at
10 bodies and 240 Hz: 0.6 ms of the main thread's CPU per message went to that, beside a
0.9 ms callback; on a shared machine that is the margin between keeping up with the period
and a queue that fills (every answer then ``queue_depth`` periods late). With per-body
topics on the node itself it was worse: 190-320 ms per wake-up at 1000 bodies (the event
handlers are checked against a list of them, quadratic in their number).

``InputServer`` is a thread that waits on its subscriptions at once (one rcl wait set,
refilled in C per wake-up, the GIL released while it waits), then takes every message that
is there, subscription by subscription, and hands each to its callback as
``(serialised bytes, message info)``. Two of them serve the node:

* ``body_states`` (and ``/tf``, ``/tf_static`` with a robot): the subscriptions belong to the
  node itself (its name, namespace, remaps and QoS overrides as for any topic) in a
  ``ServedElsewhere`` callback group, which the executor neither waits on nor runs; the
  server takes them.
* ``PerBodyInputs``: ``bodies/<name>/pose`` and ``twist`` on a node of their own
  (``<node>_per_body``, same namespace), made only for the bodies whose topics have a
  publisher: the server's wait set holds the graph's guard condition (rcl's, one per
  context, triggered by every change of the ROS graph) and, on a change, one pass over the
  graph's topic names finds the bodies that gained a publisher; their answers' publishers
  (``bodies/<name>/{pose,twist}/corrected``) and then their two subscriptions are made and
  kept. While nobody publishes per body, nothing per body exists and the server sleeps:
  at 1000 bodies, 2000 idle subscriptions in its wait set took 22-92 % of a core and
  queued ``body_states`` 200-470 ms. A per-body answer goes out only on a topic that has a
  subscriber now (``publish``).

The executor keeps what is not on the hot path: parameters, services, the diagnostics
timer. A failure in a server's thread ends the node as one in the main thread would
(``failure``, the context shut down).
"""

from __future__ import annotations

import ctypes
import threading
import time
import traceback
from functools import partial
from typing import TYPE_CHECKING, Any, Callable, Optional, Sequence

import numpy as np
from geometry_msgs.msg import PoseStamped, TwistStamped
from rclpy.callback_groups import CallbackGroup
from rclpy.event_handler import PublisherEventCallbacks, SubscriptionEventCallbacks
from rclpy.exceptions import InvalidTopicNameException
from rclpy.executors import ExternalShutdownException, ShutdownException
from rclpy.guard_condition import GuardCondition
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.node import Node

from collres_ros.ros import names, qos
from collres_ros.ros.sync import names_text

if TYPE_CHECKING:
    from collres_ros.core.pipeline import ResolvedStep
    from collres_ros.ros.messages import OutputEncoder
    from collres_ros.ros.node import CollresNode

WAIT_TIMEOUT_NS = 100_000_000   # an idle server checks the context this often
GRAPH_PASS_GAP_S = 0.02   # s, least time between two passes over the graph (a peer that
#                           advertises 200 topics changes the graph 200 times in a burst)
Served = tuple[Any, Callable[[Any, Any], None]]   # (rclpy Subscription, callback(data, info))


class GraphWatch:
    """The graph guard condition of a node's context (triggered by every change of the ROS
    graph: an entity made or gone anywhere in the domain), added to an rclpy wait set.

    rclpy (Jazzy) has no handle of it, so rcl's two functions are called through ctypes on
    the pointers rclpy gives (``librcl.so`` is loaded in the process already by rclpy)."""

    _rcl: Any = None

    def __init__(self, node: Node) -> None:
        if GraphWatch._rcl is None:
            rcl = ctypes.CDLL('librcl.so')
            rcl.rcl_node_get_graph_guard_condition.restype = ctypes.c_void_p
            rcl.rcl_node_get_graph_guard_condition.argtypes = [ctypes.c_void_p]
            rcl.rcl_wait_set_add_guard_condition.restype = ctypes.c_int
            rcl.rcl_wait_set_add_guard_condition.argtypes = [ctypes.c_void_p, ctypes.c_void_p,
                                                             ctypes.c_void_p]
            GraphWatch._rcl = rcl
        self.node = node
        self.pointer = GraphWatch._rcl.rcl_node_get_graph_guard_condition(node.handle.pointer)
        if not self.pointer:
            raise RuntimeError(f'{node.get_name()}: no graph guard condition')

    def add_to(self, wait_set: Any) -> None:
        """Into ``wait_set`` (an rclpy ``WaitSet`` with room for it), after its clear."""
        if GraphWatch._rcl.rcl_wait_set_add_guard_condition(wait_set.pointer, self.pointer,
                                                            None) != 0:
            raise RuntimeError('rcl_wait_set_add_guard_condition failed')

    def changed(self, wait_set: Any) -> bool:
        """Whether the graph changed, after ``wait_set`` woke."""
        return self.pointer in wait_set.get_ready_entities('guard_condition')


class ServedElsewhere(CallbackGroup):
    """A callback group that rclpy's executors never wait on nor run: its subscriptions are
    served by an ``InputServer``."""

    def can_execute(self, entity: Any) -> bool:
        return False

    def beginning_execution(self, entity: Any) -> bool:
        return False

    def ending_execution(self, entity: Any) -> None:
        pass


class InputServer:
    """A thread that serves subscriptions (see the module docstring) until ``close``.

    ``subscriptions``: called first in the thread, returns the (subscription, callback)
    pairs to serve (it may create them there). ``graph``: with it, the thread also wakes
    when the ROS graph changes and then calls ``graph[1]`` (at start too, at most once per
    ``GRAPH_PASS_GAP_S``), which returns the pairs to serve from then on as well (it may
    create them there); it wakes on nothing else while there is nothing to serve. ``ready``
    is set once the start's calls returned. The thread runs from ``start``.
    """

    def __init__(self, owner: Node, name: str,
                 subscriptions: Callable[[], Sequence[Served]],
                 graph: Optional[tuple[Node, Callable[[], Sequence[Served]]]] = None) -> None:
        self.owner = owner
        self._graph = graph
        self.failure: Optional[BaseException] = None
        self.ready = threading.Event()
        self.closing = False
        self._subscriptions = subscriptions
        self._wake = GuardCondition(None, None, context=owner.context)   # close() wakes us
        self._held: dict[Any, Any] = {}   # subscription handle -> a message ``waiting`` took
        self.thread = threading.Thread(target=self._run, name=name, daemon=True)

    def start(self) -> 'InputServer':
        self.thread.start()
        return self

    def _run(self) -> None:
        try:
            served = list(self._subscriptions())
            watch = None
            if self._graph is not None:
                watch = GraphWatch(self._graph[0])
                served += self._graph[1]()
            self.ready.set()
            if served or watch is not None:
                self._serve(served, watch)
        except (ShutdownException, ExternalShutdownException):
            pass
        except BaseException as failure:   # as a failure in the main thread: the node ends
            if self.closing or not self.owner.context.ok():
                return
            self.failure = failure
            self.owner.get_logger().error(f'{self.thread.name}: ' + traceback.format_exc())
            self.owner.context.try_shutdown()

    def _serve(self, served: list[Served], watch: Optional[GraphWatch]) -> None:
        """Wait on every subscription (and the graph) at once, take every message that is
        there, repeat."""
        context = self.owner.context
        by_handle = {sub.handle.pointer: (sub, callback) for sub, callback in served}
        guards = 1 if watch is None else 2
        wait_set = _rclpy.WaitSet(len(served), guards, 0, 0, 0, 0, context.handle)
        changed, passed = False, time.monotonic()   # the graph changed since the last pass
        while not self.closing and context.ok():
            if changed and time.monotonic() - passed >= GRAPH_PASS_GAP_S:
                changed, passed = False, time.monotonic()
                more = self._graph[1]() if self._graph is not None else ()
                if more:
                    served += more
                    by_handle.update((sub.handle.pointer, (sub, callback))
                                     for sub, callback in more)
                    wait_set = _rclpy.WaitSet(len(served), guards, 0, 0, 0, 0, context.handle)
            timeout = WAIT_TIMEOUT_NS if not changed else max(1, int(1e9 * (
                GRAPH_PASS_GAP_S - (time.monotonic() - passed))))
            wait_set.clear_entities()
            for sub, _ in served:
                wait_set.add_subscription(sub.handle)
            wait_set.add_guard_condition(self._wake.handle)
            if watch is not None:
                watch.add_to(wait_set)
            wait_set.wait(timeout)
            if watch is not None and watch.changed(wait_set):
                changed = True
            for pointer in wait_set.get_ready_entities('subscription'):
                sub, callback = by_handle[pointer]
                while not self.closing:
                    taken = self._held.pop(sub.handle, None) or \
                        sub.handle.take_message(sub.msg_type, True)
                    if taken is None:
                        break
                    callback(*taken)

    def waiting(self, subscription: Any) -> bool:
        """Whether a message of ``subscription`` waits to be taken now. Call it from a
        callback of that subscription (the server's thread): the message is taken ahead and
        handed to the callback next, as it would have been (a take: 1 us, where a wait that
        does not block on a wait set of its own took 65 us)."""
        handle = subscription.handle
        if handle not in self._held:
            taken = handle.take_message(subscription.msg_type, True)
            if taken is None:
                return False
            self._held[handle] = taken
        return True

    def close(self) -> None:
        """Stop the thread (the subscriptions are their owners' to destroy)."""
        self.closing = True
        self._wake.trigger()
        if self.thread.is_alive():
            self.thread.join(5.0)
        if not self.thread.is_alive():   # else the thread may still wait on it
            self._wake.destroy()


class PerBodyInputs:
    """The ``bodies/<name>/pose`` and ``twist`` subscriptions and the per-body answers'
    publishers (``bodies/<name>/{pose,twist}/corrected``): a node of their own
    (``<node>_per_body``, same namespace) served by an ``InputServer``, made body by body
    once one of the body's two input topics has a publisher in the graph (see the module
    docstring) and kept from then on; each message goes to ``CollresNode.on_part``;
    ``publish`` sends a per-body step's answers.

    The subscriptions and publishers have no default QoS-event handlers (rclpy's
    incompatible-QoS warning). QoS overrides are read as for every topic
    (``qos_overrides./bodies/<name>/pose.subscription.depth``,
    ``qos_overrides./bodies/<name>/pose/corrected.publisher.depth``) and declared on the
    node where set (``qos.overridden``).
    """

    def __init__(self, owner: 'CollresNode', body_names: Sequence[str]) -> None:
        self.owner = owner
        self.node = Node(f'{owner.get_name()}_per_body', namespace=owner.get_namespace(),
                         context=owner.context, start_parameter_services=False,
                         automatically_declare_parameters_from_overrides=False)
        # resolved input topic -> body name, for the bodies not subscribed yet; the names
        # resolved here (remaps, namespace) so that a bad one stops the start
        self._unsubscribed: dict[str, str] = {}
        try:
            for name in body_names:
                for topic in (names.pose_topic(name), names.twist_topic(name)):
                    self._unsubscribed[self.node.resolve_topic_name(topic)] = name
                    self.node.resolve_topic_name(topic + '/corrected')
        except InvalidTopicNameException as error:   # a long name in a long namespace
            self.node.destroy_node()
            raise ValueError(f'bodies: a topic name is invalid in namespace '
                             f'{owner.get_namespace()!r} '
                             f'({str(error).splitlines()[0][:120]})') from None
        except BaseException:
            self.node.destroy_node()
            raise
        # body name -> (pose answer's publisher, twist answer's publisher), made with the
        # body's subscriptions
        self.publishers: dict[str, tuple[Any, Any]] = {}
        self.subscribed = 0   # per-body input topics subscribed
        self.published = 0   # per-body answers published, all steps
        self.server = InputServer(owner, 'collres_per_body', lambda: (),
                                  graph=(self.node, self._discover))
        self.ready = self.server.ready   # the graph's first pass is done (``server.start``)

    def _profile(self, topic: str, entity: str) -> Any:
        """The QoS profile of ``topic`` for ``entity`` ('publisher' or 'subscription'): the
        node's, overridden."""
        resolved = self.node.resolve_topic_name(topic)
        profile = self.owner.publisher_qos(topic) if entity == 'publisher' \
            else self.owner.state_qos()
        return qos.overridden(self.owner, resolved, entity, profile) \
            if qos.is_overridden(self.owner, resolved, entity) else profile

    @property
    def failure(self) -> Optional[BaseException]:
        return self.server.failure

    def _discover(self) -> list[Served]:
        """After a change of the graph (in the server's thread): the bodies whose pose or
        twist topic has a publisher now (one pass over the graph's topic names, a publisher
        count per candidate) are subscribed, in the order the graph lists them."""
        if not self._unsubscribed:
            return []
        found = {}   # body name -> None, in order
        for topic, _ in self.node.get_topic_names_and_types():
            name = self._unsubscribed.get(topic)
            if name is not None and name not in found and self.node.count_publishers(topic):
                found[name] = None
        served = []
        for name in found:
            if self.server.closing:
                break
            served += self._subscribe(name)
        if served:
            self.subscribed += len(served)
            self.owner.get_logger().info(
                f'per-body inputs: {len(served)} topics subscribed, published to '
                f'({names_text(list(found))}); {self.subscribed} in all')
        return served

    def _subscribe(self, name: str) -> list[Served]:
        """``name``'s answers' publishers, then its pose and twist subscriptions: a peer that
        sees a subscription finds its answer's publisher there already."""
        made = []
        for message, topic in ((PoseStamped, names.pose_topic(name)),
                               (TwistStamped, names.twist_topic(name))):
            made.append(self.node.create_publisher(
                message, topic + '/corrected', self._profile(topic + '/corrected', 'publisher'),
                event_callbacks=PublisherEventCallbacks(use_default_callbacks=False)))
        self.publishers[name] = (made[0], made[1])
        served = []
        for kind, message, topic in (('pose', PoseStamped, names.pose_topic(name)),
                                     ('twist', TwistStamped, names.twist_topic(name))):
            callback = partial(self.owner.on_part, name, kind)
            served.append((self.node.create_subscription(
                message, topic, callback, self._profile(topic, 'subscription'), raw=True,
                event_callbacks=SubscriptionEventCallbacks(use_default_callbacks=False)),
                callback))
            del self._unsubscribed[self.node.resolve_topic_name(topic)]
        return served

    def publish(self, step: 'ResolvedStep', encoder: 'OutputEncoder') -> None:
        """A per-body step's answers, each on its topic only while that topic has a
        subscriber (checked at this step: 0.5 us a topic), the others neither encoded nor
        published."""
        pairs = [self.publishers.get(name, NO_ANSWERS) for name in step.names]
        wanted = np.array([[p is not None and p.handle.get_subscription_count() > 0
                            for p in pair] for pair in pairs], bool).reshape(len(pairs), 2)
        if not wanted.any():
            return
        for k, kind, data in encoder.per_body_wanted(step, wanted):
            pairs[k][kind].publish(data)
            self.published += 1

    def close(self) -> None:
        """Stop the thread, then free the subscriptions, the publishers and the node."""
        self.server.close()
        self.node.destroy_node()


NO_ANSWERS = (None, None)   # a body not subscribed has no answers' publishers
