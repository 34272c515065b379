"""Command-line entry points of the testbed (ROS-free)."""
