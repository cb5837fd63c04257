"""ROS 2 adapter for flexmb (rclpy). Imported only by ``flexmb node`` / ``flexmb play``."""
