"""
A source re-sends its cached answer only for the state it was computed from (issue 25 item 2).

The issue's attack: a forged state stamped one step ahead was answered, and the cached answer
then re-sent for the plant's real message of that stamp. A DamperNode in this process is fed
messages directly (its DDS subscription callback, without the writer check, which
test_writers.py covers): the plant's re-sent step gets the cached answer again; another
message of the answered stamp is refused as 'conflict', answered with nothing, and the damper's
state is unchanged.
"""
import os

import pytest
import rclpy
from sensor_msgs.msg import JointState

from pentapod_damper.nodes.damper_node import DamperNode
from pentapod_sim.interface import TCP_STATE
from pentapod_sim.nodes.common import set_stamp

JOINTS = ['tcp_x', 'tcp_y', 'tcp_z', 'tcp_rx', 'tcp_ry', 'tcp_rz']
GAIN = 2000.0       # N s/m


@pytest.fixture
def damper():
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=int(os.environ.get('ROS_DOMAIN_ID', '0')))
    node = DamperNode(context=context, cli_args=[
        '--ros-args', '-p', "tcp_directions:=['x']", '-p', f'tcp_gain:={GAIN}'])
    sent = []

    class Out:       # the force outlet: what the damper would publish, and for which stamp
        @staticmethod
        def publish(msg):
            sent.append((msg.header.stamp.nanosec, list(msg.effort)))
    node.force_out = Out()
    yield node, sent
    node.destroy_node()
    rclpy.shutdown(context=context)


def state(stamp_ns: int, velocity: float) -> JointState:
    msg = JointState(name=JOINTS, position=[0.0] * 6, velocity=[velocity] + [0.0] * 5,
                     effort=[0.0] * 6)
    set_stamp(msg.header.stamp, stamp_ns)
    return msg


def test_the_cached_answer_goes_only_to_the_state_it_was_computed_from(damper):
    node, sent = damper
    node._on_state(TCP_STATE, state(500_000, 0.001))            # step 1 of the plant
    assert sent == [(500_000, [-GAIN * 0.001])]
    node._on_state(TCP_STATE, state(500_000, 0.001))            # re-sent while it waits
    assert sent[-1] == (500_000, [-GAIN * 0.001]) and len(sent) == 2
    node._on_state(TCP_STATE, state(500_000, 50.0))             # forged, same stamp
    assert len(sent) == 2, 'a forged state of the answered stamp got an answer'
    assert node.rejected == {'conflict': 1}
    node._on_state(TCP_STATE, state(1_000_000, 0.002))          # the next real step
    assert sent[-1] == (1_000_000, [-GAIN * 0.002])


def test_a_forged_step_ahead_does_not_answer_the_real_one(damper):
    """
    Forged t_{k+1} first, then the real t_{k+1}: the forged answer is not re-sent for it.

    The forged message is answered (nothing tells it apart inside the source; the writer check
    refuses its writer), but the real message of that stamp is refused as a conflict instead
    of getting the cached answer computed from the forged state.
    """
    node, sent = damper
    node._on_state(TCP_STATE, state(500_000, 0.001))
    node._on_state(TCP_STATE, state(1_000_000, 50.0))           # forged, one step ahead
    node._on_state(TCP_STATE, state(1_000_000, 0.002))          # the real step
    assert [s for s in sent if s[0] == 1_000_000] == [(1_000_000, [-GAIN * 50.0])]
    assert node.rejected == {'conflict': 1}
