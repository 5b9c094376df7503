"""Coordination core: time, commands, actuation and the step schedule (no ROS imports)."""
