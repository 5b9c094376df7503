"""conveyor_twin: a real-time digital twin of a conveyor cell (ROS 2)."""

__version__ = '0.1.0'
