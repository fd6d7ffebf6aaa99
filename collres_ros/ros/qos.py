"""The QoS profiles collres_node and collres_sim offer, and their rosbag2 form for bags.

Every profile is reliable and volatile. Publishers of steps (the simulator's
``body_states``, per-body inputs and ``/clock``; the node's answers, contacts, wrenches
and ``/tf``) keep the last ``STEPS_DEPTH`` (1000) samples: a reliable reader that falls
that many steps behind (a recorder on a loaded machine) still receives every step; a
volatile writer holds only the samples not yet acknowledged, so a reader that keeps up
costs nothing more. Markers keep the last ``queue_depth`` (a viewer wants the newest; a
message of 1000 boxes is 1.3 MB). The node's subscriptions keep the last ``queue_depth``
(a control loop wants every step in order, never a backlog of old states).
``/diagnostics``: keep last 10 (diagnostic_updater uses depth 1; ten reports let a slow
aggregator miss none).

Every publisher and subscription of collres_node accepts rclpy's QoS
overrides (``OVERRIDES``: history, depth, reliability, durability), read once
at start from parameters such as
``qos_overrides./body_states.subscription.reliability: best_effort`` (the
topic's absolute name; read-only afterwards, as in every rclpy node). Each
entity gets a profile of its own (``state_qos`` builds a new one), because
rclpy writes the overrides into the profile it is given.

Bags record these in ``metadata.yaml`` as ``offered_qos_profiles`` (the list
rosbag2 Jazzy writes, metadata version 9), so ``ros2 bag play`` offers what the
node offered instead of guessing. Unspecified durations (0) are written as
rmw's infinite duration, as rosbag2 records them.
"""

from __future__ import annotations

from typing import Any, Sequence

from rclpy.qos import (
    DurabilityPolicy, HistoryPolicy, LivelinessPolicy, QoSPolicyKind, QoSProfile,
    ReliabilityPolicy)
from rclpy.qos_overriding_options import QoSOverridingOptions

from collres_ros.ros import names

DIAGNOSTICS_DEPTH = 10   # reports a slow subscriber may fall behind by
# Steps a publisher of steps keeps for a reliable reader that falls behind. Measured: the
# per-body live demo's recorder, with two busy loops on two cores, lost steps in 5 runs of 18
# at depth 10 (up to 152 steps of every topic), in none of 20 at 1000. Fast DDS's transport
# queues hold ~500 messages of a stalled reader, the writer's history the rest; it
# preallocates 100 samples a writer from depth 100 on (42 KB a writer more than at 10).
STEPS_DEPTH = 1000
INFINITE_NS = 2**63 - 1  # RMW_DURATION_INFINITE: 9223372036 s 854775807 ns
# The policies a params file may override on every topic of collres_node (rclpy's
# with_default_policies() plus durability: a late viewer may want transient_local markers).
OVERRIDABLE = (QoSPolicyKind.HISTORY, QoSPolicyKind.DEPTH, QoSPolicyKind.RELIABILITY,
               QoSPolicyKind.DURABILITY)
OVERRIDES = QoSOverridingOptions(OVERRIDABLE)
OVERRIDE_PREFIX = 'qos_overrides.'


def state_qos(depth: int) -> QoSProfile:
    """Reliable, volatile, keep last ``depth``: the node's state, contact and marker topics.

    Liveliness automatic: what DDS offers for rmw's default.
    """
    return QoSProfile(reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.VOLATILE,
                      history=HistoryPolicy.KEEP_LAST, depth=depth,
                      liveliness=LivelinessPolicy.AUTOMATIC)


def latched_qos() -> QoSProfile:
    """Reliable, transient local, keep last 1: a state published on change
    (``bodies/<name>/in_contact``), which a subscriber that joins later still receives, as
    robot_state_publisher offers ``robot_description``."""
    return QoSProfile(reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL,
                      history=HistoryPolicy.KEEP_LAST, depth=1,
                      liveliness=LivelinessPolicy.AUTOMATIC)


def tf_static_qos() -> QoSProfile:
    """Reliable, transient local, keep last 100: /tf_static as tf2_ros's listener takes it
    (each static broadcaster latches its transforms)."""
    return QoSProfile(reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL,
                      history=HistoryPolicy.KEEP_LAST, depth=100,
                      liveliness=LivelinessPolicy.AUTOMATIC)


