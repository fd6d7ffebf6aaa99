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
* ``lifecycle``: run ``collres_node --lifecycle``, a managed node that waits
  for ``configure`` and ``activate`` (``ros2 lifecycle set /collres_node
  configure``, then ``activate``), as nav2 brings nodes up.

New arguments go into ``ARGUMENTS`` (name, default, description) and are read
with ``LaunchConfiguration`` where they are used, as below.
"""

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.conditions import IfCondition, UnlessCondition
from launch.substitutions import LaunchConfiguration, PathJoinSubstitution
from launch_ros.actions import Node
from launch_ros.substitutions import FindPackageShare

PACKAGE = 'collres_ros'

ARGUMENTS = (
    ('params_file', PathJoinSubstitution([FindPackageShare(PACKAGE), 'config', 'collres.yaml']),
     'Params file of the scene (bodies, solver, sim settings)'),
    ('namespace', '', 'Namespace of collres_node and collres_sim'),
    ('use_sim_time', 'false', 'collres_node uses /clock (published by collres_sim)'),
    ('start_sim', 'false', 'Also start collres_sim on the same params file'),
    ('lifecycle', 'false', 'Run collres_node as a managed (lifecycle) node'),
)


def generate_launch_description() -> LaunchDescription:
    params_file = LaunchConfiguration('params_file')
    namespace = LaunchConfiguration('namespace')
    use_sim_time = LaunchConfiguration('use_sim_time')
    start_sim = LaunchConfiguration('start_sim')
    lifecycle = LaunchConfiguration('lifecycle')

    arguments = [DeclareLaunchArgument(name, default_value=default, description=text)
                 for name, default, text in ARGUMENTS]
    # the params file last: it wins over the dict, and the node resolves relative
    # mesh paths against the last --params-file it is given
    node = Node(
        package=PACKAGE, executable='collres_node', name='collres_node',
        namespace=namespace, output='screen', emulate_tty=True,
        parameters=[{'use_sim_time': use_sim_time}, params_file],
        condition=UnlessCondition(lifecycle))
    managed = Node(
        package=PACKAGE, executable='collres_node', name='collres_node',
        namespace=namespace, output='screen', emulate_tty=True, arguments=['--lifecycle'],
        parameters=[{'use_sim_time': use_sim_time}, params_file],
        condition=IfCondition(lifecycle))
    sim = Node(
        package=PACKAGE, executable='collres_sim', name='collres_sim',
        namespace=namespace, output='screen', emulate_tty=True,
        parameters=[params_file], condition=IfCondition(start_sim))
    return LaunchDescription(arguments + [node, managed, sim])
