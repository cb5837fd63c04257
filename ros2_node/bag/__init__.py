"""Recording, reading and replaying rosbag2-compatible MCAP (no rclpy needed)."""
