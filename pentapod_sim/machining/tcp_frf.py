"""
The TCP's frequency response in the cutting plane: the 2x2 FRF matrix that chatter depends on.

:class:`TcpFrf` holds ``H[i, j](f)``, the TCP displacement along machine axis i per unit TCP
force along axis j (i, j in x, y) [m/N], from the analytic plant (:func:`tcp_frf`, open loop or
with viscous dampers), from a modal model (:func:`tcp_plant` of a list of :class:`TcpMode`) or
measured (one column per excitation direction). The cutting plane is the machine x-y plane
(tool axis along machine z); a tilted spindle is not modelled.

Lightly damped modes are narrow (half-power bandwidth ``2 zeta f``: 0.05 Hz at 27 Hz for
zeta = 0.1 %), so the most negative real part, which sets the minimum stable depth, is missed
on an even grid; :func:`resonance_grid` adds points across every resonance.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping, Sequence

import control
import numpy as np
import numpy.typing as npt

from pentapod_sim.errors import ConfigError, PortError
from pentapod_sim.plant.frf import damper_feedback, FrfResult, modal_frf, statespace_frf
from pentapod_sim.plant.model import PlantModel

AXES = ('x', 'y')
TCP_FORCES = tuple(f'tcp_force_{a}' for a in AXES)
TCP_DISPLACEMENTS = tuple(f'tcp_displacement_{a}' for a in AXES)


@dataclass(frozen=True)
class TcpFrf:
    """
    FRF matrix of the TCP in the machine x-y plane.

    Attributes
    ----------
    freq : (n_f,) ndarray
        Increasing frequencies [Hz].
    matrix : (2, 2, n_f) complex ndarray
        ``matrix[i, j]``: displacement along axis i per force along axis j [m/N].
    label : str
        Legend text (scenario, position).
    """

    freq: np.ndarray
    matrix: np.ndarray
    label: str = ''

    def __post_init__(self) -> None:
        freq = np.asarray(self.freq, dtype=float)
        matrix = np.asarray(self.matrix, dtype=complex)
        if freq.ndim != 1 or freq.size < 2 or np.any(np.diff(freq) <= 0) or freq[0] < 0:
            raise ConfigError(f'{self.label or "FRF"}: frequencies must increase from >= 0 Hz '
                              f'({freq.size} given)')
        if matrix.shape != (2, 2, freq.size):
            raise ConfigError(f'{self.label or "FRF"}: matrix has shape {matrix.shape}, '
                              f'expected (2, 2, {freq.size})')
        if not np.all(np.isfinite(matrix)):
            raise ConfigError(f'{self.label or "FRF"}: the FRF has non-finite values')
        object.__setattr__(self, 'freq', freq)
        object.__setattr__(self, 'matrix', matrix)

    @classmethod
    def from_frf_result(cls, result: FrfResult, label: str | None = None) -> 'TcpFrf':
        """The x-y TCP block of an analytic FRF (PortError if a TCP port is missing)."""
        h = np.array([[result.pair(out, inp) for inp in TCP_FORCES] for out in TCP_DISPLACEMENTS])
        return cls(result.freq, h, result.label if label is None else label)

    @classmethod
    def single_direction(cls, freq: npt.ArrayLike, h: npt.ArrayLike,
                         direction: npt.ArrayLike, label: str = '') -> 'TcpFrf':
        """
        The matrix ``h(f) d d^T`` of a structure flexible along one direction ``d`` only.

        This is what one measured direct FRF (response and force along ``d``) gives; the
        compliance across ``d`` and the cross terms are taken as zero.
        """
        d = np.asarray(direction, dtype=float)
        if d.shape != (2,) or not np.linalg.norm(d) > 0:
            raise ConfigError(f'direction {direction!r} must be a non-zero 2-vector')
        d = d / np.linalg.norm(d)
        return cls(np.asarray(freq, dtype=float),
                   np.outer(d, d)[:, :, None] * np.asarray(h, dtype=complex)[None, None], label)

    def in_cutting_frame(self, feed_angle: float) -> npt.NDArray[np.complex128]:
        """``R^T H R`` (2, 2, n_f): the matrix in the cutting frame of a feed angle [rad]."""
        c, s = np.cos(feed_angle), np.sin(feed_angle)
        rot = np.array([[c, -s], [s, c]])
        return np.einsum('ki,klf,lj->ijf', rot, self.matrix, rot)

    def along(self, direction: npt.ArrayLike) -> npt.NDArray[np.complex128]:
        """Oriented FRF ``d^T H d`` (n_f,) along a unit direction of the x-y plane [m/N]."""
        d = np.asarray(direction, dtype=float)
        d = d / np.linalg.norm(d)
        return np.einsum('i,ijf,j->f', d, self.matrix, d)


def tcp_frf(plant: PlantModel, freq_hz: npt.ArrayLike,
            dampers: Mapping[str, float] | None = None, label: str = '') -> TcpFrf:
    """
    TCP FRF matrix of a plant, open loop or with viscous dampers.

    Parameters
    ----------
    plant : PlantModel
        Needs the TCP x/y force inputs and displacement outputs (and the dampers' ports).
    freq_hz : array_like
        Increasing frequencies [Hz] (see :func:`resonance_grid`).
    dampers : mapping of input port to gain, optional
        Velocity feedback ``u = -g * rate`` (:func:`pentapod_sim.plant.frf.damper_feedback`).
    label : str
        Legend text.
    """
    missing = [p for p in TCP_FORCES + TCP_DISPLACEMENTS
               if p not in plant.input_names + plant.output_names]
    if missing:
        raise PortError(f'the plant model lacks the TCP ports {", ".join(missing)}')
    if dampers:
        # the closed loop of every port, evaluated on the TCP block only
        loop = damper_feedback(plant, dampers)
        inputs = [plant.input_names.index(p) for p in TCP_FORCES]
        outputs = [plant.output_names.index(p) for p in TCP_DISPLACEMENTS]
        tcp_loop = control.ss(loop.A, loop.B[:, inputs], loop.C[outputs],
                              loop.D[np.ix_(outputs, inputs)])
        return TcpFrf(np.asarray(freq_hz, dtype=float), statespace_frf(tcp_loop, freq_hz),
                      label)
    tcp = plant.select(list(TCP_FORCES), list(TCP_DISPLACEMENTS))
    return TcpFrf.from_frf_result(modal_frf(tcp, freq_hz), label)


def plant_poles(plant: PlantModel) -> npt.NDArray[np.complex128]:
    """Poles ``-zeta w + j w sqrt(1 - zeta^2)`` of the plant's modes [rad/s] (upper half)."""
    zeta = np.minimum(plant.zeta, 1.0)
    return plant.omega * (-zeta + 1j * np.sqrt(1.0 - zeta ** 2))


def resonance_grid(poles: npt.ArrayLike, f_min: float, f_max: float, n_base: int = 2000,
                   points_per_bandwidth: int = 40, bandwidths: float = 10.0) -> np.ndarray:
    """
    Frequencies [Hz]: an even grid plus dense points across every resonance in the band.

    Parameters
    ----------
    poles : array_like
        Continuous poles [rad/s] (e.g. :func:`plant_poles`, or closed-loop eigenvalues);
        those with Im p > 0 whose damped frequency lies in [f_min, f_max] get dense points.
    f_min, f_max : float
        Band [Hz], ``0 <= f_min < f_max``.
    n_base : int
        Points of the even grid.
    points_per_bandwidth : int
        Points per half-power bandwidth ``2 |Re p| / (2 pi)`` around each resonance.
    bandwidths : float
        Half-width of each dense cluster, in half-power bandwidths.
    """
    if not 0 <= f_min < f_max:
        raise ConfigError(f'band [{f_min}, {f_max}] Hz must satisfy 0 <= f_min < f_max')
    parts = [np.linspace(f_min, f_max, n_base)]
    p = np.asarray(poles, dtype=complex).ravel()
    p = p[p.imag > 0]
    centre, half_bw = p.imag / (2 * np.pi), np.abs(p.real) / (2 * np.pi)
    keep = (centre >= f_min) & (centre <= f_max) & (half_bw > 0)
    n = int(2 * bandwidths * points_per_bandwidth) + 1
    offsets = np.linspace(-2 * bandwidths, 2 * bandwidths, n)          # in half-widths
    for f0, hw in zip(centre[keep], half_bw[keep]):
        parts.append(f0 + offsets * hw)
    grid = np.unique(np.concatenate(parts))
    return grid[(grid >= f_min) & (grid <= f_max)]


@dataclass(frozen=True)
class TcpMode:
    """
    One TCP mode in the x-y plane: ``G = d d^T (W^2 / k + j w c_v) / (W^2 - w^2 + 2 j zeta W w)``.

    Attributes
    ----------
    frequency : float
        Natural frequency [Hz].
    damping_ratio : float
        Modal damping ratio [-].
    stiffness : float
        Modal stiffness along ``direction`` [N/m] (static compliance of the mode 1/k).
    direction : (float, float)
        Direction of the mode in the machine x-y plane (normalised).
    velocity_term : float
        Numerator term on the modal velocity [m/(N s)]; zero for a real (proportionally
        damped) mode, non-zero for a mode given by a complex residue (:meth:`from_residue`).
    """

    frequency: float
    damping_ratio: float
    stiffness: float
    direction: tuple[float, float] = (1.0, 0.0)
    velocity_term: float = 0.0

    def __post_init__(self) -> None:
        if not (self.frequency > 0 and self.damping_ratio >= 0 and self.stiffness != 0
                and np.isfinite([self.frequency, self.damping_ratio, self.stiffness,
                                 self.velocity_term]).all()):
            raise ConfigError(f'mode {self!r}: needs frequency > 0 Hz, damping ratio >= 0 and '
                              'a finite, non-zero stiffness')
        if not np.linalg.norm(self.direction) > 0:
            raise ConfigError(f'mode direction {self.direction!r} must be non-zero')

    @classmethod
    def from_residue(cls, frequency: float, damping_ratio: float, residue: complex,
                     direction: tuple[float, float] = (1.0, 0.0)) -> 'TcpMode':
        """
        Mode whose FRF is ``r / (j w - s) + conj(r) / (j w - conj(s))`` [m/N].

        ``s = -zeta W + j W sqrt(1 - zeta^2)``; the residue ``r`` is in m/(N s).
        """
        w = 2 * np.pi * frequency
        wd = w * np.sqrt(1.0 - damping_ratio ** 2)
        numerator_disp = 2.0 * (damping_ratio * w * residue.real - wd * residue.imag)
        return cls(frequency, damping_ratio, w ** 2 / numerator_disp, direction,
                   2.0 * residue.real)


def tcp_plant(modes: Sequence[TcpMode]) -> PlantModel:
    """
    Plant model of ``modes``: TCP x/y force inputs, displacement and velocity outputs.

    The velocity of a complex-residue mode feeds its force through (D != 0).
    """
    if not modes:
        raise ConfigError('a TCP modal model needs at least one mode')
    omega = np.array([2 * np.pi * m.frequency for m in modes])
    zeta = np.array([m.damping_ratio for m in modes])
    dirs = np.array([np.asarray(m.direction, float) / np.linalg.norm(m.direction)
                     for m in modes])                                  # (m, 2) = b
    disp_q = (dirs * (omega ** 2 / np.array([m.stiffness for m in modes]))[:, None]).T
    disp_dq = (dirs * np.array([m.velocity_term for m in modes])[:, None]).T
    # velocity = d/dt (C_d q + C_v dq) with dq' = -W^2 q - 2 Z W dq + b F
    vel_q, vel_dq = -disp_dq * omega ** 2, disp_q - disp_dq * 2 * zeta * omega
    d = np.vstack([np.zeros((2, 2)), disp_dq @ dirs])
    velocities = [f'tcp_velocity_{a}' for a in AXES]
    return PlantModel(omega, zeta, dirs, np.vstack([disp_q, vel_q]),
                      np.vstack([disp_dq, vel_dq]), d, list(TCP_FORCES),
                      list(TCP_DISPLACEMENTS) + velocities, ['N', 'N'], ['m', 'm', 'm/s', 'm/s'],
                      [f'force at the TCP along global {a}' for a in AXES],
                      [f'TCP displacement along global {a}' for a in AXES]
                      + [f'TCP velocity along global {a}' for a in AXES],
                      {'source': 'TCP modal model', 'n_modes': len(modes)})
