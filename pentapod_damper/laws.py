"""
Damper and proof-mass-actuator laws, free of ROS (used by the nodes and the offline loop).

A law reads plant output ports (``sensor_ports``) and drives plant input ports
(``actuator_ports``). :meth:`step` is called once per plant step k with the outputs y_k and
returns u_k for its actuator ports (lockstep convention of docs/architecture.md). Laws that are
memoryless and linear also return their gain matrix from :meth:`linear_gain`, which the
offline fast path folds into a closed-loop system.

Units: forces N, moments N m, velocities m/s, angular rates rad/s, masses kg, gains as stated.
"""
from __future__ import annotations

import logging
from typing import Sequence

import numpy as np
import numpy.typing as npt
import scipy.signal

from pentapod_sim.errors import ConfigError
from pentapod_sim.plant.ports import AXES, collocated_output, N_STRUTS

LOG = logging.getLogger(__name__)


def _positive(name: str, value: float, allow_zero: bool = False) -> float:
    """Return ``value`` as float or raise ConfigError naming the parameter."""
    value = float(value)
    if not np.isfinite(value) or value < 0 or (value == 0 and not allow_zero):
        raise ConfigError(f'{name} must be {">= 0" if allow_zero else "> 0"} and finite, '
                          f'got {value!r}')
    return value


