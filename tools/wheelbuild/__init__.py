"""Building and checking the binary wheels of conveyor_twin (see tools/build_wheel.py)."""
