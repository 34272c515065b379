"""ROS 2 nodes of the testbed: thin rclpy adapters around the ROS-free core."""
