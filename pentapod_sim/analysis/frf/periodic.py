"""
FRFs without leakage from periodic excitation: synchronous averaging over integer periods.

A periodic input (multisine, periodic chirp) of ``period_steps`` samples excites only the
lines ``k / (period_steps dt)``. After the settling periods have been discarded, every further
period is one record; its discrete Fourier transform with a rectangular window holds each line
in one bin exactly (no leakage). Per line (Pintelon & Schoukens, System Identification, ch. 2):

* ``H = mean_m Y_m / mean_m U_m`` over the M periods (errors-in-variables consistent);
* noise error (standard deviation of H) from the variances across periods,
  ``var H ~ |H|^2 (var Y/|Y|^2 + var U/|U|^2 - 2 Re(cov(Y, U)/(Y conj U))) / M``;
* transient error: ``|H_first - H_second|`` of the FRFs averaged over the first and the second
  half of the periods. A transient that has not died out makes the halves differ; at steady
  state the difference is noise only: its ratio to the noise std is Rayleigh distributed with
  median ``2 sqrt(ln 2) = 1.67``.
"""
from __future__ import annotations

import dataclasses
from typing import Optional

import numpy as np
import numpy.typing as npt

from pentapod_sim.analysis.frf.estimation import FrfResult


@dataclasses.dataclass
class LineFrf(FrfResult):
    """
    An FRF at excited lines only (periodic or stepped-sine excitation).

    ``freq``, ``H`` etc. as :class:`FrfResult` (``H1 = H2 = H``, ``coherence`` NaN), plus:

    Attributes
    ----------
    noise_std : (F,) ndarray
        Standard deviation of H from the scatter across periods (or the fit residual) [unit of H].
    transient : (F,) ndarray
        Transient error estimate: ``|H_first_half - H_second_half|`` [unit of H].
    """

    noise_std: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(0))
    transient: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(0))


def line_bins(lines_hz: npt.ArrayLike, period_steps: int, dt: float) -> np.ndarray:
    """
    DFT bins of the lines ``lines_hz`` [Hz] in a record of ``period_steps`` samples of ``dt`` [s].

    Raises
    ------
    ValueError
        If a line is not an integer multiple of ``1 / (period_steps dt)`` (it would leak) or
        lies outside (0, Nyquist).
    """
    lines = np.atleast_1d(np.asarray(lines_hz, dtype=float))
    exact = lines * period_steps * dt
    bins = np.rint(exact).astype(int)
    bad = np.abs(exact - bins) > 1e-6 * np.maximum(1.0, exact)
    if np.any(bad):
        raise ValueError(f'line {lines[bad][0]:g} Hz is not a multiple of the period frequency '
                         f'{1.0 / (period_steps * dt):g} Hz; it would leak')
    if np.any(bins <= 0) or np.any(2 * bins >= period_steps):
        raise ValueError(f'lines must lie in (0, {0.5 / dt:g}) Hz, got {lines.min():g} to '
                         f'{lines.max():g} Hz')
    return bins


def period_spectra(x: npt.ArrayLike, period_steps: int, skip: int = 0) -> np.ndarray:
    """
    Rectangular-window DFTs of the full periods of ``x`` after ``skip`` samples.

    Returns
    -------
    (M, period_steps // 2 + 1) complex ndarray
        One row per full period (a trailing partial period is dropped).
    """
    x = np.asarray(x, dtype=float)[skip:]
    n_periods = len(x) // period_steps
    return np.fft.rfft(x[:n_periods * period_steps].reshape(n_periods, period_steps), axis=1)


