"""
Exciter node: a force at the TCP, answering every plant step.

Signals: impulse, step, sine, chirp, band-limited random, multisine, periodic chirp, stepped
sine (docs/nodes.md, "Excitation signals"). It is a lockstep force source: every /clock tick
t_k it answers on /pentapod/forces/<name> (ports tcp_force_{x,y,z}, efforts [N]) and publishes
the applied force on /pentapod/excitation (geometry_msgs/WrenchStamped, force [N], torque
zero). The signal is
:class:`pentapod_sim.sim.excitation.Excitation` evaluated at step k = t_k / dt, so the offline
closed loop applies bit-identical forces. At start it publishes the signal's parameters once
on /pentapod/excitation_spec/<name> (std_msgs/String, JSON, transient local), so a recording
holds them for the analysis.
"""
from __future__ import annotations

from geometry_msgs.msg import WrenchStamped
from std_msgs.msg import String

from pentapod_sim.errors import ConfigError
from pentapod_sim.interface import EXCITATION, excitation_spec_topic, stamp_ns, step_of
from pentapod_sim.nodes.common import qos, run_node
from pentapod_sim.nodes.lockstep_source import LockstepSource
from pentapod_sim.nodes.parameter_tables import ExciterParams
from pentapod_sim.sim.excitation import Excitation
from pentapod_sim.sim.excitation_spec import spec_message

TCP_PORTS = ['tcp_force_x', 'tcp_force_y', 'tcp_force_z']


class ExciterNode(LockstepSource):
    """Force source at the TCP driven by /clock."""

    Params = ExciterParams

    def __init__(self, **kwargs):
        super().__init__('exciter', **kwargs)
        spec = self.params.spec()
        self.dt = self.params.dt
        try:
            self.signal = Excitation(spec, self.dt)
        except ConfigError as err:
            raise ConfigError(f'exciter parameters: {err}') from None
        self.setup([], TCP_PORTS)
        self.wrench_out = self.info_outlet(WrenchStamped, EXCITATION)
        self.wrench = WrenchStamped()
        self.wrench.header.frame_id = 'tcp'
        self.spec_pub = self.create_publisher(String, excitation_spec_topic(self.source_name),
                                              qos('spec'))
        self.spec_pub.publish(String(data=spec_message(spec, self.params.sample_rate,
                                                       self.source_name)))
        self.get_logger().info(describe(self.signal))

    def compute(self, ns: int, sensors):
        """Force at step k = round(t_k / dt) [N]."""
        k = step_of(ns, self.dt)
        if stamp_ns(k, self.dt) != ns:
            raise ConfigError(f'stamp {ns} ns is not a step of sample_rate '
                              f'{1 / self.dt} Hz; set the same sample_rate as the plant')
        return self.signal.force(k)

    def after_publish(self, stamp, efforts) -> None:
        """Publish the applied force (one message object, refilled every step)."""
        msg = self.wrench
        msg.header.stamp.sec, msg.header.stamp.nanosec = stamp.sec, stamp.nanosec
        force = msg.wrench.force
        force.x, force.y, force.z = map(float, efforts)
        self.wrench_out.publish(msg)


def describe(signal: Excitation) -> str:
    """The start log line: kind, amplitude, direction, crest factor, period and lines."""
    spec = signal.spec
    text = (f'{spec.kind} excitation, {spec.amplitude} N along {signal.direction.tolist()}, '
            f'crest factor {signal.crest_factor:.3f}')
    if signal.period_steps is not None:
        text += (f', period {signal.period_steps} steps, {len(signal.lines_hz)} lines, '
                 f'{signal.settle_periods} settling period(s)')
    windows = signal.stepped_windows()
    if windows:
        text += (f', {len(windows)} lines over '
                 f'{(windows[-1][2] - signal.first) * signal.dt:.6g} s')
    return text


def main(argv=None) -> int:
    """Entry point of ``ros2 run pentapod_testbed exciter``."""
    return run_node(ExciterNode, argv)


if __name__ == '__main__':
    raise SystemExit(main())
