"""Wire formats of the twin without ROS: CDR from numpy, ros2msg schemas, RIHS01 type hashes."""
