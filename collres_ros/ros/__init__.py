"""What adapts the core to ROS: messages, parameters, sync, bags, processes.

One home per concept; the executables (``collres_ros.node``, ``sim``,
``replay``, ``demo``) are thin mains over these modules and the core.
"""
