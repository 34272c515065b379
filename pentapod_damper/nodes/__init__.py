"""ROS 2 nodes of the damping controllers (thin adapters around pentapod_damper.laws)."""
