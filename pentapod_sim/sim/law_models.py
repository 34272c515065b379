"""
Linear models of decentralised damping laws: one transfer function per channel, sampled.

A channel reads one plant output and drives one plant input through a continuous transfer
function ``K(s)`` in series with the law's actuator/sensor dynamics (:class:`Dynamics`: a
low-pass and a delay of n samples). :func:`channel_discrete` discretises the series exactly
(:func:`scipy.signal.cont2discrete`, discrete poles ``exp(s_i dt)``) for a sensor signal that
varies linearly between samples ('foh') or is held ('zoh'), then shifts it by the delay; the
law is the same channel on every port pair (:func:`per_channel`). The laws (sensor y,
actuator effort u, s in rad/s):

* integral force feedback (IFF) on a force sensor in series with the actuator,
  ``u = -g / (s + omega_i) F`` (:func:`iff`);
* relative velocity feedback through a band-pass, ``u = -b HP(s) LP(s) v`` (:func:`band_pass`);
* lag displacement feedback, ``u = +K omega_c / (s + omega_c) y`` (:func:`lag_displacement`),
  the IFF-type law on a displacement: a spring ``-K`` that gives way (a Maxwell element) above
  ``omega_c``;
* positive position feedback on one mode,
  ``u = +g omega_f^2 / (s^2 + 2 zeta_f omega_f s + omega_f^2) y`` (:func:`ppf`).

Every function returns a :class:`LinearLaw`: its ``discrete(dt)`` is the
:class:`~pentapod_sim.sim.controllers.DiscreteController` of the sampled loop, its
``continuous()`` the same container with continuous matrices (no delay) for
:func:`pentapod_sim.sim.loop_poles.continuous_loop_poles`. ``pentapod_damper.laws`` steps them.

Units: gains in N (or N m) per unit of the sensor signal and per second as stated; corner
frequencies in Hz at the interfaces, rad/s inside.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Sequence

import numpy as np
import numpy.typing as npt
import scipy.signal

from pentapod_sim.errors import ConfigError
from pentapod_sim.sim.controllers import DiscreteController

#: Filter orders of :class:`Dynamics`: 0 = none, 1 = first-order, 2 = second-order low-pass.
FILTER_ORDERS = (0, 1, 2)
#: Input assumptions of the exact discretisation: first-order hold (the sensor signal varies
#: linearly between samples) or zero-order hold (held over each step).
HOLDS = ('foh', 'zoh')
Matrices = tuple[npt.NDArray[np.float64], ...]


def positive(name: str, value: float, allow_zero: bool = False) -> float:
    """Return ``value`` as float or raise ConfigError naming the parameter."""
    value = float(value)
    if not np.isfinite(value) or value < 0 or (value == 0 and not allow_zero):
        raise ConfigError(f'{name} must be {">= 0" if allow_zero else "> 0"} and finite, '
                          f'got {value!r}')
    return value


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
            positive('filter bandwidth [Hz]', self.bandwidth_hz)
            positive('filter damping ratio [-]', self.damping)
        if self.hold not in HOLDS:
            raise ConfigError(f'filter hold must be one of {HOLDS}, got {self.hold!r}')
        if int(self.delay_steps) != self.delay_steps or self.delay_steps < 0:
            raise ConfigError(f'delay_steps must be an integer >= 0, got {self.delay_steps!r}')

    @property
    def is_static(self) -> bool:
        """True without filter and delay (the law stays memoryless)."""
        return self.order == 0 and self.delay_steps == 0

    def with_delay(self, delay_steps: int) -> 'Dynamics':
        """The same dynamics with another delay [samples]."""
        return Dynamics(self.order, self.bandwidth_hz, self.damping, delay_steps, self.hold)

    def continuous(self) -> Matrices:
        """Continuous state space (a, b, c, d) of the low-pass of one channel (no delay)."""
        w = 2 * np.pi * self.bandwidth_hz
        cont: tuple[Any, ...]
        if self.order == 1:
            cont = ([[-w]], [[w]], [[1.0]], [[0.0]])
        elif self.order == 2:
            cont = ([[0.0, 1.0], [-w * w, -2 * self.damping * w]], [[0.0], [w * w]],
                    [[1.0, 0.0]], [[0.0]])
        else:
            cont = (np.zeros((0, 0)), np.zeros((0, 1)), np.zeros((1, 0)), [[1.0]])
        return tuple(np.array(m, dtype=float) for m in cont)

    def siso(self, dt: float) -> Matrices:
        """
        Discrete state space (a, b, c, d) of one channel at sample time ``dt`` [s].

        Raises
        ------
        ConfigError
            If the bandwidth is not below the Nyquist frequency ``0.5 / dt``.
        """
        return channel_discrete(([1.0], [1.0]), self, dt)


def series(first: Matrices, second: Matrices) -> Matrices:
    """State space of ``second`` driven by the output of ``first`` (both SISO or matching)."""
    a1, b1, c1, d1 = first
    a2, b2, c2, d2 = second
    n1, n2 = a1.shape[0], a2.shape[0]
    a = np.block([[a1, np.zeros((n1, n2))], [b2 @ c1, a2]])
    b = np.vstack([b1, b2 @ d1])
    c = np.hstack([d2 @ c1, c2])
    return a, b, c, d2 @ d1


def tf_matrices(num: Sequence[float], den: Sequence[float]) -> Matrices:
    """Continuous state space of a proper SISO transfer function ``num(s) / den(s)``."""
    if len(num) > len(den):
        raise ConfigError(f'transfer function {list(num)} / {list(den)} is not proper')
    if len(den) == 1:
        return (np.zeros((0, 0)), np.zeros((0, 1)), np.zeros((1, 0)),
                np.array([[float(num[0]) / float(den[0])]]))
    a, b, c, d = scipy.signal.tf2ss(np.asarray(num, float), np.asarray(den, float))
    return (np.atleast_2d(a).astype(float), np.atleast_2d(b).astype(float).reshape(-1, 1),
            np.atleast_2d(c).astype(float), np.atleast_2d(d).astype(float))


def channel_continuous(tf: tuple[Sequence[float], Sequence[float]],
                       dynamics: Dynamics) -> Matrices:
    """Continuous (a, b, c, d) of the law ``tf`` in series with the dynamics' low-pass."""
    return series(tf_matrices(*tf), dynamics.continuous())


