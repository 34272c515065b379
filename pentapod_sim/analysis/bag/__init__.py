"""Reading recorded bags (rosbag2 MCAP) into arrays, ROS-free."""
