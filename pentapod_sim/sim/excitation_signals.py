"""
Signals for lightly damped structures: multisine, periodic chirp, stepped sine, shaped pulses.

Each function builds samples for :class:`pentapod_sim.sim.excitation.Excitation` with numpy and
scipy (``scipy.signal.chirp``); the signals are defined here:

* multisine, one period of P samples: x[n] = sum_l cos(2 pi b_l n / P + phi_l) over the DFT
  bins b_l of its lines (line frequency b_l / (P dt)), scaled to a peak of 1. Schroeder's
  phases phi_l = -pi l (l - 1) / L (l = 1..L, equal amplitudes; Schroeder 1970, IEEE Trans.
  Inf. Theory 16(1)) keep the crest factor low, near that of a sweep;
* periodic chirp, one period: sin(2 pi (f0 tau + (f1 - f0) tau^2 / (2 T))), tau = n dt,
  T = P dt, repeated by indexing with n mod P: periodic in samples exactly. The sweep's end
  value joins its start smoothly when (f0 + f1) T / 2 is a whole number;
* stepped sine: per line a sine of frequency f' = q / (N dt), N = round(q / (f dt)) samples,
  so that the measurement window of N samples holds exactly q = ``periods_per_line`` periods
  (f' differs from the requested f by at most f / (2 N)); before each window the line runs
  for ``settle_time``; the phase is continuous from line to line;
* pulse of n samples, taken at the sample midpoints s = (j + 1/2) / n: rect 1, half_sine
  sin(pi s), hann sin^2(pi s) (times the peak).
"""
from __future__ import annotations

from dataclasses import dataclass
import math
from typing import Sequence

import numpy as np
import numpy.typing as npt
import scipy.signal

from pentapod_sim.errors import ConfigError


def schroeder_phases(n_lines: int) -> npt.NDArray[np.float64]:
    """Schroeder's phases -pi l (l - 1) / L [rad] of L lines of equal amplitude."""
    ell = np.arange(1, n_lines + 1, dtype=float)
    return -np.pi * ell * (ell - 1) / n_lines


def line_phases(n_lines: int, kind: str, seed: int) -> npt.NDArray[np.float64]:
    """Phases [rad] of the multisine lines: ``schroeder``, ``random`` (seeded) or ``zero``."""
    if kind == 'schroeder':
        return schroeder_phases(n_lines)
    if kind == 'random':
        return np.random.default_rng(seed).uniform(0.0, 2 * np.pi, n_lines)
    return np.zeros(n_lines)


def multisine_bins(n_period: int, dt: float, f_start: float, f_end: float,
                   frequencies: Sequence[float]) -> npt.NDArray[np.intp]:
    """
    DFT bins (of one period of ``n_period`` samples) of the multisine lines.

    ``frequencies`` [Hz] if given (each a whole multiple of 1 / (n_period dt), else
    ConfigError naming it), else every multiple in [f_start, f_end]; never DC or Nyquist.
    """
    period = n_period * dt
    if len(frequencies):
        exact = np.asarray(frequencies, dtype=float) * period
        bins = np.round(exact).astype(np.intp)
        for f, e, b in zip(frequencies, exact, bins):
            if abs(e - b) > 1e-6 * max(1.0, e):
                raise ConfigError(f'multisine line {f!r} Hz is not a multiple of 1/period = '
                                  f'{1 / period:.6g} Hz')
        if len(np.unique(bins)) != len(bins):
            raise ConfigError(f'multisine frequencies {list(frequencies)} repeat a line')
        bins = np.sort(bins)
    else:
        low = max(1, math.ceil(f_start * period - 1e-9))
        high = math.floor(f_end * period + 1e-9)
        bins = np.arange(low, high + 1, dtype=np.intp)
    bins = bins[2 * bins < n_period]
    if not len(bins) or bins[0] < 1:
        raise ConfigError(f'no multisine line between f_start={f_start} and f_end={f_end} Hz '
                          f'at 1/period = {1 / period:.6g} Hz below Nyquist')
    return bins