def offered(topic: str, queue_depth: int) -> QoSProfile:
    """The profile collres_node (or, for its inputs, collres_sim) offers on ``topic``.

    ``topic``: relative or absolute name; ``queue_depth``: the node's parameter.
    """
    if topic.endswith('diagnostics'):
        return state_qos(DIAGNOSTICS_DEPTH)
    if topic.rsplit('/', 1)[-1] in (names.MARKERS, names.BODY_MARKERS):
        return state_qos(queue_depth)
    return state_qos(STEPS_DEPTH)


def _time(ns: int) -> Any:
    from rosbags.interfaces import QosTime
    ns = INFINITE_NS if ns <= 0 or ns >= INFINITE_NS else int(ns)
    return QosTime(ns // 1_000_000_000, ns % 1_000_000_000)


def to_bag(profile: Any) -> Any:
    """An rclpy QoSProfile -> the rosbags ``Qos`` written to ``offered_qos_profiles``."""
    from rosbags.interfaces import (
        Qos, QosDurability, QosHistory, QosLiveliness, QosReliability)

    def enum(kind: Any, value: Any, unknown: Any) -> Any:
        try:
            return kind(int(value))
        except ValueError:
            return unknown
    return Qos(
        history=enum(QosHistory, profile.history, QosHistory.UNKNOWN),
        depth=int(profile.depth),
        reliability=enum(QosReliability, profile.reliability, QosReliability.UNKNOWN),
        durability=enum(QosDurability, profile.durability, QosDurability.UNKNOWN),
        deadline=_time(profile.deadline.nanoseconds),
        lifespan=_time(profile.lifespan.nanoseconds),
        liveliness=enum(QosLiveliness, profile.liveliness, QosLiveliness.UNKNOWN),
        liveliness_lease_duration=_time(profile.liveliness_lease_duration.nanoseconds),
        avoid_ros_namespace_conventions=bool(profile.avoid_ros_namespace_conventions))


def to_bag_list(profiles: Sequence[Any]) -> list[Any]:
    """Several publishers' profiles (rclpy) -> rosbags ``Qos`` list, duplicates once."""
    out: list[Any] = []
    for profile in profiles:
        qos = to_bag(profile)
        if qos not in out:
            out.append(qos)
    return out


def _override_names(node: Any) -> frozenset[str]:
    """The ``qos_overrides.*`` names among the node's parameter overrides (computed once)."""
    names = getattr(node, '_collres_qos_override_names', None)
    if names is None:   # rclpy's _parameter_overrides: the params files' and -p values
        names = frozenset(n for n in node._parameter_overrides if n.startswith(OVERRIDE_PREFIX))
        node._collres_qos_override_names = names
    return names


def is_overridden(node: Any, topic: str, entity: str) -> bool:
    """Whether ``node``'s parameters override a policy of ``topic`` (absolute name) for
    ``entity`` ('publisher' or 'subscription')."""
    given = _override_names(node)
    prefix = f'{OVERRIDE_PREFIX}{topic}.{entity}.'
    return any(prefix + kind.name.lower() in given for kind in OVERRIDABLE)


def overridden(node: Any, topic: str, entity: str, profile: QoSProfile) -> QoSProfile:
    """``profile`` with the overrides ``node``'s parameters give ``topic`` (absolute name) for
    ``entity`` ('publisher' or 'subscription'), as ``qos_overriding_options`` applies them.

    The per-body topics' form: the same parameter names and values as the other topics
    (``qos_overrides./bodies/box1/pose.subscription.depth: 5``), each declared read-only
    on ``node`` when it is set (so ``ros2 param get`` shows it), nothing declared for a
    topic without overrides (declaring four per topic made a 1000-body scene declare
    16,000 parameters and start in seconds). ValueError (one line) for a bad value.
    """
    from rcl_interfaces.msg import ParameterDescriptor
    if not is_overridden(node, topic, entity):
        return profile
    given = _override_names(node)
    prefix = f'{OVERRIDE_PREFIX}{topic}.{entity}.'
    enums = {QoSPolicyKind.HISTORY: HistoryPolicy, QoSPolicyKind.RELIABILITY: ReliabilityPolicy,
             QoSPolicyKind.DURABILITY: DurabilityPolicy}
    for kind in OVERRIDABLE:
        policy = kind.name.lower()
        name = prefix + policy
        if name not in given:
            continue
        current = getattr(profile, policy)
        default = current.name.lower() if kind in enums else int(current)
        value = node.declare_parameter(name, default, ParameterDescriptor(
            description=f'{policy} for {entity} `{topic}`', read_only=True)).value
        try:
            setattr(profile, policy, enums[kind][str(value).upper()] if kind in enums
                    else int(value))
        except (KeyError, ValueError, TypeError):
            raise ValueError(f'{name}: not a {policy} policy (got {value!r})') from None
    return profile
