"""rosbag2 reading, writing and flight conversion (no rclpy)."""
