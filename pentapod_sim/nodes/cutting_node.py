"""
Cutting-process node: regenerative milling at the TCP, answering every plant step.

A lockstep force source like the exciter, but closed around the plant: every step t_k it
reads the TCP displacement (``tcp_displacement_{x,y}`` on /pentapod/tcp_state), computes the
chip of every tooth from the displacement now and the surface the previous tooth left one tooth
period ago (:class:`pentapod_sim.machining.cutting_process.CuttingProcess`: a ring buffer of
one tooth period, the non-integer delay interpolated, the tool leaving the cut where h <= 0;
the helix ignored) and answers on /pentapod/forces/<name> with the cutting force on the TCP
(ports ``tcp_force_{x,y}`` [N]). Its state goes out every step on /pentapod/cutting/state
(tooth angles, chips, tangential forces; layout in :mod:`pentapod_sim.interface`), its
operation once on /pentapod/cutting/spec (JSON, transient local), so a recording can be judged
with ``analyze chatter BAG``. The process is the same object the offline loop steps
(:func:`pentapod_sim.machining.cutting_process.simulate_cut`), so a run reproduces it bit for
bit. The linear model for the plant's truncation check is the averaged regenerative loop
(:mod:`pentapod_sim.machining.cutting_model`: what that check can and cannot say).
"""
from __future__ import annotations

import array

from sensor_msgs.msg import JointState
from std_msgs.msg import String

from pentapod_sim.errors import ConfigError
from pentapod_sim.interface import (
    cutting_joints,
    CUTTING_SPEC,
    CUTTING_STATE,
    stamp_ns,
    step_of,
)
from pentapod_sim.machining.cutting_model import regenerative_controller
from pentapod_sim.machining.cutting_process import CuttingProcess
from pentapod_sim.machining.cutting_spec import spec_message
from pentapod_sim.nodes.common import qos, run_node
from pentapod_sim.nodes.lockstep_source import LockstepSource
from pentapod_sim.nodes.parameter_tables import CuttingParams
from pentapod_sim.sim.controllers import DiscreteController


class CuttingNode(LockstepSource):
    """Regenerative milling force at the TCP (lockstep source)."""

    Params = CuttingParams

    def __init__(self, **kwargs):
        super().__init__('cutting', **kwargs)
        self.dt = self.params.dt
        try:
            self.spec = self.params.spec(self.source_name)
            self.process = CuttingProcess(self.spec.conditions, self.dt)
        except ConfigError as err:
            raise ConfigError(f'cutting parameters: {err}') from None
        self.setup(CuttingProcess.sensor_ports, CuttingProcess.actuator_ports)
        cond = self.spec.conditions
        self.state_out = self.info_outlet(JointState, CUTTING_STATE)
        self.state = JointState(name=cutting_joints(cond.cut.teeth))   # refilled every step
        self.spec_pub = self.create_publisher(String, CUTTING_SPEC, qos('spec'))
        self.spec_pub.publish(String(data=spec_message(self.spec)))
        self.get_logger().info(
            f'{self.spec.operation}: {cond.cut.teeth} teeth at {cond.spindle_speed:g} rpm, '
            f'{cond.axial_depth * 1e3:g} mm deep, feed {cond.feed_per_tooth * 1e3:g} mm/tooth, '
            f'K_t {cond.cut.tangential_coefficient:.4g} N/m^2; tooth period '
            f'{cond.tooth_period / self.dt:.2f} steps')

    def compute(self, ns: int, sensors):
        """Cutting force [N] at step k = t_k / dt from the TCP displacement [m]."""
        k = step_of(ns, self.dt)
        if stamp_ns(k, self.dt) != ns:
            raise ConfigError(f'stamp {ns} ns is not a step of sample_rate '
                              f'{1 / self.dt} Hz; set the same sample_rate as the plant')
        return self.process.answer(k, sensors)

    def linear_model(self) -> DiscreteController:
        """The averaged regenerative loop (ConfigError for a tooth period too long)."""
        return regenerative_controller(self.spec.conditions, self.dt)

    def reset(self) -> None:
        """A new plant run: the surface is straight again, the tool at angle zero."""
        self.process.reset()

    def after_publish(self, stamp, efforts) -> None:
        """Publish tooth angles, chips and tangential forces of the step."""
        msg, process = self.state, self.process
        msg.position = array.array('d', process.angles.tobytes())
        msg.velocity = array.array('d', process.chip.tobytes())
        msg.effort = array.array('d', process.tooth_force.tobytes())
        msg.header.stamp.sec, msg.header.stamp.nanosec = stamp.sec, stamp.nanosec
        self.state_out.publish(msg)


def main(argv=None) -> int:
    """Entry point of ``ros2 run pentapod_testbed cutting``."""
    return run_node(CuttingNode, argv)


if __name__ == '__main__':
    raise SystemExit(main())
