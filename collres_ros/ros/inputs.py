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
* ``PerBodyInputs``: ``bodies/<name>/pose`` and ``twist`` of every body, on a node of their
  own (``<node>_per_body``, same namespace), created by the server's thread with the answers'
  publishers (``bodies/<name>/{pose,twist}/corrected``; 4000 entities at 1000 bodies take
  seconds, ``body_states`` is served meanwhile). The batched path's wait set holds one
  subscription whatever the body count. A per-body answer goes out only on a topic that
  has a subscriber now: the publishers exist before the first per-body step, so a
  subscriber matched then gets every answer, and an unsubscribed answer is neither encoded
  nor published (``publish``).

The executor keeps what is not on the hot path: parameters, services, the diagnostics
timer. A failure in a server's thread ends the node as one in the main thread would
(``failure``, the context shut down).
"""

from __future__ import annotations

import threading
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

if TYPE_CHECKING:
    from collres_ros.core.pipeline import ResolvedStep
    from collres_ros.ros.messages import OutputEncoder
    from collres_ros.ros.node import CollresNode

WAIT_TIMEOUT_NS = 100_000_000   # an idle server checks the context this often
Served = tuple[Any, Callable[[Any, Any], None]]   # (rclpy Subscription, callback(data, info))


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
    pairs to serve (it may create them there); ``ready`` is set once it has returned. The
    thread runs from ``start``.
    """

    def __init__(self, owner: Node, name: str,
                 subscriptions: Callable[[], Sequence[Served]]) -> None:
        self.owner = owner
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
            self.ready.set()
            if served:
                self._serve(served)
        except (ShutdownException, ExternalShutdownException):
            pass
        except BaseException as failure:   # as a failure in the main thread: the node ends
            if self.closing or not self.owner.context.ok():
                return
            self.failure = failure
            self.owner.get_logger().error(f'{self.thread.name}: ' + traceback.format_exc())
            self.owner.context.try_shutdown()

    def _serve(self, served: Sequence[Served]) -> None:
        """Wait on every subscription at once, take every message that is there, repeat."""
        context = self.owner.context
        by_handle = {sub.handle.pointer: (sub, callback) for sub, callback in served}
        wait_set = _rclpy.WaitSet(len(served), 1, 0, 0, 0, 0, context.handle)
        while not self.closing and context.ok():
            wait_set.clear_entities()
            for sub, _ in served:
                wait_set.add_subscription(sub.handle)
            wait_set.add_guard_condition(self._wake.handle)
            wait_set.wait(WAIT_TIMEOUT_NS)
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
    (``<node>_per_body``, same namespace) served by an ``InputServer``; each message goes
    to ``CollresNode.on_part``; ``publish`` sends a per-body step's answers.

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
        # (message type, topic, callback, QoS profile: None for the default one, made in the
        # server's thread; 2000 profiles took 40 ms of a 1000-body start); per answer topic
        # (body, kind, message type, topic, profile or None)
        self._wanted = []
        self._answers = []
        try:
            for name in body_names:
                for kind, message, topic in (('pose', PoseStamped, names.pose_topic(name)),
                                             ('twist', TwistStamped, names.twist_topic(name))):
                    self._wanted.append((message, topic, partial(owner.on_part, name, kind),
                                         self._profile(topic, 'subscription')))
                    answer = topic + '/corrected'
                    self._answers.append((name, kind, message, answer,
                                          self._profile(answer, 'publisher')))
        except InvalidTopicNameException as error:   # a long name in a long namespace
            self.node.destroy_node()
            raise ValueError(f'bodies: a topic name is invalid in namespace '
                             f'{owner.get_namespace()!r} '
                             f'({str(error).splitlines()[0][:120]})') from None
        except BaseException:
            self.node.destroy_node()
            raise
        # body name -> (pose answer's publisher, twist answer's publisher), made with the
        # subscriptions
        self.publishers: dict[str, tuple[Any, Any]] = {}
        self.published = 0   # per-body answers published, all steps
        self.server = InputServer(owner, 'collres_per_body', self._subscribe)
        self.ready = self.server.ready   # every topic exists (after ``server.start``)

    def _profile(self, topic: str, entity: str) -> Any:
        """The overridden QoS profile of ``topic`` for ``entity``, None when not overridden."""
        resolved = self.node.resolve_topic_name(topic)
        return qos.overridden(self.owner, resolved, entity, self.owner.state_qos()) \
            if qos.is_overridden(self.owner, resolved, entity) else None

    @property
    def failure(self) -> Optional[BaseException]:
        return self.server.failure

    def _subscribe(self) -> list[Served]:
        """The answers' publishers, then the subscriptions, created in the server's thread
        (stops early when closed): a peer that sees a subscription finds its answer's
        publisher there already."""
        made: dict[str, list[Any]] = {}
        for name, kind, message, topic, profile in self._answers:
            if self.server.closing:
                return []
            made.setdefault(name, []).append(self.node.create_publisher(
                message, topic, profile or self.owner.state_qos(),
                event_callbacks=PublisherEventCallbacks(use_default_callbacks=False)))
        self.publishers = {name: (pose, twist) for name, (pose, twist) in made.items()}
        served = []
        for message, topic, callback, profile in self._wanted:
            if self.server.closing:
                return []
            served.append((self.node.create_subscription(
                message, topic, callback, profile or self.owner.state_qos(), raw=True,
                event_callbacks=SubscriptionEventCallbacks(use_default_callbacks=False)),
                callback))
        self.owner.get_logger().info(f'per-body inputs: {len(served)} topics subscribed, '
                                     f'{len(self._answers)} answer topics advertised')
        return served

    def publish(self, step: 'ResolvedStep', encoder: 'OutputEncoder') -> None:
        """A per-body step's answers, each on its topic only while that topic has a
        subscriber (checked at this step: 0.5 us a topic), the others neither encoded nor
        published."""
        pairs = [self.publishers[name] for name in step.names]
        wanted = np.array([[p.handle.get_subscription_count() > 0 for p in pair]
                           for pair in pairs], bool).reshape(len(pairs), 2)
        if not wanted.any():
            return
        for k, kind, data in encoder.per_body_wanted(step, wanted):
            pairs[k][kind].publish(data)
            self.published += 1

    def close(self) -> None:
        """Stop the thread, then free the subscriptions, the publishers and the node."""
        self.server.close()
        self.node.destroy_node()
