"""
Damping controllers for the pentapod testbed: viscous dampers and proof-mass actuators.

``pentapod_damper.laws`` holds the ROS-free control laws; ``pentapod_damper.nodes`` the
ROS 2 adapters.
"""