def channel_discrete(tf: tuple[Sequence[float], Sequence[float]], dynamics: Dynamics,
                     dt: float) -> Matrices:
    """
    Discrete (a, b, c, d) of one channel.

    ``tf`` and the low-pass, exact with the dynamics'
    hold, then the delay of ``dynamics.delay_steps`` samples (a shift register).

    Raises
    ------
    ConfigError
        If the low-pass corner is not below the Nyquist frequency ``0.5 / dt``.
    """
    positive('sample time dt [s]', dt)
    if dynamics.order and dynamics.bandwidth_hz >= 0.5 / dt:
        raise ConfigError(f'filter bandwidth {dynamics.bandwidth_hz} Hz must be below Nyquist '
                          f'{0.5 / dt:g} Hz')
    a, b, c, d = channel_continuous(tf, dynamics)
    if a.shape[0]:
        a, b, c, d, _ = scipy.signal.cont2discrete((a, b, c, d), dt, method=dynamics.hold)
    return delayed((a, b, c, d), int(dynamics.delay_steps))


def delayed(system: Matrices, n: int) -> Matrices:
    """A discrete SISO system followed by a shift register of ``n`` samples."""
    a, b, c, d = system
    if n == 0:
        return a, b, c, d
    nf = a.shape[0]
    shift = np.eye(n, k=-1)
    a_s = np.block([[a, np.zeros((nf, n))], [np.zeros((n, nf)), shift]])
    a_s[nf, :nf] = c[0]
    b_s = np.vstack([b, np.zeros((n, 1))])
    b_s[nf, 0] = d[0, 0]
    c_s = np.zeros((1, nf + n))
    c_s[0, -1] = 1.0
    return a_s, b_s, c_s, np.zeros((1, 1))


