"""rosbag2-compatible MCAP recording and reading without ROS (mcap, no rclpy)."""
