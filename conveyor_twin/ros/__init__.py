"""ROS 2 nodes: thin translators between the cores and topics (no core package imports rclpy)."""
