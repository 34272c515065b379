"""
Viscous velocity feedback on collocated ports, optionally through actuator/sensor dynamics.

A viscous damper reads the velocity output collocated with its actuator port, so the memoryless
law only removes energy; with :class:`~pentapod_sim.sim.law_models.Dynamics` (a low-pass and a
delay of n samples, ``delay_steps`` = 1 being the one-sample computational delay of a real
digital controller) it has controller states and offers its discrete state space from
:meth:`ViscousDamper.discrete_model`.

Units: forces N, moments N m, velocities m/s, angular rates rad/s, gains as stated.
"""
from __future__ import annotations

import logging
from typing import Sequence

import numpy as np
import numpy.typing as npt

from pentapod_sim.errors import ConfigError
from pentapod_sim.plant.ports import AXES, collocated_output, N_STRUTS
from pentapod_sim.sim.controllers import DiscreteController
from pentapod_sim.sim.law_models import Dynamics
from pentapod_sim.sim.law_models import positive as _positive

LOG = logging.getLogger(__name__)


class ViscousDamper:
    """
    Collocated viscous velocity feedback ``u_j = -b_j * rate_j``, optionally through dynamics.

    Parameters
    ----------
    actuator_ports : sequence of str
        Input ports driven (forces [N] or moments [N m]).
    gains : float or sequence of float
        Damping b per actuator: N s/m for forces, N m s/rad for moments; >= 0.
    dynamics : Dynamics, optional
        Low-pass and delay between sensor and actuator, the same on every channel; default
        none (memoryless).
    dt : float, optional
        Sample time [s]; needed when ``dynamics`` has a filter or a delay.

    Notes
    -----
    The sensor of each actuator is its collocated velocity output
    (:func:`pentapod_sim.plant.ports.collocated_output`), so the memoryless law only removes
    energy. With dynamics ``u = -b H(z) rate``; the gains may still be changed between steps.
    """

    def __init__(self, actuator_ports: Sequence[str], gains: float | Sequence[float],
                 dynamics: Dynamics | None = None, dt: float | None = None):
        self.actuator_ports = list(actuator_ports)
        self.sensor_ports = [collocated_output(p, 'velocity') for p in self.actuator_ports]
        gains = np.broadcast_to(np.asarray(gains, dtype=float), (len(self.actuator_ports),))
        for port, gain in zip(self.actuator_ports, gains):
            _positive(f'damping gain of {port}', gain, allow_zero=True)
        self.gains = np.array(gains)
        self.dynamics = dynamics or Dynamics()
        self.dt = None if dt is None else _positive('sample time dt [s]', dt)
        if self.dynamics.is_static:
            self._siso = None
        elif self.dt is None:
            raise ConfigError(f'dampers on {self.actuator_ports} have dynamics '
                              f'{self.dynamics}; they need the sample time dt')
        else:
            self._siso = self.dynamics.siso(self.dt)
        self.reset()

    def reset(self) -> None:
        """Controller states (filter and delay line of every channel) to zero."""
        n = 0 if self._siso is None else self._siso[0].shape[0]
        self._state = np.zeros((len(self.actuator_ports), n))

    def step(self, sensors: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        """Return the actuator efforts -b * H rate for the sensor values of this step."""
        if self._siso is None:
            return -self.gains * sensors
        a, b, c, d = self._siso
        x = self._state
        filtered = x @ c[0] + d[0, 0] * sensors
        self._state = x @ a.T + np.multiply.outer(sensors, b[:, 0])
        return -self.gains * filtered

    def linear_gain(self) -> npt.NDArray[np.float64] | None:
        """Gain matrix (n_actuators, n_sensors) of u = K y; None with dynamics (memory)."""
        return -np.diag(self.gains) if self._siso is None else None

    def viscous_gains(self) -> npt.NDArray[np.float64]:
        """The nominal damping b per actuator (the ideal viscous damper the law stands for)."""
        return self.gains.copy()

    def discrete_model(self) -> DiscreteController:
        """The law's discrete state space on its ports (controller states channel by channel)."""
        eye = np.eye(len(self.actuator_ports))
        if self._siso is None:
            return DiscreteController.static(self.sensor_ports, self.actuator_ports,
                                             self.linear_gain())
        a, b, c, d = self._siso
        g = -np.diag(self.gains)
        return DiscreteController(self.sensor_ports, self.actuator_ports, np.kron(eye, a),
                                  np.kron(eye, b), g @ np.kron(eye, c), g * d[0, 0])


    def continuous_model(self) -> DiscreteController:
        """
        The law's continuous state space (the low-pass, no delay) on its ports.

        Same container as :meth:`discrete_model`, with continuous matrices (``dxc/dt``), for
        :func:`pentapod_sim.sim.loop_poles.continuous_loop_poles`.
        """
        a, b, c, d = self.dynamics.continuous()
        eye, g = np.eye(len(self.actuator_ports)), -np.diag(self.gains)
        return DiscreteController(self.sensor_ports, self.actuator_ports, np.kron(eye, a),
                                  np.kron(eye, b), g @ np.kron(eye, c), g * d[0, 0])


def strut_bending_damper(struts: Sequence[int], gain: float, dynamics: Dynamics | None = None,
                         dt: float | None = None) -> ViscousDamper:
    """Rotational bending dampers on both cardan axes (2, 3) of each strut; gain [N m s/rad].

    The port is the rotation of the strut's WP end relative to its rear end (paper Fig. 6).
    """
    return ViscousDamper([f'strut{i}_bending_moment_{k}' for i in _struts(struts)
                          for k in (2, 3)], gain, dynamics, dt)


def chord_damper(struts: Sequence[int], gain: float, dynamics: Dynamics | None = None,
                 dt: float | None = None) -> ViscousDamper:
    """Translational lateral dampers at the strut's chord point, along e2 and e3; gain [N s/m].

    Force on the strut at the chord point against its chord between the joints
    (:mod:`pentapod_sim.plant.ports`, ``strut<i>_chord_force_<k>``).
    """
    return ViscousDamper([f'strut{i}_chord_force_{k}' for i in _struts(struts)
                          for k in (2, 3)], gain, dynamics, dt)


def strut_axial_damper(struts: Sequence[int], gain: float, dynamics: Dynamics | None = None,
                       dt: float | None = None) -> ViscousDamper:
    """Axial dampers between strut and BP ring; gain [N s/m]."""
    return ViscousDamper([f'strut{i}_axial_force' for i in _struts(struts)], gain, dynamics, dt)


def tcp_damper(directions: Sequence[str], gain: float, dynamics: Dynamics | None = None,
               dt: float | None = None) -> ViscousDamper:
    """Dampers from the TCP to ground in the given directions (x, y, z); gain [N s/m]."""
    return ViscousDamper([f'tcp_force_{a}' for a in _axes(directions)], gain, dynamics, dt)


def _struts(struts: Sequence[int]) -> list[int]:
    """Check strut numbers 1..5."""
    out = [int(i) for i in struts]
    for i in out:
        if not 1 <= i <= N_STRUTS:
            raise ConfigError(f'strut number {i} is outside 1..{N_STRUTS}')
    if len(set(out)) != len(out):
        raise ConfigError(f'strut numbers {out} repeat')
    return out


def _axes(directions: Sequence[str]) -> list[str]:
    """Check direction names x, y, z."""
    out = [str(a).lower() for a in directions]
    for a in out:
        if a not in AXES:
            raise ConfigError(f'direction {a!r} is not one of x, y, z')
    if len(set(out)) != len(out):
        raise ConfigError(f'directions {out} repeat')
    return out
