"""
Analytic frequency responses of the modal plant, open loop and with added viscous damping.

Open loop, the FRF is a vectorised modal sum (BLAS products over frequency blocks), far
cheaper than ``control.frequency_response`` of the 2m-state system (bench/bench_statespace.py).
Added damping is velocity feedback ``u = -g * rate`` through collocated ports (strut bending,
strut axial, TCP or PMA mount against ground); the loop is closed with ``control.feedback``
and evaluated through the eigen-decomposition of the closed-loop A. Plotting functions end in
``_plot`` and write PNGs.
"""
from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path
from typing import Mapping, Sequence

import control
import numpy as np
import numpy.typing as npt
import scipy.linalg as spla

from pentapod_sim.errors import ConfigError, PortError
from pentapod_sim.plant.model import PlantModel
from pentapod_sim.plant.ports import collocated_output


@dataclass(frozen=True)
class FrfResult:
    """
    Frequency response on a grid.

    Attributes
    ----------
    freq : (n_f,) ndarray
        Frequencies [Hz].
    H : (n_out, n_in, n_f) complex ndarray
        Response of each output to each input (output unit per input unit, e.g. m/N).
    input_names, output_names : list of str
        Port names.
    input_units, output_units : list of str
        SI units.
    label : str
        Free text for legends (e.g. 'P1 open loop').
    """

    freq: npt.NDArray[np.float64]
    H: npt.NDArray[np.complex128]
    input_names: list[str]
    output_names: list[str]
    input_units: list[str]
    output_units: list[str]
    label: str = ''

    def pair(self, output: str, input_: str) -> npt.NDArray[np.complex128]:
        """The (n_f,) FRF of one output/input pair (PortError if absent)."""
        for name, have in ((output, self.output_names), (input_, self.input_names)):
            if name not in have:
                raise PortError(f'{name!r} is not in this FRF; it has {", ".join(have)}')
        return self.H[self.output_names.index(output), self.input_names.index(input_)]


def _check_freq(freq_hz: npt.ArrayLike) -> np.ndarray:
    freq = np.atleast_1d(np.asarray(freq_hz, dtype=float))
    if freq.ndim != 1 or np.any(freq < 0) or not np.all(np.isfinite(freq)):
        raise ConfigError(f'frequencies must be finite and >= 0 Hz, got {freq_hz!r}')
    return freq


def modal_frf_matrix(omega: npt.ArrayLike, zeta: npt.ArrayLike, b: npt.ArrayLike,
                     c_disp: npt.ArrayLike, c_vel: npt.ArrayLike, d: npt.ArrayLike | None,
                     freq_hz: npt.ArrayLike) -> npt.NDArray[np.complex128]:
    """
    Modal-sum FRF ``sum_i (c_d,i + j w c_v,i) b_i / (w_i^2 - w^2 + 2 j zeta_i w_i w) + D``.

    Parameters
    ----------
    omega, zeta : (m,) array_like
        Natural angular frequencies [rad/s] and damping ratios [-].
    b : (m, n_in) array_like
        Modal input matrix.
    c_disp, c_vel : (n_out, m) array_like
        Modal output matrices on modal displacements and velocities.
    d : (n_out, n_in) array_like or None
        Feed-through.
    freq_hz : (n_f,) array_like
        Frequencies [Hz].

    Returns
    -------
    (n_out, n_in, n_f) complex ndarray
    """
    w = 2 * np.pi * _check_freq(freq_hz)
    omega = np.asarray(omega, float)
    zeta = np.broadcast_to(np.asarray(zeta, float), omega.shape)
    denom = omega[:, None] ** 2 - w[None, :] ** 2 + 2j * (zeta * omega)[:, None] * w[None, :]
    modal = 1.0 / denom                                             # (m, n_f)
    b = np.asarray(b, float)
    h = _sum_over_modes(np.asarray(c_disp, float), b, modal)
    if np.any(c_vel):
        h += _sum_over_modes(np.asarray(c_vel, float), b, modal * (1j * w)[None, :])
    if d is not None:
        h = h + np.asarray(d, float)[:, :, None]
    return h


def _sum_over_modes(left: np.ndarray, right: np.ndarray, weights: np.ndarray,
                    block: int = 256) -> np.ndarray:
    """
    ``H[o, i, f] = sum_m left[o, m] right[m, i] weights[m, f]`` by BLAS products.

    Frequency blocks bound the (n_out, m, block) temporary; a plain three-operand einsum
    would loop in C without BLAS and is several times slower here.
    """
    h = np.empty((left.shape[0], right.shape[1], weights.shape[1]), dtype=complex)
    for start in range(0, weights.shape[1], block):
        part = slice(start, start + block)
        scaled = left[:, :, None] * weights[None, :, part]            # (o, m, f)
        h[:, :, part] = np.tensordot(scaled, right, axes=(1, 0)).transpose(0, 2, 1)
    return h


