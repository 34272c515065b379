"""
FRF from stepped-sine excitation: a least-squares sine fit per line.

Each line f is held over a window of samples (the excitation settles, then runs an integer
number of periods). In the measuring window, input and output are fitted by
``a cos(2 pi f t) + b sin(2 pi f t) + c`` (ordinary least squares, the offset c takes up a
static deflection); the complex amplitude is ``a - j b`` and ``H(f) = Y / U``.

Per line also: the noise error, from the fit residual (the standard deviation of the
amplitudes of a least-squares fit with white residual is ``sigma sqrt(2 / n)``), and the
transient error ``|H_first_half - H_second_half|`` of separate fits to the two halves of the
window.
"""
from __future__ import annotations

from typing import Sequence

import numpy as np
import numpy.typing as npt

from pentapod_sim.analysis.frf.periodic import LineFrf


def fit_sine(x: np.ndarray, freq_hz: float, dt: float, first_step: int
             ) -> tuple[complex, float]:
    """
    Complex amplitude of ``x`` at ``freq_hz`` and the residual standard deviation.

    Parameters
    ----------
    x : (n,) ndarray
        Samples ``first_step .. first_step + n - 1`` (time ``k dt``).
    freq_hz : float
        The known frequency [Hz].
    dt : float
        Sample time [s].
    first_step : int
        Step index of ``x[0]`` (sets the phase reference, common to input and output).

    Returns
    -------
    amplitude : complex
        ``a - j b`` for ``x ~ a cos + b sin + c`` (so ``x ~ Re(amplitude e^{j w t}) + c``).
    residual_std : float
        Standard deviation of the residual [unit of x].
    """
    t = (first_step + np.arange(len(x))) * dt
    phase = 2 * np.pi * freq_hz * t
    basis = np.column_stack([np.cos(phase), np.sin(phase), np.ones(len(x))])
    coef, *_ = np.linalg.lstsq(basis, x, rcond=None)
    resid = x - basis @ coef
    return coef[0] - 1j * coef[1], float(np.sqrt(np.sum(resid ** 2) / max(len(x) - 3, 1)))


def stepped_sine_frf(u: npt.ArrayLike, y: npt.ArrayLike, dt: float,
                     windows: Sequence[tuple[float, int, int]], input_unit: str = '',
                     output_unit: str = '',
                     label: str = '') -> LineFrf:
    """
    FRF at the lines of a stepped sine, one least-squares fit per measuring window.

    Parameters
    ----------
    u, y : (N,) array_like
        Input [N] and output, sample k at time k dt.
    dt : float
        Sample time [s].
    windows : sequence of (f_Hz, first_step, end_step)
        Measuring window per line (after its settling), e.g. from
        ``Excitation.stepped_windows()``; samples ``first_step .. end_step - 1``.
    input_unit, output_unit, label : str
        Stored in the result.

    Returns
    -------
    LineFrf
        Lines sorted by frequency; ``n_averages`` is the smallest window length in periods.

    Raises
    ------
    ValueError
        If a window lies outside the record, holds fewer than 8 samples or no input.
    """
    u = np.asarray(u, dtype=float)
    y = np.asarray(y, dtype=float)
    if u.shape != y.shape or u.ndim != 1:
        raise ValueError(f'u and y must be 1-D of equal length, got {u.shape}, {y.shape}')
    if not windows:
        raise ValueError('no stepped-sine windows given')
    rows = []
    min_periods = np.inf
    for freq, first, end in sorted(windows):
        first, end = int(first), int(end)
        if not 0 <= first < end <= len(u) or end - first < 8:
            raise ValueError(f'window of {freq:g} Hz, steps {first}..{end}, does not lie in '
                             f'the record of {len(u)} samples (or is shorter than 8)')
        rows.append(_line(u, y, float(freq), dt, first, end))
        min_periods = min(min_periods, (end - first) * dt * freq)
    lines, h, noise, transient = (np.array(col) for col in zip(*rows))
    return LineFrf(lines, h, h.copy(), h.copy(), np.full(len(lines), np.nan),
                   input_unit=input_unit, output_unit=output_unit, excitation='stepped_sine',
                   n_averages=int(min_periods), label=label, noise_std=noise,
                   transient=transient)


def _line(u: np.ndarray, y: np.ndarray, freq: float, dt: float, first: int, end: int
          ) -> tuple[float, complex, float, float]:
    amp_u, std_u = fit_sine(u[first:end], freq, dt, first)
    amp_y, std_y = fit_sine(y[first:end], freq, dt, first)
    if abs(amp_u) == 0:
        raise ValueError(f'no input at {freq:g} Hz in steps {first}..{end}')
    h = amp_y / amp_u
    n = end - first
    noise = np.sqrt(2.0 / n) * np.hypot(std_y, abs(h) * std_u) / abs(amp_u)
    mid = (first + end) // 2
    h_a = fit_sine(y[first:mid], freq, dt, first)[0] / fit_sine(u[first:mid], freq, dt, first)[0]
    h_b = fit_sine(y[mid:end], freq, dt, mid)[0] / fit_sine(u[mid:end], freq, dt, mid)[0]
    return freq, h, noise, abs(h_a - h_b)
