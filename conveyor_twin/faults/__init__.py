"""Faults a controller must handle, injected on demand or by a scenario (no ROS imports)."""
