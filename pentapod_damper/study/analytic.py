"""
Analytic FRFs of a scenario: the continuous closed loop and the sampled lockstep loop.

The continuous FRF (:func:`pentapod_sim.plant.frf.closed_loop_frf`) is the paper's view: ideal
viscous dampers. The discrete FRF is what the testbed runs: plain sampled feedback, the
zero-order-hold plant with every law answering ``u_k`` to the outputs ``y_k`` of the same step
(docs/architecture.md), through the laws' own actuator/sensor dynamics and delays
(``delay_steps`` = 1: one-sample computational delay), evaluated at ``z = exp(j w dt)``; a
recorded lockstep run must match it up to estimation error.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np
import numpy.typing as npt

from pentapod_sim.plant.drives import DrivenPlant
from pentapod_sim.plant.frf import closed_loop_frf, modal_frf
from pentapod_sim.plant.model import PlantModel
from pentapod_sim.sim.closed_loop import closed_loop_system
from pentapod_sim.sim.stepping import DiscretePlant

#: Largest eigenvector condition number for the eigen-decomposition path.
MAX_COND = 1e8


def continuous_frf(plant: PlantModel, dampers: dict[str, float], freq_hz: npt.ArrayLike,
                   output: str, input_: str) -> npt.NDArray[np.complex128]:
    """
    FRF ``output / input_`` of the continuous plant with ideal viscous ``dampers``.

    Parameters
    ----------
    plant : PlantModel
        Modal plant (SI units).
    dampers : dict
        Input port -> viscous gain [N s/m or N m s/rad]; empty for the open loop.
    freq_hz : (F,) array_like
        Frequencies [Hz].
    output, input_ : str
        Port names.
    """
    result = (closed_loop_frf(plant, dampers, freq_hz) if dampers
              else modal_frf(plant, freq_hz))
    return result.pair(output, input_)


@dataclass
class SampledLoop:
    """
    The lockstep sampled loop of a plant and linear laws, and its eigen-decomposition.

    ``a, b, c_y, c_u, augmented`` as :func:`pentapod_sim.sim.closed_loop.closed_loop_system`
    returns them for the zero-order-hold plant ``core``; ``a = vec diag(lam) vec^-1``. Built
    once per loop (:func:`sampled_loop`) and shared by :func:`discrete_frf` and
    :class:`SampledPairFrf`.
    """

    core: DiscretePlant
    a: np.ndarray
    b: np.ndarray
    c_y: np.ndarray
    c_u: np.ndarray
    augmented: bool
    lam: np.ndarray
    vec: np.ndarray


def sampled_loop(plant: PlantModel | DrivenPlant, laws: Sequence[Any], dt: float) -> SampledLoop:
    """The sampled loop of ``plant`` (discretised with zero-order hold at ``dt`` [s]) and laws."""
    core = DiscretePlant(plant.discretize(dt))
    a, b, c_y, c_u, augmented = closed_loop_system(core, laws)
    lam, vec = np.linalg.eig(a)
    return SampledLoop(core, a, b, c_y, c_u, augmented, lam, vec)


@dataclass
class DiscreteFrf:
    """
    FRFs of the sampled closed loop from one external input.

    Attributes
    ----------
    freq : (F,) ndarray
        Frequencies [Hz].
    outputs : dict of str to (F,) complex ndarray
        Plant output port -> FRF [output unit / input unit].
    efforts : dict of str to (F,) complex ndarray
        Plant input port -> total effort u (external plus controller) per unit input.
    spectral_radius : float
        Largest |eigenvalue| of the closed loop (>= 1: not asymptotically stable).
    """

    freq: np.ndarray
    outputs: dict[str, npt.NDArray[np.complex128]]
    efforts: dict[str, npt.NDArray[np.complex128]]
    spectral_radius: float


def _resolvent_columns(a: np.ndarray, b: np.ndarray, z: np.ndarray,
                       lam: np.ndarray, vec: np.ndarray) -> np.ndarray:
    """(n, F) columns ``(z_f I - a)^-1 b`` for one input column ``b``; a = V diag(lam) V^-1."""
    if np.isfinite(np.linalg.cond(vec)) and np.linalg.cond(vec) < MAX_COND:
        right = np.linalg.solve(vec, b.astype(complex))
        return vec @ (right[:, None] / (z[None, :] - lam[:, None]))
    # defective or ill-conditioned closed loop: one dense solve per frequency
    eye = np.eye(a.shape[0])
    return np.stack([np.linalg.solve(zf * eye - a, b) for zf in z], axis=1)


def discrete_frf(plant: PlantModel | DrivenPlant, laws: Sequence[Any], dt: float,
                 freq_hz: npt.ArrayLike, input_: str,
                 loop: SampledLoop | None = None) -> DiscreteFrf:
    """
    FRFs of the lockstep sampled loop (u_k answers y_k, zero-order hold) from an external input.

    Parameters
    ----------
    plant : PlantModel
        Continuous modal plant; discretised here with zero-order hold at ``dt``.
    laws : sequence
        Linear laws: memoryless (``linear_gain()``, e.g. viscous dampers or an unfiltered PMA)
        or with a discrete model (``discrete_model()``: dampers with a low-pass or a delay);
        empty for the open loop.
    dt : float
        Sample time [s].
    freq_hz : (F,) array_like
        Frequencies [Hz], below the Nyquist frequency.
    input_ : str
        External input port (e.g. ``tcp_force_x``), added to the controllers' efforts.
    loop : SampledLoop, optional
        :func:`sampled_loop` of the same plant, laws and ``dt``, if already built.
    """
    freq = np.asarray(freq_hz, dtype=float)
    loop = sampled_loop(plant, laws, dt) if loop is None else loop
    core, b, c_y, c_u, lam = loop.core, loop.b, loop.c_y, loop.c_u, loop.lam
    j = core.input_names.index(input_)
    z = np.exp(2j * np.pi * freq * dt)
    x = _resolvent_columns(loop.a, b[:, j], z, lam, loop.vec)
    unit = np.zeros(len(core.input_names))
    unit[j] = 1.0
    u = c_u @ x + unit[:, None]
    y = c_y @ x
    if not loop.augmented and core.has_feedthrough:
        y = y + (core.d @ u) / z[None, :]
    return DiscreteFrf(freq, dict(zip(core.output_names, y)), dict(zip(core.input_names, u)),
                       float(np.max(np.abs(lam))))


class SampledPairFrf:
    """
    One FRF ``output / input_`` of the sampled closed loop in pole-residue form, exact at any f.

    ``H(z) = sum_i r_i / (z - l_i) + z^-1 (sum_i q_i / (z - l_i) + d_ij)`` at
    ``z = exp(j w dt)`` (the second sum: the plant's feed-through acting on ``u_{k-1}``). The
    laws may carry dynamics (:func:`pentapod_sim.sim.closed_loop.closed_loop_system`).
    ``poles`` are the continuous equivalents ``ln(l_i) / dt`` [rad/s], for
    :func:`pentapod_sim.plant.frf_peaks.maximise_near_poles`. ``loop``: the
    :func:`sampled_loop` of the same plant, laws and ``dt``, if already built.
    """

    def __init__(self, plant: PlantModel | DrivenPlant, laws: Sequence[Any], dt: float,
                 output: str, input_: str, loop: SampledLoop | None = None) -> None:
        loop = sampled_loop(plant, laws, dt) if loop is None else loop
        core, b, c_y, c_u, augmented = loop.core, loop.b, loop.c_y, loop.c_u, loop.augmented
        j, o = core.input_names.index(input_), core.output_names.index(output)
        lam, vec = loop.lam, loop.vec
        right = np.linalg.solve(vec, b[:, j].astype(complex))
        self.dt, self.lam = dt, lam
        self.r = (c_y[o] @ vec) * right
        late = (not augmented) and core.has_feedthrough
        self.q = (core.d[o] @ c_u @ vec) * right if late else np.zeros_like(self.r)
        self.d_late = float(core.d[o, j]) if late else 0.0
        with np.errstate(divide='ignore', invalid='ignore'):   # a delay cell's pole z = 0
            self.poles = np.log(lam.astype(complex)) / dt
        self.spectral_radius = float(np.abs(lam).max())

    def __call__(self, freq_hz: npt.ArrayLike) -> np.ndarray:
        """Complex FRF at the frequencies [Hz] (below Nyquist)."""
        z = np.exp(2j * np.pi * np.asarray(freq_hz, dtype=float) * self.dt).reshape(-1)
        inv = 1.0 / (z[:, None] - self.lam[None, :])
        h = inv @ self.r + (inv @ self.q + self.d_late) / z
        return h.reshape(np.shape(freq_hz))


def pma_requirements(mount_velocity: npt.ArrayLike, freq_hz: npt.ArrayLike, mass: float,
                     gain: float, force_amplitude: float,
                     filter_response: npt.ArrayLike | None = None
                     ) -> tuple[np.ndarray, np.ndarray]:
    """
    Stroke and force amplitudes of a PMA for a harmonic TCP force.

    The proof mass is accelerated by ``g H v`` (v: mount velocity, H: the law's filter, 1 for
    the ideal law), so its force on the structure is ``m_a g H v`` and its stroke relative to
    the mount is ``|v| |1 - g H / (j w)| / w`` (``|v| sqrt(1 + (g / w)^2) / w`` for H = 1).

    Parameters
    ----------
    mount_velocity : (F,) array_like
        Closed-loop FRF mount velocity / TCP force [m/(s N)].
    freq_hz : (F,) array_like
        Frequencies [Hz], > 0.
    mass, gain : float
        Proof mass m_a [kg] and gain g [1/s].
    force_amplitude : float
        Amplitude of the harmonic TCP force [N].
    filter_response : (F,) array_like, optional
        H(j w) of the law's velocity filter; default 1 (ideal law).

    Returns
    -------
    stroke, force : (F,) ndarray
        Amplitudes [m] and [N].
    """
    w = 2 * np.pi * np.asarray(freq_hz, dtype=float)
    v = np.abs(np.asarray(mount_velocity)) * force_amplitude
    if filter_response is None:
        return v * np.sqrt(1.0 + (gain / w) ** 2) / w, mass * gain * v
    h = np.asarray(filter_response)
    return v * np.abs(1.0 - gain * h / (1j * w)) / w, mass * gain * np.abs(h) * v


def peak_and_rms(h: npt.ArrayLike, freq_hz: npt.ArrayLike, f_lo: float,
                 f_hi: float) -> tuple[float, float]:
    """Largest |H| and RMS of |H| over [f_lo, f_hi] Hz (uniform grid assumed)."""
    freq = np.asarray(freq_hz)
    band = (freq >= f_lo) & (freq <= f_hi)
    mag = np.abs(np.asarray(h))[band]
    return float(mag.max()), float(np.sqrt(np.mean(mag ** 2)))


def improvement_share(base: float, partial: float, full: float) -> float:
    """Share of the full improvement ``base - full`` that ``partial`` achieves (NaN if none)."""
    gained = base - full
    return float((base - partial) / gained) if gained > 0 else float('nan')
