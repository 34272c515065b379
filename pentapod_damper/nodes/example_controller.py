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
5. Declare your parameters as a frozen dataclass of ``pentapod_sim.parameters.param`` fields
   (type, default, range, unit, description) and name it ``Params`` in a ``TestbedNode``
   subclass: the node declares them with their descriptors, refuses misspelt names, prints
   them for ``--help`` and hands you the typed values as ``self.params``. This node's are in
   pentapod_damper/node_parameters.py (the registry, pentapod_sim/registry.py, names them);
   yours may live in your node's module. A scenario file runs your class in your own package
   with ``node_class: your_package.module:YourController`` in its node's section.
6. Optionally watch the plant's run status (``PlantRunWatch``, as below): stopped after the
   plant's run ended (the scenario runner stops the sources then), the node says so and exits
   0 instead of ``stopped by SIGINT`` and 130.
7. Optionally publish the linear model of your law once, for the plant's truncation check:
   ``pentapod_sim.nodes.source_model.publish_model(self, source_name, DiscreteController.static(
   ['tcp_velocity_x'], ['tcp_force_x'], [[-gain]]).to_json())``. This example does not, so the
   plant names it as unchecked (docs/statespace.md).

This example is a TCP damper in x with gain ``gain`` [N s/m]: u = -gain * v_x.
"""
from sensor_msgs.msg import JointState

from pentapod_damper.node_parameters import ExampleControllerParams
from pentapod_sim.interface import force_topic, TCP_STATE
from pentapod_sim.nodes.common import (
    FORCE_QOS,
    run_node,
    STATE_SUB_QOS,  # new steps only, no writer history
)
from pentapod_sim.nodes.run_status import PlantRunWatch
from pentapod_sim.nodes.testbed_node import TestbedNode


class ExampleController(TestbedNode):
    """Velocity feedback on the TCP x direction."""

    # every parameter with its type, default, range and a description with the unit; the
    # node declares them and refuses unknown names
    Params = ExampleControllerParams

    def __init__(self, **kwargs):
        super().__init__('example_controller', **kwargs)
        self.gain = self.params.gain
        self.pub = self.create_publisher(JointState, force_topic(self.params.source_name),
                                         FORCE_QOS)
        self.sub = self.create_subscription(JointState, TCP_STATE, self.on_state, STATE_SUB_QOS)
        self.last_stamp = None
        self.last_answer = None
        self.plant_run = PlantRunWatch(self)

    def stopped_after_run_end(self) -> bool:
        """After a stop signal (run_node asks): True if the plant's run had ended: exit 0."""
        return self.plant_run.explains_stop()

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
    return run_node(ExampleController, argv)


if __name__ == '__main__':
    raise SystemExit(main())
