"""
Wire CDR of rclpy message objects (pentapod_sim/nodes/wire_cdr.py).

The direct JointState/Clock/WrenchStamped serialisers against rosbags' serialiser (the general
path) on messages that exercise every alignment case (names of every length mod 4, empty and
non-empty arrays, frame ids of every length mod 8, non-ASCII text), and against rclpy's
deserialiser (the bytes decode to the message). That they equal what DDS delivers is checked
on a recorded run in test_composed_handoff.py.
"""
from geometry_msgs.msg import WrenchStamped
import numpy as np
import pytest
from rclpy.serialization import deserialize_message
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState

from fixtures.rosbags_cdr import RosbagsCdr
from pentapod_sim.nodes.wire_cdr import serializer


def _joint_states(rng):
    for n_names in range(0, 6):
        for lengths in ((0, 0, 0), (n_names, n_names, 0), (0, 0, n_names), (1, 0, 3)):
            names = ['j' * int(rng.integers(0, 9)) + str(i) for i in range(n_names)]
            msg = JointState(name=names, position=rng.normal(size=lengths[0]).tolist(),
                             velocity=rng.normal(size=lengths[1]).tolist(),
                             effort=rng.normal(size=lengths[2]).tolist())
            msg.header.stamp.sec = int(rng.integers(-5, 2**31 - 1))
            msg.header.stamp.nanosec = int(rng.integers(0, 10**9))
            msg.header.frame_id = ['', 'f', 'base_µ', 'abc'][n_names % 4]
            yield msg


def test_joint_state_direct_path_equals_rosbags():
    rng = np.random.default_rng(5)
    direct, general = serializer(JointState), RosbagsCdr(JointState)
    count = 0
    for msg in _joint_states(rng):
        data = direct(msg)
        assert data == general(msg), msg
        assert len(data) % 4 == 0
        back = deserialize_message(data, JointState)
        assert back == msg
        assert direct(msg) == data        # the cached names block gives the same bytes
        count += 1
    assert count == 24


@pytest.mark.parametrize('sec,nanosec', [(0, 0), (3, 999_999_999), (-1, 5)])
def test_clock_direct_path_equals_rosbags(sec, nanosec):
    msg = Clock()
    msg.clock.sec, msg.clock.nanosec = sec, nanosec
    data = serializer(Clock)(msg)
    assert data == RosbagsCdr(Clock)(msg) and len(data) == 12
    assert deserialize_message(data, Clock) == msg


@pytest.mark.parametrize('frame_id', ['', 't', 'tc', 'tcp', 'tcp0', 'tcp_µ', 'x' * 9])
def test_wrench_stamped_direct_path_equals_rosbags(frame_id):
    """Every frame-id length mod 8 puts the wrench's doubles behind a different padding."""
    rng = np.random.default_rng(len(frame_id))
    msg = WrenchStamped()
    msg.header.stamp.sec, msg.header.stamp.nanosec = int(rng.integers(0, 2**31 - 1)), 7
    msg.header.frame_id = frame_id
    force, torque = msg.wrench.force, msg.wrench.torque
    force.x, force.y, force.z, torque.x, torque.y, torque.z = rng.normal(size=6).tolist()
    direct = serializer(WrenchStamped)
    data = direct(msg)
    assert data == RosbagsCdr(WrenchStamped)(msg) and len(data) % 4 == 0
    assert deserialize_message(data, WrenchStamped) == msg
    assert direct(msg) == data            # the cached frame block gives the same bytes


def test_types_without_a_direct_serialiser_stay_on_dds():
    """The recorder takes from the bus only what it can write as DDS delivers it."""
    from diagnostic_msgs.msg import DiagnosticStatus
    assert serializer(DiagnosticStatus) is None
