"""ROS 2 adapters: the rclpy detector node, replay and recording.

Import rclpy (or ROS messages) at module level: ``node``, ``replay``, ``record``,
``stamps``. ROS-free, usable without ROS installed: ``node_params`` (the node's
parameter definitions), ``merge`` (stamp-ordered merge of the lidar streams),
``transforms`` (extrinsics) and ``processes`` (starting the node, replay and recorder
as separate processes for the demo and tests).
"""
