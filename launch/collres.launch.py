"""Launch collres_node, and collres_sim beside it on request.

::

    ros2 launch collres_ros collres.launch.py
    ros2 launch collres_ros collres.launch.py start_sim:=true
    ros2 launch collres_ros collres.launch.py namespace:=r1 \
        params_file:=/path/to/scene.yaml use_sim_time:=true

Arguments (``ros2 launch collres_ros collres.launch.py --show-args``):

* ``params_file``: the scene and settings of both executables (default: the
  package's ``config/collres.yaml``; the shipped scenes are in ``config/scenes/``).
  Relative mesh paths in it are resolved against its directory.
* ``namespace``: namespace of both nodes, so several scenes run side by side
  (a params file may then use ``/<namespace>/collres_node:`` sections).
* ``use_sim_time``: ``collres_node`` takes its clock from ``/clock``
  (collres_sim publishes it). The node's answers are stamped from their
  inputs either way; this only affects its log and diagnostics times.
* ``start_sim``: also start ``collres_sim``, which integrates the scene,
  closes the loop through the node and exits after the scene's ``duration``.
* ``lifecycle``: run ``collres_node --lifecycle`` as a launch ``LifecycleNode``, a managed
  node (as nav2 brings nodes up); with ``autostart:=true`` (the default) the launch
  configures and then activates it, with ``autostart:=false`` it waits unconfigured for
  ``ros2 lifecycle set /collres_node configure``, then ``activate``.
* ``clock_topic``: the topic collres_sim publishes its clock on and collres_node (with
  ``use_sim_time``) reads it from: ``/clock`` by default, which is absolute, so scenes run
  side by side each need their own (``namespace:=r1 clock_topic:=/r1/clock``); it is a
  remap of ``/clock`` on both nodes.

New arguments go into ``ARGUMENTS`` (name, default, description) and are read
with ``LaunchConfiguration`` where they are used, as below.
"""

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, EmitEvent, RegisterEventHandler
from launch.conditions import IfCondition, UnlessCondition
from launch.events import matches_action
from launch.substitutions import AndSubstitution, LaunchConfiguration, PathJoinSubstitution
from launch_ros.actions import LifecycleNode, Node
from launch_ros.event_handlers import OnStateTransition
from launch_ros.events.lifecycle import ChangeState
from launch_ros.substitutions import FindPackageShare

PACKAGE = 'collres_ros'
# lifecycle_msgs/msg/Transition ids (the launch file imports launch and launch_ros only)
TRANSITION_CONFIGURE, TRANSITION_ACTIVATE = 1, 3

ARGUMENTS = (
    ('params_file', PathJoinSubstitution([FindPackageShare(PACKAGE), 'config', 'collres.yaml']),
     'Params file of the scene (bodies, solver, sim settings)'),
    ('namespace', '', 'Namespace of collres_node and collres_sim'),
    ('use_sim_time', 'false', 'collres_node uses /clock (published by collres_sim)'),
    ('start_sim', 'false', 'Also start collres_sim on the same params file'),
    ('lifecycle', 'false', 'Run collres_node as a managed (lifecycle) node'),
    ('autostart', 'true', 'lifecycle: configure and activate collres_node at launch'),
    ('clock_topic', '/clock', 'Clock topic of collres_sim and collres_node (a remap of '
     '/clock; give each of several scenes its own)'),
)


def generate_launch_description() -> LaunchDescription:
    params_file = LaunchConfiguration('params_file')
    namespace = LaunchConfiguration('namespace')
    use_sim_time = LaunchConfiguration('use_sim_time')
    start_sim = LaunchConfiguration('start_sim')
    lifecycle = LaunchConfiguration('lifecycle')
    autostart = LaunchConfiguration('autostart')
    clock = [('/clock', LaunchConfiguration('clock_topic'))]

    arguments = [DeclareLaunchArgument(name, default_value=default, description=text)
                 for name, default, text in ARGUMENTS]
    # the params file last: it wins over the dict, and the node resolves relative
    # mesh paths against the last --params-file it is given
    node = Node(
        package=PACKAGE, executable='collres_node', name='collres_node',
        namespace=namespace, output='screen', emulate_tty=True,
        parameters=[{'use_sim_time': use_sim_time}, params_file], remappings=clock,
        condition=UnlessCondition(lifecycle))
    managed = LifecycleNode(
        package=PACKAGE, executable='collres_node', name='collres_node',
        namespace=namespace, output='screen', emulate_tty=True, arguments=['--lifecycle'],
        parameters=[{'use_sim_time': use_sim_time}, params_file], remappings=clock,
        condition=IfCondition(lifecycle))
    starting = AndSubstitution(lifecycle, autostart)
    configure = EmitEvent(event=ChangeState(lifecycle_node_matcher=matches_action(managed),
                                            transition_id=TRANSITION_CONFIGURE),
                          condition=IfCondition(starting))
    activate = RegisterEventHandler(OnStateTransition(
        target_lifecycle_node=managed, goal_state='inactive',
        entities=[EmitEvent(event=ChangeState(lifecycle_node_matcher=matches_action(managed),
                                              transition_id=TRANSITION_ACTIVATE))]),
        condition=IfCondition(starting))
    sim = Node(
        package=PACKAGE, executable='collres_sim', name='collres_sim',
        namespace=namespace, output='screen', emulate_tty=True,
        parameters=[params_file], remappings=clock, condition=IfCondition(start_sim))
    return LaunchDescription(arguments + [node, managed, activate, configure, sim])
