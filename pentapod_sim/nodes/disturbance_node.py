"""
Disturbance node: seeded white noise on chosen plant input ports, answering every plant step.

A lockstep force source like the exciter (it answers each /clock tick t_k on
/pentapod/forces/<name>), but on any input ports and independent on each
(:class:`pentapod_sim.sim.disturbance.PortNoise`): the excitation with which the judge
identifies a controller in the loop (its FRF from the outputs it reads to the efforts it
answers). Its force of step k = t_k / dt depends on the seed and k alone, so the offline loop
applies the same values.
"""
from __future__ import annotations

from pentapod_sim.errors import ConfigError
from pentapod_sim.interface import stamp_ns, step_of
from pentapod_sim.nodes.common import run_node
from pentapod_sim.nodes.lockstep_source import LockstepSource
from pentapod_sim.nodes.parameter_tables import DisturbanceParams
from pentapod_sim.sim.disturbance import PortNoise


class DisturbanceNode(LockstepSource):
    """White noise on input ports, driven by /clock."""

    Params = DisturbanceParams

    def __init__(self, **kwargs):
        super().__init__('disturbance', **kwargs)
        self.dt = self.params.dt
        try:
            self.noise = PortNoise(self.params.ports, self.params.amplitude, self.params.seed)
        except ConfigError as err:
            raise ConfigError(f'disturbance parameters: {err}') from None
        self.setup([], self.noise.actuator_ports)
        self.get_logger().info(f'white noise of {self.params.amplitude:g} RMS on '
                               f'{", ".join(self.noise.actuator_ports)} (seed '
                               f'{self.params.seed})')

    def compute(self, ns: int, sensors):
        """Efforts of step k = round(t_k / dt)."""
        k = step_of(ns, self.dt)
        if stamp_ns(k, self.dt) != ns:
            raise ConfigError(f'stamp {ns} ns is not a step of sample_rate '
                              f'{1 / self.dt} Hz; set the same sample_rate as the plant')
        return self.noise.force(k)


def main(argv=None) -> int:
    """Entry point of ``ros2 run pentapod_testbed disturbance``."""
    return run_node(DisturbanceNode, argv)


if __name__ == '__main__':
    raise SystemExit(main())
