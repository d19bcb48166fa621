"""Pure core of uav_fusion. Nothing under this package may import rclpy."""
