"""ROS 2 nodes: thin translators between the cores and topics (the only place with rclpy)."""
