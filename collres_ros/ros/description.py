"""The URDF from the ``robot_description`` topic (std_msgs/String, reliable, transient local:
the message robot_state_publisher holds), for ``robot_description_topic: true``.

collres_node waits for it as long as it takes (a log line every 5 s); collres_sim and
collres_replay wait up to a deadline and then stop with one line saying what they waited for.
"""

from __future__ import annotations

import time
from typing import Any, Callable, Optional, Sequence

from collres_ros.ros import cli, names, qos

LOG_PERIOD = 5.0   # s between "waiting" lines


def wait_for(node: Any, timeout: Optional[float], log: Callable[[str], None]) -> Optional[str]:
    """The URDF text of the first message on ``node``'s ``robot_description`` topic, waited
    for up to ``timeout`` s (None: until it comes), logging every LOG_PERIOD s; None when the
    deadline passed. KeyboardInterrupt when the context shuts down while waiting."""
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from std_msgs.msg import String
    got: list[str] = []
    executor = SingleThreadedExecutor(context=node.context)   # of the node's context
    executor.add_node(node)
    subscription = node.create_subscription(String, names.ROBOT_DESCRIPTION,
                                            lambda msg: got.append(msg.data),
                                            qos.latched_qos())
    topic = names.absolute(names.ROBOT_DESCRIPTION, node.get_namespace())
    end = None if timeout is None else time.monotonic() + timeout
    try:
        while not got and rclpy.ok(context=node.context) \
                and (end is None or time.monotonic() < end):
            log(f'waiting for the URDF on {topic} (transient local)')
            pause = time.monotonic() + LOG_PERIOD
            while not got and time.monotonic() < min(pause, end or pause) \
                    and rclpy.ok(context=node.context):
                executor.spin_once(timeout_sec=0.1)
    finally:
        executor.remove_node(node)
        executor.shutdown()
        node.destroy_subscription(subscription)
    if not got and not rclpy.ok(context=node.context):
        raise KeyboardInterrupt   # shut down while waiting
    if got:
        log(f'robot_description: {len(got[0])} characters from {topic}')
    return got[0] if got else None


def fetch(executable: str, ros_args: Sequence[str], timeout: float) -> str:
    """The URDF for ``executable`` (collres_sim, collres_replay), from a node of its own with
    the command's ROS arguments (namespace, remaps); CliError after ``timeout`` s."""
    from rclpy.context import Context
    from rclpy.node import Node
    context = Context()   # its own: the executable's later init starts afresh
    with cli.ros_init(args=[executable, *ros_args], context=context):
        node = Node(executable, context=context)
        try:
            text = wait_for(node, timeout, lambda line: print(line, flush=True))
            topic = names.absolute(names.ROBOT_DESCRIPTION, node.get_namespace())
        finally:
            node.destroy_node()
    if text is None:
        raise cli.CliError(f'robot_description_topic: no URDF on {topic} within {timeout:g} s '
                           '(is robot_state_publisher running, in this ROS_DOMAIN_ID?)')
    return text