class ViscousDamper:
    """
    Collocated viscous velocity feedback ``u_j = -b_j * rate_j``.

    Parameters
    ----------
    actuator_ports : sequence of str
        Input ports driven (forces [N] or moments [N m]).
    gains : float or sequence of float
        Damping b per actuator: N s/m for forces, N m s/rad for moments; >= 0.

    Notes
    -----
    The sensor of each actuator is its collocated velocity output
    (:func:`pentapod_sim.plant.ports.collocated_output`), so the law only removes energy.
    """

    def __init__(self, actuator_ports: Sequence[str], gains: float | Sequence[float]):
        self.actuator_ports = list(actuator_ports)
        self.sensor_ports = [collocated_output(p, 'velocity') for p in self.actuator_ports]
        gains = np.broadcast_to(np.asarray(gains, dtype=float), (len(self.actuator_ports),))
        for port, gain in zip(self.actuator_ports, gains):
            _positive(f'damping gain of {port}', gain, allow_zero=True)
        self.gains = np.array(gains)

    def reset(self) -> None:
        """Memoryless: nothing to reset."""

    def step(self, sensors: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        """Return the actuator efforts -b * rate for the sensor values of this step."""
        return -self.gains * sensors

    def linear_gain(self) -> npt.NDArray[np.float64]:
        """Gain matrix (n_actuators, n_sensors) of u = K y."""
        return -np.diag(self.gains)


def strut_bending_damper(struts: Sequence[int], gain: float) -> ViscousDamper:
    """Bending dampers on both cardan axes (2, 3) of each strut; gain [N m s/rad]."""
    return ViscousDamper([f'strut{i}_bending_moment_{k}' for i in _struts(struts)
                          for k in (2, 3)], gain)


def strut_axial_damper(struts: Sequence[int], gain: float) -> ViscousDamper:
    """Axial dampers between strut and BP ring; gain [N s/m]."""
    return ViscousDamper([f'strut{i}_axial_force' for i in _struts(struts)], gain)


def tcp_damper(directions: Sequence[str], gain: float) -> ViscousDamper:
    """Dampers from the TCP to ground in the given directions (x, y, z); gain [N s/m]."""
    return ViscousDamper([f'tcp_force_{a}' for a in _axes(directions)], gain)


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


class ProofMassActuator:
    """
    Ideal inertial actuator on ``pma_mount``: the proof mass is accelerated by ``g v``.

    The actuator pushes the proof mass m_a with ``F_a = m_a g v_f`` (v_f: measured mount
    velocity, optionally high-passed) and the structure with the reaction ``-F_a``, which is a
    viscous damper of ``b = m_a g`` for frequencies above the high-pass. The proof mass is
    integrated exactly for a force held over the step; the mount moves with the sampled
    velocity over the step.

    Parameters
    ----------
    directions : sequence of str
        Axes (x, y, z) with one actuator each.
    mass : float
        Proof mass m_a [kg], > 0.
    gain : float
        g [1/s], >= 0 (damping b = m_a g [N s/m]).
    dt : float
        Sample time [s].
    highpass_hz : float
        Corner of a 2nd-order Butterworth high-pass on the velocity [Hz]; 0 = none.
    stroke_limit : float
        Max |stroke| [m] (proof mass relative to the mount); 0 = unlimited.
    force_limit : float
        Max |F_a| commanded [N]; 0 = unlimited. At the stroke limit an ideal end stop adds
        the force that holds the proof mass at the limit (it may exceed ``force_limit``).
    """

    def __init__(self, directions: Sequence[str], mass: float, gain: float, dt: float,
                 highpass_hz: float = 0.0, stroke_limit: float = 0.0, force_limit: float = 0.0):
        axes = _axes(directions)
        self.actuator_ports = [f'pma_force_{a}' for a in axes]
        self.sensor_ports = [f'pma_mount_velocity_{a}' for a in axes]
        self.mass = _positive('proof mass m_a [kg]', mass)
        self.gain = _positive('gain g [1/s]', gain, allow_zero=True)
        self.dt = _positive('sample time dt [s]', dt)
        self.highpass_hz = _positive('highpass_hz', highpass_hz, allow_zero=True)
        if self.highpass_hz >= 0.5 / self.dt:
            raise ConfigError(f'highpass_hz {self.highpass_hz} must be below Nyquist '
                              f'{0.5 / self.dt} Hz')
        self.stroke_limit = _positive('stroke_limit [m]', stroke_limit, allow_zero=True)
        self.force_limit = _positive('force_limit [N]', force_limit, allow_zero=True)
        self.sos = (scipy.signal.butter(2, self.highpass_hz, 'highpass', fs=1 / self.dt,
                                        output='sos')[0] if self.highpass_hz > 0 else None)
        self.reset()

    def reset(self) -> None:
        """Proof mass at rest in the middle of its stroke; filter at rest."""
        n = len(self.actuator_ports)
        self.stroke = np.zeros(n)          # proof-mass displacement relative to the mount [m]
        self.mass_velocity = np.zeros(n)   # absolute proof-mass velocity [m/s]
        self.force = np.zeros(n)           # F_a on the proof mass over the last step [N]
        self._hp_state = np.zeros((n, 2))
        self.limit_hits = {'stroke': 0, 'force': 0}

    def _highpass(self, v: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        """One sample of the biquad (transposed direct form II, scipy's sosfilt recursion).

        Written out because a sosfilt call per sample costs ~20 us of overhead.
        """
        b0, b1, b2, _, a1, a2 = self.sos
        z = self._hp_state
        out = b0 * v + z[:, 0]
        z[:, 0] = b1 * v - a1 * out + z[:, 1]
        z[:, 1] = b2 * v - a2 * out
        return out

    def step(self, sensors: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        """
        Advance the proof mass over one step and return the force on the structure [N].

        Parameters
        ----------
        sensors : (n,) ndarray
            Mount velocity v_k [m/s] per axis.
        """
        v = np.asarray(sensors, dtype=float)
        v_f = self._highpass(v) if self.sos is not None else v
        force = self.mass * self.gain * v_f
        if self.force_limit > 0:
            clipped = np.clip(force, -self.force_limit, self.force_limit)
            self.limit_hits['force'] += int(np.count_nonzero(clipped != force))
            force = clipped
        half_dt2_m = 0.5 * self.dt ** 2 / self.mass
        free = self.stroke + self.dt * (self.mass_velocity - v)
        if self.stroke_limit > 0:
            target = np.clip(free + half_dt2_m * force, -self.stroke_limit, self.stroke_limit)
            limited = (target - free) / half_dt2_m
            hit = np.abs(limited - force) > 1e-12 * (1 + np.abs(force))
            self.limit_hits['stroke'] += int(np.count_nonzero(hit))
            force = np.where(hit, limited, force)
        self.stroke = free + half_dt2_m * force
        self.mass_velocity = self.mass_velocity + self.dt / self.mass * force
        self.force = force
        return -force

    def linear_gain(self) -> npt.NDArray[np.float64] | None:
        """``-m_a g I`` when there is no filter or limit, else None (the law has memory)."""
        if self.sos is not None or self.stroke_limit > 0 or self.force_limit > 0:
            return None
        return -self.mass * self.gain * np.eye(len(self.actuator_ports))
