"""uav_fusion: radar + passive RF fusion for non-cooperative UAV tracking (ROS 2 Jazzy).

``uav_fusion.core`` is the pure part (no rclpy): site geometry, dataset readers, the digital
twin, the estimator, metrics and reports. ``uav_fusion.nodes`` holds the thin ROS 2 nodes.
"""

__version__ = "0.1.0"