def modal_frf(plant: PlantModel, freq_hz: npt.ArrayLike, label: str = '') -> FrfResult:
    """FRF of all ports of a plant model on a frequency grid [Hz]."""
    freq = _check_freq(freq_hz)
    h = modal_frf_matrix(plant.omega, plant.zeta, plant.b, plant.c_disp, plant.c_vel, plant.d,
                         freq)
    return FrfResult(freq, h, list(plant.input_names), list(plant.output_names),
                     list(plant.input_units), list(plant.output_units), label)


def damper_feedback(plant: PlantModel, dampers: Mapping[str, float]) -> control.StateSpace:
    """
    Close velocity-feedback loops ``u_k = -g_k * rate_k`` on collocated ports.

    Parameters
    ----------
    plant : PlantModel
        Must contain each damper input and its collocated velocity output.
    dampers : mapping of input port name to gain
        Gain g_k >= 0 [N s/m for forces on velocities, N m s/rad for moments on rates].

    Returns
    -------
    control.StateSpace
        Continuous closed loop with the plant's input/output names; the damper inputs stay
        as external inputs (added to the damper force).
    """
    sys = plant.to_statespace()
    gain = np.zeros((len(plant.input_names), len(plant.output_names)))
    for input_name, g in dampers.items():
        if not np.isfinite(g) or g < 0:
            raise ConfigError(f'damper gain for {input_name!r} must be >= 0, got {g!r}')
        rate = collocated_output(input_name, 'velocity')
        if input_name not in plant.input_names or rate not in plant.output_names:
            raise PortError(f'damper {input_name!r} needs input {input_name!r} and output '
                            f'{rate!r} in the plant model')
        gain[plant.input_names.index(input_name), plant.output_names.index(rate)] = g
    feedback = control.ss([], [], [], gain, inputs=list(plant.output_names),
                          outputs=list(plant.input_names))
    closed = control.feedback(sys, feedback, sign=-1)
    return control.ss(closed.A, closed.B, closed.C, closed.D, inputs=list(plant.input_names),
                      outputs=list(plant.output_names), name='pentapod_damped')


def statespace_frf(sys: control.StateSpace, freq_hz: npt.ArrayLike) -> np.ndarray:
    """
    FRF (n_out, n_in, n_f) of a continuous state space through the eigen-decomposition of A.

    ``H(jw) = C V diag(1 / (jw - lambda)) V^-1 B + D``; hand-written because
    ``control.frequency_response`` solves one dense system per frequency.
    """
    w = 2 * np.pi * _check_freq(freq_hz)
    lam, vec = spla.eig(sys.A)
    if np.linalg.cond(vec) > 1e10:
        raise ConfigError('closed-loop A is (nearly) defective; eigen-decomposition FRF '
                          'unreliable, use control.frequency_response')
    left = sys.C @ vec                                   # (n_out, n)
    right = np.linalg.solve(vec, sys.B)                  # (n, n_in)
    resolvent = 1.0 / (1j * w[None, :] - lam[:, None])   # (n, n_f)
    return _sum_over_modes(left, right, resolvent) + sys.D[:, :, None]


def closed_loop_frf(plant: PlantModel, dampers: Mapping[str, float], freq_hz: npt.ArrayLike,
                    label: str = '') -> FrfResult:
    """FRF of all ports with added viscous dampers (see :func:`damper_feedback`)."""
    freq = _check_freq(freq_hz)
    h = statespace_frf(damper_feedback(plant, dampers), freq)
    return FrfResult(freq, h, list(plant.input_names), list(plant.output_names),
                     list(plant.input_units), list(plant.output_units), label)


def frf_to_csv(results: Sequence[FrfResult], pairs: Sequence[tuple[str, str]],
               path: str | Path) -> Path:
    """
    Write magnitude and phase of (output, input) pairs of one or more FRFs to CSV.

    Columns: freq_hz, then per result and pair ``<label>:<out>/<in>:mag`` and ``:phase_deg``.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    header, columns = ['freq_hz'], [results[0].freq]
    for res in results:
        for out, inp in pairs:
            h = res.pair(out, inp)
            header += [f'{res.label}:{out}/{inp}:mag', f'{res.label}:{out}/{inp}:phase_deg']
            columns += [np.abs(h), np.degrees(np.angle(h))]
    with open(path, 'w', newline='') as stream:
        writer = csv.writer(stream)
        writer.writerow(header)
        writer.writerows(np.column_stack(columns).tolist())
    return path
