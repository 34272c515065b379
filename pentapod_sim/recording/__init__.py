"""ROS-free recording of testbed runs as rosbag2-compatible MCAP bags (see docs/recording.md)."""
from pentapod_sim.recording.bag_writer import BagWriter, QOS_BEST_EFFORT, qos_profile, QOS_RELIABLE
from pentapod_sim.recording.msgdefs import message_definition

__all__ = ['BagWriter', 'QOS_BEST_EFFORT', 'QOS_RELIABLE', 'message_definition', 'qos_profile']
