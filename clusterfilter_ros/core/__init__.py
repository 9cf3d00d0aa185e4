"""ROS-free core: frames in; clusters, scores, trajectories and positions out.

Nothing in this package imports rclpy, ROS messages, or the io/ros/cli layers.
"""
