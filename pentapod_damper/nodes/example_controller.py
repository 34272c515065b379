"""
Example controller: copy this file to write your own controller against the lockstep contract.

The contract (docs/nodes.md):

1. The plant publishes the outputs y_k of step k on the state topics (here
   /pentapod/tcp_state, sensor_msgs/JointState) with ``header.stamp`` = t_k.
2. Your node answers that step ONCE on /pentapod/forces/<source name> with a JointState whose
   ``name`` lists plant input ports, ``effort`` the forces [N] / moments [N m] and
   ``header.stamp`` the SAME stamp t_k.
3. The plant waits (timing ``lockstep``) until every configured source answered, applies the
   sum of the forces over [t_k, t_k+1) and publishes step k+1. If a stamp arrives twice (the
   plant re-publishes when an answer is slow), send the same answer again without advancing
   your controller state.
4. Add your source name to the plant's ``sources`` parameter (and optionally
   ``source_ports.<name>``).

This example is a TCP damper in x with gain ``gain`` [N s/m]: u = -gain * v_x.
"""
import sys

from rcl_interfaces.msg import ParameterDescriptor
import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from sensor_msgs.msg import JointState

from pentapod_sim.interface import force_topic, TCP_STATE
from pentapod_sim.nodes.common import FORCE_QOS, STATE_QOS


class ExampleController(Node):
    """Velocity feedback on the TCP x direction."""

    def __init__(self):
        super().__init__('example_controller')
        # every parameter with a descriptor that states its unit
        self.gain = self.declare_parameter('gain', 1000.0, ParameterDescriptor(
            description='damping of the TCP in x [N s/m]')).value
        name = self.declare_parameter('source_name', 'example', ParameterDescriptor(
            description='answers on /pentapod/forces/<source_name>', read_only=True)).value
        self.pub = self.create_publisher(JointState, force_topic(name), FORCE_QOS)
        self.sub = self.create_subscription(JointState, TCP_STATE, self.on_state, STATE_QOS)
        self.last_stamp = None
        self.last_answer = None

    def on_state(self, msg: JointState) -> None:
        """Answer one plant step."""
        stamp = (msg.header.stamp.sec, msg.header.stamp.nanosec)
        if stamp == self.last_stamp:            # the plant re-sent this step: same answer
            self.pub.publish(self.last_answer)
            return
        v_x = msg.velocity[msg.name.index('tcp_x')]                  # [m/s]
        answer = JointState(name=['tcp_force_x'], effort=[-self.gain * v_x])  # [N]
        answer.header.stamp = msg.header.stamp  # the step this answers
        self.pub.publish(answer)
        self.last_stamp, self.last_answer = stamp, answer


def main(argv=None) -> int:
    """Spin with spin_once on the EventsExecutor (much faster per step than rclpy.spin)."""
    rclpy.init(args=sys.argv if argv is None else argv)
    node = ExampleController()
    try:
        from rclpy.experimental import EventsExecutor
        executor = EventsExecutor()
    except ImportError:
        executor = rclpy.executors.SingleThreadedExecutor()
    executor.add_node(node)
    try:
        while rclpy.ok():
            executor.spin_once(timeout_sec=0.1)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
