"""
Exciter node: a force at the TCP (impulse, step, sine, chirp, band-limited random).

It is a lockstep force source: every /clock tick t_k it answers on /pentapod/forces/<name>
(ports tcp_force_{x,y,z}, efforts [N]) and publishes the applied force on
/pentapod/excitation (geometry_msgs/WrenchStamped, force [N], torque zero). The signal is
:class:`pentapod_sim.sim.excitation.Excitation` evaluated at step k = t_k / dt, so the offline
closed loop applies bit-identical forces.
"""
from __future__ import annotations

import math

from geometry_msgs.msg import WrenchStamped

from pentapod_sim.errors import ConfigError
from pentapod_sim.interface import EXCITATION, stamp_ns, step_of
from pentapod_sim.nodes.common import declare, INFO_QOS, run_node
from pentapod_sim.nodes.lockstep_source import LockstepSource
from pentapod_sim.sim.excitation import Excitation, ExcitationSpec, KINDS

TCP_PORTS = ['tcp_force_x', 'tcp_force_y', 'tcp_force_z']


def excitation_spec(node) -> tuple[ExcitationSpec, float]:
    """Declare the exciter parameters and return the signal spec and the sample rate [Hz]."""
    d = node
    rate = declare(d, 'sample_rate', 5000.0, 'plant sample rate [Hz] (same as the plant)',
                   read_only=True, low=1.0, high=1e6)
    spec = ExcitationSpec(
        kind=declare(d, 'kind', 'impulse', 'one of ' + ', '.join(KINDS), read_only=True),
        amplitude=declare(d, 'amplitude', 100.0, 'peak force [N] (RMS for random)',
                          read_only=True, low=-1e9, high=1e9),
        direction=declare(d, 'direction', [1.0, 0.0, 0.0], 'force direction x, y, z in the '
                          'machine frame (normalised)', read_only=True, array='double[]'),
        frequency=declare(d, 'frequency', 40.0, 'sine frequency [Hz]', read_only=True,
                          low=0.0, high=1e6),
        f_start=declare(d, 'f_start', 5.0, 'chirp start / random band low edge [Hz]',
                        read_only=True, low=0.0, high=1e6),
        f_end=declare(d, 'f_end', 300.0, 'chirp end / random band high edge [Hz]',
                      read_only=True, low=0.0, high=1e6),
        duration=declare(d, 'duration', 0.0, 'signal length [s]; 0 = endless (impulse, step, '
                         'sine)', read_only=True, low=0.0, high=1e7),
        start_delay=declare(d, 'start_delay', 0.0, 'time of the first non-zero force [s]',
                            read_only=True, low=0.0, high=1e7),
        pulse_width=declare(d, 'pulse_width', 0.0, 'impulse length [s]; 0 = one sample',
                            read_only=True, low=0.0, high=1e3),
        seed=declare(d, 'seed', 0, 'random seed', read_only=True, low=0, high=2 ** 31))
    if spec.duration == 0.0:
        spec.duration = math.inf
    return spec, rate


class ExciterNode(LockstepSource):
    """Force source at the TCP driven by /clock."""

    def __init__(self, **kwargs):
        super().__init__('exciter', **kwargs)
        spec, rate = excitation_spec(self)
        self.dt = 1.0 / rate
        try:
            self.signal = Excitation(spec, self.dt)
        except ConfigError as err:
            raise ConfigError(f'exciter parameters: {err}') from None
        self.setup([], TCP_PORTS)
        self.wrench_pub = self.create_publisher(WrenchStamped, EXCITATION, INFO_QOS)
        self.info_pubs.append(self.wrench_pub)
        self.get_logger().info(f'{spec.kind} excitation, {spec.amplitude} N along '
                               f'{self.signal.direction.tolist()}')

    def compute(self, ns: int, sensors):
        """Force at step k = round(t_k / dt) [N]."""
        k = step_of(ns, self.dt)
        if stamp_ns(k, self.dt) != ns:
            raise ConfigError(f'stamp {ns} ns is not a step of sample_rate '
                              f'{1 / self.dt} Hz; set the same sample_rate as the plant')
        return self.signal.force(k)

    def after_publish(self, stamp, efforts) -> None:
        """Publish the applied force."""
        msg = WrenchStamped()
        msg.header.stamp = stamp
        msg.header.frame_id = 'tcp'
        msg.wrench.force.x, msg.wrench.force.y, msg.wrench.force.z = map(float, efforts)
        self.wrench_pub.publish(msg)


def main(argv=None) -> int:
    """Entry point of ``ros2 run pentapod_testbed exciter``."""
    return run_node(ExciterNode, argv)


if __name__ == '__main__':
    raise SystemExit(main())
