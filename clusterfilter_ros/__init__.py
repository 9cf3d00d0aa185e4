"""clusterfilter_ros: training-free drone detection in Livox lidar point clouds.

Layout (dependencies point one way, downwards):

- ``clusterfilter_ros.core``: ROS-free algorithm (numpy/scipy/scikit-learn only).
- ``clusterfilter_ros.sim``: ROS-free simulator of the MMAUD rig.
- ``clusterfilter_ros.io``: readers/writers (challenge folders, PointCloud2, Livox
  CustomMsg, bags, ground truth); imports core, never ros.
- ``clusterfilter_ros.ros``: the rclpy node and replay tools; imports core and io.
- ``clusterfilter_ros.cli``: the ``clusterfilter`` command.
"""

__version__ = "0.1.0"
