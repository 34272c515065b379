"""
The feed drives' digital position/velocity cascade, and IFF inside it (HAC-LAC).

Each strut's servo amplifier closes, at the loop's sample rate, on its motor encoder
(:class:`pentapod_sim.plant.drives.DrivenPlant`: ``strut<i>_motor_position`` [m],
``strut<i>_motor_velocity`` [m/s] along the strut):

* position loop (P): ``v_ref = K_p (x_ref - x_m)``, x_ref = 0 (holding the strut length);
* velocity loop (PI): ``F_cmd = K_v (e_v + (1 / T_n) sum e_v dt)``, ``e_v = v_ref - v_m``,
  ``K_v = m_r 2 pi f_v``;
* the drive's own delay of n samples before ``strut<i>_motor_force`` (the current loop's
  low-pass is continuous, in the plant).

The integral action holds ``x_m`` at 0 statically, so the machine with its drives has the FE
model's static compliance: the reference a damping law must not worsen.

HAC-LAC (``iff_gain`` > 0): integral force feedback on the strut's load cell
(``strut<i>_force``) adds ``w = -g / (s + omega_i) F`` to the force command: the
low-authority damping loop inside the high-authority position loop, whose integral takes the
static softening of IFF back.

Units: gains as stated, forces N, positions m, sample time s.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np
import numpy.typing as npt
import scipy.linalg as sla

from pentapod_sim.errors import ConfigError
from pentapod_sim.plant.drives import DriveParams, motor_ports
from pentapod_sim.sim.controllers import DiscreteController
from pentapod_sim.sim.law_models import (
    channel_continuous,
    channel_discrete,
    delayed,
    Dynamics,
    Matrices,
    positive,
)

_NONE: Matrices = (np.zeros((0, 0)), np.zeros((0, 1)), np.zeros((1, 0)), np.zeros((1, 1)))


def _cascade(params: DriveParams, dt: float | None, iff: Matrices) -> Matrices:
    """
    One drive's controller: inputs ``[x_m, v_m, F]``, output the force command.

    The command is taken before the delay; state ``[z_I, IFF filter]``. Discrete
    (forward-Euler integral) for a ``dt``, continuous for None.
    """
    k_v, k_p, t_n = params.velocity_gain, params.position_gain, params.velocity_reset_time
    a_f, b_f, c_f, d_f = iff
    nf = a_f.shape[0]
    a = np.zeros((1 + nf, 1 + nf))
    b = np.zeros((1 + nf, 3))
    a[0, 0] = 1.0 if dt is not None else 0.0
    b[0, :2] = np.array([-k_p, -1.0]) * (dt if dt is not None else 1.0)
    a[1:, 1:] = a_f
    b[1:, 2:] = b_f
    c = np.zeros((1, 1 + nf))
    c[0, 0] = k_v / t_n
    c[0, 1:] = c_f[0]
    d = np.array([[-k_v * k_p, -k_v, float(d_f[0, 0])]])
    return a, b, c, d


def _iff(gain: float, omega_i: float, dynamics: Dynamics, dt: float | None) -> Matrices:
    """The IFF filter; its ``delay_steps`` delay the IFF command before the drive's own."""
    if not gain:
        return _NONE
    tf = ((-float(gain),), (1.0, float(omega_i)))
    return channel_continuous(tf, dynamics) if dt is None else channel_discrete(tf, dynamics, dt)


