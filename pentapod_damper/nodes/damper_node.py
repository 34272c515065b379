"""
Damper node: viscous velocity feedback u = -b * rate on struts and the TCP, and active strut laws.

One node may serve several dampers: strut bending dampers (moment pairs about e2 and e3 from
the bending rates, b [N m s/rad]), strut chord dampers (lateral force pairs along e2 and e3 at
the chord point against the chord, b [N s/m]), strut axial dampers (force from the axial
velocity, b [N s/m]) and TCP dampers against ground (force from the TCP velocity, b [N s/m]),
and the active strut laws of docs/dampers.md (integral force feedback from the load cells,
lag displacement, band-pass velocity and positive position feedback on the strut ports, and
the feed drives' servo cascade with IFF inside, HAC-LAC, on a plant with the drives),
all optionally through the same low-pass and delay (``filter_order``, ``bandwidth_hz``,
``filter_damping``, ``delay_steps``; controller states reset with every new plant run). It answers
every plant step on /pentapod/forces/<source_name> (lockstep contract, docs/nodes.md). The
gains may be changed at run time (``ros2 param set``; ``drive_iff_gain`` rebuilds the drives'
cascade with the new IFF gain, between values > 0); everything else is read-only. The node
publishes the linear model of its laws on /pentapod/controller_models/<source_name> for the
plant's truncation check, again after a gain changed.
"""
from __future__ import annotations

import numpy as np
from rcl_interfaces.msg import SetParametersResult

from pentapod_damper.laws.linear import DrivesLaw
from pentapod_damper.node_parameters import DamperParams
from pentapod_sim.errors import ConfigError
from pentapod_sim.nodes.common import run_node
from pentapod_sim.nodes.lockstep_source import LockstepSource
from pentapod_sim.sim.controllers import controller_of, DiscreteController, parallel


class DamperNode(LockstepSource):
    """Viscous dampers and active strut laws on selected struts and TCP directions."""

    Params = DamperParams

    def __init__(self, **kwargs):
        super().__init__('damper', **kwargs)
        self.laws = self.params.laws()
        if not self.laws:
            raise ConfigError('damper node has no damper: set bending_struts, chord_struts, '
                              'axial_struts, tcp_directions, iff_struts, lag_struts, '
                              'bandpass_struts, ppf_struts or drive_struts')
        laws = list(self.laws.values())
        self.setup([p for law in laws for p in law.sensor_ports],
                   [p for law in laws for p in law.actuator_ports])
        self._slices = []
        start = 0
        for law in laws:
            self._slices.append((slice(start, start + len(law.sensor_ports)), law))
            start += len(law.sensor_ports)
        self.add_on_set_parameters_callback(self._on_set)
        self.get_logger().info(f'dampers on {self.actuator_ports}')

    def _on_set(self, params) -> SetParametersResult:
        """
        Apply new gains (range already checked by rclpy).

        The drives' cascade is rebuilt with a new ``drive_iff_gain``
        (:class:`pentapod_damper.laws.linear.DrivesLaw`); refused (nothing applied) if it
        would add or drop the load cells.
        """
        for p in params:
            law = self.laws.get(p.name)
            if isinstance(law, DrivesLaw):
                try:
                    law.with_iff_gain(float(p.value))
                except ConfigError as err:
                    return SetParametersResult(successful=False, reason=str(err))
        for p in params:
            if p.name in self.laws:
                law = self.laws[p.name]
                law.gains = np.full(len(law.actuator_ports), float(p.value))
        return SetParametersResult(successful=True)

    def linear_model(self) -> DiscreteController:
        """Every damper of the node side by side (their ports in the node's order)."""
        return parallel([controller_of(law) for law in self.laws.values()])

    def reset(self) -> None:
        """Filter and delay states of every law back to zero (a new plant run started)."""
        for law in self.laws.values():
            law.reset()

    def compute(self, ns: int, sensors: np.ndarray) -> np.ndarray:
        """U = -b * rate for every damper of this node."""
        if len(self._slices) == 1:
            return self._slices[0][1].step(sensors)
        return np.concatenate([law.step(sensors[sl]) for sl, law in self._slices])


def main(argv=None) -> int:
    """Entry point of ``ros2 run pentapod_testbed damper``."""
    return run_node(DamperNode, argv)


if __name__ == '__main__':
    raise SystemExit(main())
