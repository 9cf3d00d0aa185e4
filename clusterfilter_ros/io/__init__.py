"""Readers and writers: challenge folders, PointCloud2, Livox CustomMsg, bags, ground truth.

Imports ``clusterfilter_ros.core`` only; never rclpy (ROS message classes are optional
and duck-typed: anything with PointCloud2's attributes works).
"""