@dataclass(frozen=True)
class FeedDrives:
    """
    The feed drives' controllers of a set of struts, optionally with IFF inside (HAC-LAC).

    Attributes
    ----------
    params : DriveParams
        Cascade gains and delay.
    struts : tuple of int
        Strut numbers 1..5 (the :class:`~pentapod_sim.plant.drives.DrivenPlant`'s).
    iff_gain : float
        g [1/s] of the IFF inside the loops (0: the drives alone).
    iff_omega : float
        omega_i [rad/s] of the IFF (>= 0).
    iff_dynamics : Dynamics
        Low-pass of the load cell's signal, and a delay of the IFF command besides the
        drive's own (0: the IFF runs in the drive's cycle).
    """

    params: DriveParams
    struts: tuple[int, ...] = (1, 2, 3, 4, 5)
    iff_gain: float = 0.0
    iff_omega: float = 0.0
    iff_dynamics: Dynamics = Dynamics()

    def __post_init__(self) -> None:
        positive('IFF gain g [1/s]', self.iff_gain, allow_zero=True)
        positive('IFF corner omega_i [rad/s]', self.iff_omega, allow_zero=True)
        if not self.struts:
            raise ConfigError('feed drives need at least one strut')
        drive_struts(self.struts)

    @property
    def sensor_ports(self) -> tuple[str, ...]:
        """Encoder positions, velocities, then (with IFF) the load cells."""
        ports = [motor_ports(i)[1] for i in self.struts] + [motor_ports(i)[2]
                                                             for i in self.struts]
        if self.iff_gain:
            ports += [f'strut{i}_force' for i in self.struts]
        return tuple(ports)

    @property
    def actuator_ports(self) -> tuple[str, ...]:
        """The motors' force commands."""
        return tuple(motor_ports(i)[0] for i in self.struts)

    def _controller(self, dt: float | None) -> DiscreteController:
        iff = _iff(self.iff_gain, self.iff_omega, self.iff_dynamics, dt)
        one = _cascade(self.params, dt, iff)
        if dt is not None:
            one = _delayed_mimo(one, int(self.params.delay_steps))
        r = len(self.struts)
        a = sla.block_diag(*[one[0]] * r)
        b_blocks = [sla.block_diag(*[one[1][:, [j]]] * r) for j in range(3)]
        d_blocks = [np.kron(np.eye(r), one[3][:, [j]]) for j in range(3)]
        keep = 3 if self.iff_gain else 2
        b = np.hstack(b_blocks[:keep])
        d = np.hstack(d_blocks[:keep])
        c = sla.block_diag(*[one[2]] * r)
        return DiscreteController(self.sensor_ports, self.actuator_ports, a, b, c, d)

    def discrete(self, dt: float) -> DiscreteController:
        """The controllers at the loop's sample time ``dt`` [s] (with the drive's delay)."""
        positive('sample time dt [s]', dt)
        return self._controller(dt)

    def continuous(self) -> DiscreteController:
        """The controllers' continuous state space (no delay)."""
        return self._controller(None)


def _delayed_mimo(system: Matrices, n: int) -> Matrices:
    """A discrete system with one output followed by a shift register of ``n`` samples."""
    a, b, c, d = system
    if n == 0:
        return a, b, c, d
    single = delayed((a, b[:, :1], c, d[:, :1]), n)
    nf = a.shape[0]
    b_s = np.zeros((nf + n, b.shape[1]))
    b_s[:nf] = b
    b_s[nf] = d[0]
    return single[0], b_s, single[2], np.zeros_like(d)


def servo_impedance(params: DriveParams, k_a: float, freq_hz: npt.ArrayLike
                    ) -> npt.NDArray[np.complex128]:
    """
    Closed form of the drive's force on the strut per unit strut motion, ``-u / delta``.

    Continuous and without delay: the link in series with the rotor held by its servo,
    ``k_a Z / (k_a + Z)``, ``Z = m_r s^2 + L(s) K_v (s + K_p)(1 + 1 / (T_n s))``,
    ``L = w_c / (s + w_c)``; the independent reference of the tests. With ``Z -> inf`` it is
    the locked link ``k_a``.
    """
    s = 2j * np.pi * np.asarray(freq_hz, dtype=float)
    w_c = 2 * np.pi * params.current_bandwidth_hz
    servo = (w_c / (s + w_c) * params.velocity_gain * (s + params.position_gain)
             * (1 + 1 / (params.velocity_reset_time * s)))
    z = params.rotor_mass * s ** 2 + servo
    return k_a * z / (k_a + z)


def drive_struts(struts: Sequence[int]) -> tuple[int, ...]:
    """Strut numbers as a tuple of int (ConfigError outside 1..5 or repeated)."""
    out = tuple(int(i) for i in struts)
    if any(not 1 <= i <= 5 for i in out) or len(set(out)) != len(out):
        raise ConfigError(f'feed-drive struts must be distinct numbers 1..5, got {list(struts)}')
    return out
