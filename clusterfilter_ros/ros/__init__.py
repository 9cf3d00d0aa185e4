"""ROS 2 adapters: the rclpy detector node, replay and recording.

Modules that import rclpy do so at module level only in ``node``/``replay``/``record``;
``node_params`` is ROS-free so the CLI and YAML generation can use it without ROS.
"""