def multisine_period(n_period: int, bins: npt.ArrayLike,
                     phases: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """One period (n_period samples) of sum cos(2 pi b n / P + phi), scaled to peak 1."""
    spectrum = np.zeros(n_period // 2 + 1, dtype=complex)
    spectrum[np.asarray(bins)] = np.exp(1j * np.asarray(phases, dtype=float))
    x = np.fft.irfft(spectrum, n=n_period)
    return x / np.max(np.abs(x))


def periodic_chirp_period(n_period: int, dt: float, f_start: float,
                          f_end: float) -> npt.NDArray[np.float64]:
    """One period of the linear sweep f_start -> f_end over n_period samples (peak 1)."""
    tau = np.arange(n_period) * dt
    return scipy.signal.chirp(tau, f_start, n_period * dt, f_end, method='linear', phi=-90)


def pulse(n: int, shape: str) -> npt.NDArray[np.float64]:
    """Pulse of ``n`` samples (peak 1 at the centre): ``rect``, ``half_sine``, ``hann``."""
    s = (np.arange(n) + 0.5) / n
    if shape == 'half_sine':
        return np.sin(np.pi * s)
    if shape == 'hann':
        return np.sin(np.pi * s) ** 2
    return np.ones(n)


@dataclass(frozen=True)
class SteppedLayout:
    """
    Lines of a stepped sine, in samples from the start of the signal.

    Attributes
    ----------
    frequencies : (L,) ndarray
        Frequencies applied [Hz] (whole periods in whole samples, module docstring).
    starts : (L,) ndarray of int
        First sample of each line (its settling part).
    settle : int
        Samples of settling at each line.
    window : (L,) ndarray of int
        Samples of each measurement window (``periods`` whole periods).
    phase0 : (L,) ndarray
        Phase [rad] at each line's first sample (continuous from line to line).
    end : int
        First sample after the last line.
    dt : float
        Sample time [s].
    """

    frequencies: npt.NDArray[np.float64]
    starts: npt.NDArray[np.intp]
    settle: int
    window: npt.NDArray[np.intp]
    phase0: npt.NDArray[np.float64]
    end: int
    dt: float

    def value(self, j: int) -> float:
        """Sine value at sample j (0 outside the lines)."""
        if j < 0 or j >= self.end:
            return 0.0
        i = int(np.searchsorted(self.starts, j, side='right')) - 1
        return math.sin(self.phase0[i]
                        + 2 * math.pi * self.frequencies[i] * (j - int(self.starts[i])) * self.dt)


def stepped_layout(requested: npt.ArrayLike, dt: float, settle_time: float,
                   periods: int) -> SteppedLayout:
    """Layout of a stepped sine over the ``requested`` frequencies [Hz] (in that order)."""
    requested = np.asarray(requested, dtype=float)
    if not len(requested):
        raise ConfigError('a stepped sine needs at least one frequency')
    nyquist = 0.5 / dt
    window = np.round(periods / (requested * dt)).astype(np.intp)
    actual = periods / (window * dt)
    for f, fa in zip(requested, actual):
        if not 0 < f or not fa < nyquist:
            raise ConfigError(f'stepped-sine frequency {f!r} Hz: {periods} whole periods in '
                              f'whole samples need a frequency below {nyquist} Hz')
    settle = int(round(settle_time / dt))
    lengths = settle + window
    starts = np.concatenate([[0], np.cumsum(lengths)[:-1]]).astype(np.intp)
    advance = np.mod(2 * np.pi * actual * lengths * dt, 2 * np.pi)
    phase0 = np.mod(np.concatenate([[0.0], np.cumsum(advance)[:-1]]), 2 * np.pi)
    return SteppedLayout(actual, starts, settle, window, phase0, int(np.sum(lengths)), float(dt))


def stepped_frequencies(f_start: float, f_end: float, spacing: float) -> npt.NDArray[np.float64]:
    """Lines f_start, f_start + spacing, ... <= f_end [Hz]."""
    if not f_start > 0:
        raise ConfigError(f'stepped-sine lines from f_start = {f_start!r} Hz: need > 0 Hz')
    count = int(math.floor((f_end - f_start) / spacing + 1e-9)) + 1
    return f_start + spacing * np.arange(count, dtype=np.float64)