def synchronous_frf(u: npt.ArrayLike, y: npt.ArrayLike, dt: float, period_steps: int,
                    settle_periods: int = 1, lines_hz: Optional[npt.ArrayLike] = None,
                    first_step: int = 0, input_unit: str = '', output_unit: str = '',
                    label: str = '') -> LineFrf:
    """
    FRF at the excited lines of a periodic excitation by synchronous averaging.

    Parameters
    ----------
    u, y : (N,) array_like
        Input (e.g. force [N]) and output (e.g. displacement [m]), sample k at time k dt.
    dt : float
        Sample time [s].
    period_steps : int
        Samples per period of the excitation.
    settle_periods : int
        Periods discarded after ``first_step`` (transient of the structure).
    lines_hz : array_like, optional
        Excited lines [Hz] (multiples of ``1 / (period_steps dt)``). Default: every bin whose
        averaged input amplitude exceeds 1e-3 of the largest.
    first_step : int
        Sample at which the periodic excitation starts (``start_delay / dt``).
    input_unit, output_unit, label : str
        Stored in the result.

    Returns
    -------
    LineFrf
        ``n_averages`` is the number of averaged periods.

    Raises
    ------
    ValueError
        With fewer than 2 full periods after settling, on unequal lengths, or on a leaking line.
    """
    u = np.asarray(u, dtype=float)
    y = np.asarray(y, dtype=float)
    period_steps = int(period_steps)
    if u.shape != y.shape or u.ndim != 1:
        raise ValueError(f'u and y must be 1-D of equal length, got {u.shape}, {y.shape}')
    if period_steps < 4 or dt <= 0:
        raise ValueError(f'need period_steps >= 4 and dt > 0 s, got {period_steps}, {dt}')
    skip = int(first_step) + int(settle_periods) * period_steps
    n_periods = max(0, (len(u) - skip) // period_steps)
    if n_periods < 2:
        raise ValueError(f'{len(u)} samples hold {n_periods} full period(s) of {period_steps} '
                         f'after {settle_periods} settling period(s) from step {first_step}; '
                         'need at least 2 to average (record longer)')
    spec_u = period_spectra(u, period_steps, skip)
    spec_y = period_spectra(y, period_steps, skip)
    if lines_hz is None:
        mean_u = np.abs(spec_u.mean(axis=0))
        bins = np.flatnonzero(mean_u > 1e-3 * mean_u[1:].max())
        bins = bins[(bins > 0) & (2 * bins < period_steps)]
    else:
        bins = line_bins(lines_hz, period_steps, dt)
    spec_u, spec_y = spec_u[:, bins], spec_y[:, bins]
    h, noise = _average(spec_u, spec_y)
    half = n_periods // 2
    h_first, _ = _average(spec_u[:half], spec_y[:half])
    h_second, _ = _average(spec_u[half:2 * half], spec_y[half:2 * half])
    freq = bins / (period_steps * dt)
    return LineFrf(freq, h, h.copy(), h.copy(), np.full(len(bins), np.nan),
                   input_unit=input_unit, output_unit=output_unit, excitation='periodic',
                   n_averages=n_periods, label=label, noise_std=noise,
                   transient=np.abs(h_first - h_second))


def _average(spec_u: np.ndarray, spec_y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """FRF of the averaged spectra and its noise standard deviation (M, L) -> (L,), (L,)."""
    m = spec_u.shape[0]
    mu, my = spec_u.mean(axis=0), spec_y.mean(axis=0)
    if np.any(mu == 0):
        raise ValueError(f'{int(np.sum(mu == 0))} line(s) carry no input; check lines_hz')
    h = my / mu
    if m < 2:
        return h, np.full(len(h), np.nan)
    du, dy = spec_u - mu, spec_y - my
    var_u = np.sum(np.abs(du) ** 2, axis=0) / (m - 1)
    var_y = np.sum(np.abs(dy) ** 2, axis=0) / (m - 1)
    cov_yu = np.sum(dy * np.conj(du), axis=0) / (m - 1)
    with np.errstate(divide='ignore', invalid='ignore'):
        rel = var_y / np.abs(my) ** 2 + var_u / np.abs(mu) ** 2 \
            - 2 * np.real(cov_yu / (my * np.conj(mu)))
    var_h = np.abs(h) ** 2 * np.maximum(rel, 0.0) / m
    # a zero output line (antiresonance) makes the relative form undefined: use var_y/|U|^2
    var_h = np.where(np.isfinite(var_h), var_h, var_y / np.abs(mu) ** 2 / m)
    return h, np.sqrt(var_h)
