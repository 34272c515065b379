"""ROS-free recording of testbed runs as rosbag2-compatible MCAP bags (see docs/recording.md)."""
from pentapod_sim.recording.bag_writer import BagWriter, QOS_BEST_EFFORT, QOS_RELIABLE, qos_profile
from pentapod_sim.recording.cdr import encode_clock, encode_joint_state, encode_wrench_stamped
from pentapod_sim.recording.msgdefs import message_definition

__all__ = [
    'BagWriter', 'QOS_BEST_EFFORT', 'QOS_RELIABLE', 'encode_clock', 'encode_joint_state',
    'encode_wrench_stamped', 'message_definition', 'qos_profile',
]