def per_channel(sensor_ports: Sequence[str], actuator_ports: Sequence[str], siso: Matrices,
                gains: npt.ArrayLike = 1.0) -> DiscreteController:
    """The same SISO system on every (sensor, actuator) pair, scaled by ``gains`` per channel."""
    if len(sensor_ports) != len(actuator_ports):
        raise ConfigError(f'{len(sensor_ports)} sensors for {len(actuator_ports)} actuators')
    a, b, c, d = siso
    n = len(actuator_ports)
    eye = np.eye(n)
    g = np.diag(np.broadcast_to(np.asarray(gains, float), (n,)))
    return DiscreteController(sensor_ports, actuator_ports, np.asarray(np.kron(eye, a), float),
                              np.asarray(np.kron(eye, b), float), g @ np.kron(eye, c),
                              g * d[0, 0])


@dataclass(frozen=True)
class LinearLaw:
    """
    A decentralised linear law: ``u_j = gain_j K(s) y_j`` through ``dynamics`` on each pair.

    Attributes
    ----------
    name : str
        What the law is (for tables and messages).
    sensor_ports, actuator_ports : tuple of str
        Plant output and input ports, pair by pair.
    tf : (num, den)
        ``K(s)`` as polynomial coefficients in s (highest power first).
    gains : tuple of float
        Gain per channel (sign included in ``tf``).
    dynamics : Dynamics
        Actuator/sensor low-pass and delay.
    parameters : dict
        The law's parameters as given (SI units), for reports.
    """

    name: str
    sensor_ports: tuple[str, ...]
    actuator_ports: tuple[str, ...]
    tf: tuple[tuple[float, ...], tuple[float, ...]]
    gains: tuple[float, ...]
    dynamics: Dynamics = Dynamics()
    parameters: dict[str, float] = field(default_factory=dict)

    def discrete(self, dt: float) -> DiscreteController:
        """The law's discrete state space at sample time ``dt`` [s] (with its delay)."""
        return per_channel(self.sensor_ports, self.actuator_ports,
                           channel_discrete(self.tf, self.dynamics, dt), self.gains)

    def continuous(self) -> DiscreteController:
        """The law's continuous state space (transfer function and low-pass, no delay)."""
        return per_channel(self.sensor_ports, self.actuator_ports,
                           channel_continuous(self.tf, self.dynamics), self.gains)

    def with_dynamics(self, dynamics: Dynamics) -> 'LinearLaw':
        """The same law with other actuator/sensor dynamics."""
        return LinearLaw(self.name, self.sensor_ports, self.actuator_ports, self.tf,
                         self.gains, dynamics, dict(self.parameters))


def _gains(value: float | Sequence[float], n: int, name: str) -> tuple[float, ...]:
    gains = np.broadcast_to(np.asarray(value, dtype=float), (n,))
    for g in gains:
        positive(name, g, allow_zero=True)
    return tuple(float(g) for g in gains)


def iff(force_ports: Sequence[str], actuator_ports: Sequence[str],
        gain: float | Sequence[float],
        omega_i: float = 0.0, dynamics: Dynamics = Dynamics()) -> LinearLaw:
    """
    Integral force feedback ``u = -g / (s + omega_i) F``.

    ``gain`` g [1/s] per channel, ``omega_i`` [rad/s] >= 0 (0: pure integrator; > 0: a
    high-pass against sensor offset that also keeps a static force ``-(g / omega_i) F``).
    """
    positive('IFF corner omega_i [rad/s]', omega_i, allow_zero=True)
    return LinearLaw('IFF', tuple(force_ports), tuple(actuator_ports),
                     ((-1.0,), (1.0, float(omega_i))),
                     _gains(gain, len(actuator_ports), 'IFF gain g [1/s]'), dynamics,
                     {'gain_per_s': float(np.max(gain)), 'omega_i_rad_s': float(omega_i)})


