"""
Proof-mass actuator (PMA) node on the working platform.

It acts on the ports pma_force_* and senses pma_mount_velocity_*.

The ideal law of :class:`pentapod_damper.laws.ProofMassActuator`: the proof mass m_a [kg] is
accelerated by g v (g [1/s], v the mount velocity, optionally high-passed), the structure gets
the reaction -m_a g v, i.e. viscous damping b = m_a g [N s/m]. Stroke and force limits are
optional. Answers each step on /pentapod/forces/<source_name> and publishes
/pentapod/pma/state (sensor_msgs/JointState, joints pma_{x,y,z}: position = stroke of the
proof mass relative to the mount [m] after the step, velocity = proof-mass velocity [m/s],
effort = force on the structure over the step [N]). The ideal law's linear model (damping
m_a g) goes to the plant's truncation check; with a high-pass or limits it has none and the
plant names the PMA as unchecked.
"""
from __future__ import annotations

import array

from sensor_msgs.msg import JointState

from pentapod_damper.node_parameters import PmaParams
from pentapod_sim.interface import PMA_STATE
from pentapod_sim.nodes.common import run_node
from pentapod_sim.nodes.lockstep_source import LockstepSource
from pentapod_sim.sim.controllers import controller_of, DiscreteController


class PmaNode(LockstepSource):
    """Proof-mass actuator as a lockstep force source."""

    Params = PmaParams

    def __init__(self, **kwargs):
        super().__init__('pma', **kwargs)
        self.law = self.params.law()
        self.setup(self.law.sensor_ports, self.law.actuator_ports)
        self.joints = [p.replace('pma_force_', 'pma_') for p in self.law.actuator_ports]
        self.state_out = self.info_outlet(JointState, PMA_STATE)
        self.state = JointState(name=self.joints)     # refilled every step
        self.get_logger().info(f'PMA m_a = {self.law.mass} kg, g = {self.law.gain} 1/s '
                               f'(b = {self.law.mass * self.law.gain:.6g} N s/m) on '
                               f'{self.law.actuator_ports}')

    def compute(self, ns, sensors):
        """Advance the proof mass one step and return the force on the structure [N]."""
        return self.law.step(sensors)

    def linear_model(self) -> DiscreteController:
        """The ideal PMA's damping ``-m_a g`` (ConfigError with a high-pass or limits)."""
        return controller_of(self.law)

    def reset(self) -> None:
        """Proof mass back to rest for a new plant run."""
        self.law.reset()

    def after_publish(self, stamp, efforts) -> None:
        """Publish stroke, proof-mass velocity and force."""
        msg = self.state
        msg.position = array.array('d', self.law.stroke.tobytes())
        msg.velocity = array.array('d', self.law.mass_velocity.tobytes())
        msg.effort = array.array('d', efforts.tobytes())
        msg.header.stamp.sec, msg.header.stamp.nanosec = stamp.sec, stamp.nanosec
        self.state_out.publish(msg)


def main(argv=None) -> int:
    """Entry point of ``ros2 run pentapod_testbed pma``."""
    return run_node(PmaNode, argv)


if __name__ == '__main__':
    raise SystemExit(main())
