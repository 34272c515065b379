"""
Damper and proof-mass-actuator laws, free of ROS (used by the nodes and the offline loop).

A law reads plant output ports (``sensor_ports``) and drives plant input ports
(``actuator_ports``). :meth:`step` is called once per plant step k with the outputs y_k and
returns u_k for its actuator ports (lockstep convention of docs/architecture.md): sampled
feedback with a zero-order hold, u_k answers y_k. Viscous dampers may carry actuator/sensor
dynamics (:class:`Dynamics`: a first- or second-order low-pass and a pure delay of n samples,
``delay_steps`` = 1 being the one-sample computational delay of a real digital controller);
they then have controller states and offer their discrete state space from
:meth:`ViscousDamper.discrete_model`. Memoryless linear laws return their gain matrix from
:meth:`linear_gain`.

Units: forces N, moments N m, velocities m/s, angular rates rad/s, masses kg, gains as stated.
"""
from __future__ import annotations

from dataclasses import dataclass
import logging
from typing import Sequence

import numpy as np
import numpy.typing as npt
import scipy.signal

from pentapod_sim.errors import ConfigError
from pentapod_sim.plant.ports import AXES, collocated_output, N_STRUTS
from pentapod_sim.sim.controllers import DiscreteController

LOG = logging.getLogger(__name__)


def _positive(name: str, value: float, allow_zero: bool = False) -> float:
    """Return ``value`` as float or raise ConfigError naming the parameter."""
    value = float(value)
    if not np.isfinite(value) or value < 0 or (value == 0 and not allow_zero):
        raise ConfigError(f'{name} must be {">= 0" if allow_zero else "> 0"} and finite, '
                          f'got {value!r}')
    return value


#: Filter orders of :class:`Dynamics`: 0 = none, 1 = first-order, 2 = second-order low-pass.
FILTER_ORDERS = (0, 1, 2)
#: Input assumptions of the exact discretisation: first-order hold (the sensor signal varies
#: linearly between samples) or zero-order hold (held over each step).
HOLDS = ('foh', 'zoh')


@dataclass(frozen=True)
class Dynamics:
    """
    Actuator/sensor dynamics of a law: a low-pass on each channel, then a delay of n samples.

    The low-pass is ``w / (s + w)`` (order 1) or ``w^2 / (s^2 + 2 zeta w s + w^2)`` (order 2)
    with ``w = 2 pi bandwidth_hz``, discretised exactly (:func:`scipy.signal.cont2discrete`;
    discrete poles ``exp(s_i dt)``) for a continuous sensor signal that varies linearly between
    samples (``hold`` 'foh', default: the filter's output at step k answers the samples up to
    and including k) or that is held over each step ('zoh': the output at step k answers the
    samples before k only, one more sample of lag). ``delay_steps`` = n shifts the filtered
    signal by n samples: 0 = plain sampled feedback (u_k answers y_k), 1 = one-sample
    computational delay.

    Attributes
    ----------
    order : int
        0, 1 or 2 (0 = no low-pass).
    bandwidth_hz : float
        Corner frequency [Hz], > 0 and below Nyquist when ``order`` > 0.
    damping : float
        Damping ratio zeta [-] of the second-order low-pass (> 0).
    delay_steps : int
        Pure delay [samples], >= 0.
    hold : str
        'foh' or 'zoh' (input assumption of the discretisation).
    """

    order: int = 0
    bandwidth_hz: float = 0.0
    damping: float = 0.7071067811865476
    delay_steps: int = 0
    hold: str = 'foh'

    def __post_init__(self) -> None:
        """Check the values (ConfigError names the bad one)."""
        if self.order not in FILTER_ORDERS:
            raise ConfigError(f'filter order must be one of {FILTER_ORDERS}, got {self.order!r}')
        if self.order:
            _positive('filter bandwidth [Hz]', self.bandwidth_hz)
            _positive('filter damping ratio [-]', self.damping)
        if self.hold not in HOLDS:
            raise ConfigError(f'filter hold must be one of {HOLDS}, got {self.hold!r}')
        if int(self.delay_steps) != self.delay_steps or self.delay_steps < 0:
            raise ConfigError(f'delay_steps must be an integer >= 0, got {self.delay_steps!r}')

    @property
    def is_static(self) -> bool:
        """True without filter and delay (the law stays memoryless)."""
        return self.order == 0 and self.delay_steps == 0

    def continuous(self) -> tuple[np.ndarray, ...]:
        """Continuous state space (a, b, c, d) of the low-pass of one channel (no delay)."""
        w = 2 * np.pi * self.bandwidth_hz
        if self.order == 1:
            cont = ([[-w]], [[w]], [[1.0]], [[0.0]])
        elif self.order == 2:
            cont = ([[0.0, 1.0], [-w * w, -2 * self.damping * w]], [[0.0], [w * w]],
                    [[1.0, 0.0]], [[0.0]])
        else:
            cont = (np.zeros((0, 0)), np.zeros((0, 1)), np.zeros((1, 0)), [[1.0]])
        return tuple(np.array(m, dtype=float) for m in cont)

    def siso(self, dt: float) -> tuple[np.ndarray, ...]:
        """
        Discrete state space (a, b, c, d) of one channel at sample time ``dt`` [s].

        Raises
        ------
        ConfigError
            If the bandwidth is not below the Nyquist frequency ``0.5 / dt``.
        """
        if self.order and self.bandwidth_hz >= 0.5 / dt:
            raise ConfigError(f'filter bandwidth {self.bandwidth_hz} Hz must be below Nyquist '
                              f'{0.5 / dt:g} Hz')
        a, b, c, d = self.continuous()
        if self.order:
            a, b, c, d, _ = scipy.signal.cont2discrete((a, b, c, d), dt, method=self.hold)
        n = int(self.delay_steps)
        if n == 0:
            return a, b, c, d
        # series: filter, then a shift register of n samples (its last cell is the output)
        nf = a.shape[0]
        shift = np.eye(n, k=-1)
        a_s = np.block([[a, np.zeros((nf, n))], [np.zeros((n, nf)), shift]])
        a_s[nf, :nf] = c[0]
        b_s = np.vstack([b, np.zeros((n, 1))])
        b_s[nf, 0] = d[0, 0]
        c_s = np.zeros((1, nf + n))
        c_s[0, -1] = 1.0
        return a_s, b_s, c_s, np.zeros((1, 1))


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