def band_pass(velocity_ports: Sequence[str], actuator_ports: Sequence[str],
              gain: float | Sequence[float], highpass_hz: float, lowpass_hz: float,
              dynamics: Dynamics = Dynamics()) -> LinearLaw:
    """
    Relative velocity feedback through a first-order band-pass.

    ``u = -b s / (s + w_h) * w_l / (s + w_l) v`` (w = 2 pi f), ``gain`` b [N s/m, N m s/rad].
    """
    w_h = 2 * np.pi * positive('band-pass high-pass corner [Hz]', highpass_hz)
    w_l = 2 * np.pi * positive('band-pass low-pass corner [Hz]', lowpass_hz)
    if w_h >= w_l:
        raise ConfigError(f'band-pass: high-pass corner {highpass_hz} Hz must be below the '
                          f'low-pass corner {lowpass_hz} Hz')
    return LinearLaw('band-pass velocity', tuple(velocity_ports), tuple(actuator_ports),
                     ((-w_l, 0.0), tuple(np.polymul([1.0, w_h], [1.0, w_l]))),
                     _gains(gain, len(actuator_ports), 'damping gain b'), dynamics,
                     {'gain': float(np.max(gain)), 'highpass_hz': float(highpass_hz),
                      'lowpass_hz': float(lowpass_hz)})


def lag_displacement(displacement_ports: Sequence[str], actuator_ports: Sequence[str],
                     stiffness: float | Sequence[float], corner_hz: float,
                     dynamics: Dynamics = Dynamics()) -> LinearLaw:
    """
    Lag displacement feedback ``u = +K w_c / (s + w_c) y`` (w_c = 2 pi ``corner_hz``).

    ``stiffness`` K [N/m or N m/rad] per channel: a negative static stiffness ``-K`` on the
    port that relaxes above ``w_c``, so the law adds the damping of a Maxwell element and
    takes ``K`` off the port's static stiffness (keep K well below it: near it the port
    buckles).
    """
    w_c = 2 * np.pi * positive('lag corner [Hz]', corner_hz)
    return LinearLaw('lag displacement', tuple(displacement_ports), tuple(actuator_ports),
                     ((w_c,), (1.0, w_c)),
                     _gains(stiffness, len(actuator_ports), 'lag stiffness K'), dynamics,
                     {'stiffness': float(np.max(stiffness)), 'corner_hz': float(corner_hz)})


def ppf(displacement_ports: Sequence[str], actuator_ports: Sequence[str],
        gain: float | Sequence[float], frequency_hz: float, damping: float,
        dynamics: Dynamics = Dynamics()) -> LinearLaw:
    """
    Positive position feedback ``u = +g w_f^2 / (s^2 + 2 zeta_f w_f s + w_f^2) y`` on one mode.

    ``gain`` g [N/m or N m/rad] per channel (the static loop gain g G(0) of a collocated port
    must stay below 1), ``frequency_hz`` the filter's (near the mode), ``damping`` zeta_f > 0.
    """
    w_f = 2 * np.pi * positive('PPF frequency [Hz]', frequency_hz)
    zeta_f = positive('PPF damping ratio [-]', damping)
    return LinearLaw('PPF', tuple(displacement_ports), tuple(actuator_ports),
                     ((w_f * w_f,), (1.0, 2 * zeta_f * w_f, w_f * w_f)),
                     _gains(gain, len(actuator_ports), 'PPF gain g'), dynamics,
                     {'gain': float(np.max(gain)), 'frequency_hz': float(frequency_hz),
                      'damping': float(damping)})


def delay_output(controller: DiscreteController, n: int) -> DiscreteController:
    """``controller`` with its efforts delayed by ``n`` more samples (a shift register each)."""
    if n == 0:
        return controller
    a, b, c, d = controller.a, controller.b, controller.c, controller.d
    n_c, n_a, n_s = a.shape[0], c.shape[0], b.shape[1]
    size = n_c + n * n_a
    a_out, b_out = np.zeros((size, size)), np.zeros((size, n_s))
    a_out[:n_c, :n_c], b_out[:n_c] = a, b
    a_out[n_c:n_c + n_a, :n_c], b_out[n_c:n_c + n_a] = c, d     # first cell: this step's u
    for k in range(1, n):
        rows = slice(n_c + k * n_a, n_c + (k + 1) * n_a)
        a_out[rows, n_c + (k - 1) * n_a:n_c + k * n_a] = np.eye(n_a)
    c_out = np.zeros((n_a, size))
    c_out[:, n_c + (n - 1) * n_a:] = np.eye(n_a)
    return DiscreteController(controller.sensor_ports, controller.actuator_ports, a_out, b_out,
                              c_out, np.zeros_like(d))
