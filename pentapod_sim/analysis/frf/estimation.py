"""
Estimate frequency response functions (FRFs) from recorded excitation and response signals.

Estimators (x = input u, y = output, G = cross/auto spectral densities from scipy.signal):
H1 = G_uy / G_uu (unbiased by output noise), H2 = G_yy / G_yu (unbiased by input noise),
coherence = |G_uy|^2 / (G_uu G_yy). Window and averaging follow the excitation type:

* ``random``: Hann window, Welch averaging with 50 % overlap.
* ``chirp``: Hann window, few long segments with 75 % overlap (each frequency appears in
  several segments, so coherence stays meaningful).
* ``impulse``: one record, force window on u (zero outside the pulse) and, if the response has
  not decayed by the end of the record, an exponential window on y and u; the added damping
  ``1 / (tau omega)`` is recorded in ``FrfResult.exp_window_tau`` and removed by the peak
  identification. Coherence is undefined for a single record (NaN).
* ``sine``: one frequency; complex amplitudes by least squares on the last half of the record.
"""
import dataclasses
import logging
from typing import Optional, TypedDict
import warnings

import numpy as np
import numpy.typing as npt
from scipy import signal

from pentapod_sim.analysis.bag.reader import Series
from pentapod_sim.errors import BagError

LOGGER = logging.getLogger(__name__)
EXCITATIONS = ('random', 'chirp', 'impulse', 'sine')


@dataclasses.dataclass
class FrfResult:
    """
    An estimated FRF.

    Attributes
    ----------
    freq : (F,) ndarray
        Frequency [Hz].
    H : (F,) complex ndarray
        Preferred estimate (H1; for impulse and sine the single-record ratio) [output/input].
    H1, H2 : (F,) complex ndarray
        The two classical estimators (equal for a single record).
    coherence : (F,) ndarray
        Ordinary coherence in [0, 1]; NaN when undefined (single record).
    input_unit, output_unit : str
        Units of input and output, so H is in ``output_unit/input_unit``.
    excitation : str
        Excitation type the estimator was chosen for.
    n_averages : int
        Number of averaged segments.
    exp_window_tau : float or None
        Time constant [s] of an applied exponential window (impulse), else None.
    label : str
        Free text (e.g. ``'bag: input -> output'``).
    """

    freq: np.ndarray
    H: np.ndarray
    H1: np.ndarray
    H2: np.ndarray
    coherence: np.ndarray
    input_unit: str = ''
    output_unit: str = ''
    excitation: str = 'random'
    n_averages: int = 1
    exp_window_tau: Optional[float] = None
    label: str = ''

    @property
    def unit(self) -> str:
        """Unit of H, e.g. ``'m/N'``."""
        return f'{self.output_unit}/{self.input_unit}'


class _Labels(TypedDict):
    """The text fields of a :class:`FrfResult` every estimator passes on unchanged."""

    input_unit: str
    output_unit: str
    excitation: str
    label: str


def estimate_frf(u: npt.ArrayLike, y: npt.ArrayLike, fs: float, excitation: str = 'random',
                 nperseg: Optional[int] = None, input_unit: str = '', output_unit: str = '',
                 label: str = '') -> FrfResult:
    """
    Estimate the FRF from input ``u`` to output ``y`` sampled at ``fs``.

    Parameters
    ----------
    u, y : (N,) array_like
        Input (e.g. force [N]) and output (e.g. displacement [m]) on the same time grid.
    fs : float
        Sampling rate [Hz].
    excitation : {'random', 'chirp', 'impulse', 'sine'}
        Excitation type; selects window and averaging (module docstring).
    nperseg : int, optional
        Segment length [samples] for random/chirp; default N // 8 (random), N // 4 (chirp).
    input_unit, output_unit, label : str
        Units and a free label, stored in the result.

    Returns
    -------
    FrfResult

    Raises
    ------
    ValueError
        On an unknown excitation, mismatched lengths or fewer than 16 samples.
    """
    u = np.asarray(u, dtype=float)
    y = np.asarray(y, dtype=float)
    if excitation not in EXCITATIONS:
        raise ValueError(f'excitation {excitation!r} is not one of {EXCITATIONS}')
    if u.shape != y.shape or u.ndim != 1 or len(u) < 16:
        raise ValueError(f'u and y must be 1-D of equal length >= 16, got {u.shape}, {y.shape}')
    if fs <= 0:
        raise ValueError(f'sampling rate fs={fs} Hz must be positive')
    if not np.any(u):
        raise ValueError('the input signal is identically zero')
    meta: _Labels = {'input_unit': input_unit, 'output_unit': output_unit,
                     'excitation': excitation, 'label': label}
    if excitation == 'impulse':
        return _impulse_frf(u, y, fs, meta)
    if excitation == 'sine':
        return _sine_frf(u, y, fs, meta)
    n = len(u)
    if nperseg is None:
        nperseg = n // 8 if excitation == 'random' else n // 4
    nperseg = int(min(max(nperseg, 16), n))
    overlap = nperseg // 2 if excitation == 'random' else (3 * nperseg) // 4
    kw = {'fs': fs, 'window': 'hann', 'nperseg': nperseg, 'noverlap': overlap,
          'detrend': 'constant'}
    freq, g_uu = signal.welch(u, **kw)
    _, g_yy = signal.welch(y, **kw)
    _, g_uy = signal.csd(u, y, **kw)  # scipy: conj(U) Y, i.e. G_uy
    with np.errstate(divide='ignore', invalid='ignore'):
        h1 = g_uy / g_uu
        h2 = g_yy / np.conj(g_uy)
        coherence = np.clip(np.abs(g_uy) ** 2 / (g_uu * g_yy), 0.0, 1.0)
    n_avg = 1 + (n - nperseg) // (nperseg - overlap)
    LOGGER.info('FRF %s: %s, %d samples, %d segments of %d, df = %.4g Hz', label, excitation,
                n, n_avg, nperseg, fs / nperseg)
    return FrfResult(freq, h1, h1, h2, coherence, n_averages=n_avg, **meta)


def _impulse_frf(u: np.ndarray, y: np.ndarray, fs: float, meta: _Labels) -> FrfResult:
    n = len(u)
    peak = int(np.argmax(np.abs(u)))
    threshold = 0.02 * abs(u[peak])
    # force window: keep the contiguous pulse around the peak, zero the rest (noise, rebounds)
    first, last = peak, peak
    while first > 0 and abs(u[first - 1]) > threshold:
        first -= 1
    while last < n - 1 and abs(u[last + 1]) > threshold:
        last += 1
    u_win = np.zeros_like(u)
    u_win[first:last + 1] = u[first:last + 1]
    tail = y[int(0.9 * n):]
    tau = None
    if np.sqrt(np.mean(tail ** 2)) > 0.01 * np.max(np.abs(y)):
        duration = (n - first) / fs
        tau = duration / np.log(100.0)  # window falls to 1 % at the record end
        window = np.ones(n)
        window[first:] = np.exp(-(np.arange(n - first) / fs) / tau)
        y = y * window
        u_win = u_win * window
    freq = np.fft.rfftfreq(n, 1.0 / fs)
    spec_u = np.fft.rfft(u_win)
    spec_y = np.fft.rfft(y)
    with np.errstate(divide='ignore', invalid='ignore'):
        h = spec_y / spec_u
    weak = np.abs(spec_u) < 1e-3 * np.max(np.abs(spec_u))
    if np.any(weak):
        warnings.warn(f'impulse spectrum falls below -60 dB above {freq[np.argmax(weak)]:.1f} Hz;'
                      ' the FRF there is unreliable')
    return FrfResult(freq, h, h, h.copy(), np.full(len(freq), np.nan), n_averages=1,
                     exp_window_tau=tau, **meta)


def _sine_frf(u: np.ndarray, y: np.ndarray, fs: float, meta: _Labels) -> FrfResult:
    n = len(u)
    spec = np.abs(np.fft.rfft(u - u.mean()))
    k = int(np.argmax(spec[1:])) + 1
    if 0 < k < len(spec) - 1:  # parabolic refinement of the excitation frequency
        a, b, c = np.log(spec[k - 1:k + 2] + 1e-300)
        k = k + 0.5 * (a - c) / (a - 2 * b + c)
    f0 = k * fs / n
    t = np.arange(n) / fs
    half = slice(n // 2, n)  # skip the transient
    basis = np.column_stack([np.cos(2 * np.pi * f0 * t), np.sin(2 * np.pi * f0 * t),
                             np.ones(n)])[half]
    cu = np.linalg.lstsq(basis, u[half], rcond=None)[0]
    cy = np.linalg.lstsq(basis, y[half], rcond=None)[0]
    # x(t) = a cos + b sin = Re{(a - j b) e^{j w t}}
    h = np.array([(cy[0] - 1j * cy[1]) / (cu[0] - 1j * cu[1])])
    resid = y[half] - basis @ cy
    coh = 1.0 - np.var(resid) / max(np.var(y[half]), 1e-300)
    return FrfResult(np.array([f0]), h, h, h.copy(), np.array([coh]), **meta)


def aligned(u: Series, y: Series) -> tuple[np.ndarray, np.ndarray, float]:
    """
    Put two recorded series on their common sample times.

    Returns
    -------
    u_values, y_values : (N,) ndarray
        Samples at the common times.
    fs : float
        Sampling rate [Hz] (median time step).

    Raises
    ------
    BagError
        If fewer than 16 common times exist.
    """
    common, iu, iy = np.intersect1d(u.time_ns, y.time_ns, return_indices=True)
    if len(common) < 16:
        raise BagError(f'{u.label} and {y.label} share only {len(common)} sample times; '
                       'lockstep recordings stamp both with the step time')
    lost = 1.0 - len(common) / max(len(u.time_ns), len(y.time_ns))
    if lost > 0.01:
        warnings.warn(f'{lost:.1%} of the samples of {u.label} / {y.label} have no partner')
    steps = np.diff(common)
    dt = np.median(steps)
    if np.any(np.abs(steps - dt) > 0.01 * dt):
        warnings.warn(f'{int(np.sum(np.abs(steps - dt) > 0.01 * dt))} irregular time steps '
                      f'(median {dt * 1e-9:g} s); FRF assumes uniform sampling')
    return u.values[iu], y.values[iy], 1e9 / dt


def frf_from_series(u: Series, y: Series, excitation: str = 'random',
                    nperseg: Optional[int] = None) -> FrfResult:
    """
    Estimate the FRF between two recorded series (aligned on common stamps).

    Parameters
    ----------
    u, y : Series
        Input and output series from :meth:`pentapod_sim.analysis.bag.reader.Bag.series`.
    excitation : str
        See :func:`estimate_frf`.
    nperseg : int, optional
        See :func:`estimate_frf`.

    Returns
    -------
    FrfResult
    """
    u_val, y_val, fs = aligned(u, y)
    return estimate_frf(u_val, y_val, fs, excitation, nperseg, u.unit, y.unit,
                        label=f'{u.label} -> {y.label}')


def amplitude_spectrum(x: npt.ArrayLike, fs: float, nperseg: Optional[int] = None
                       ) -> tuple[np.ndarray, np.ndarray]:
    """
    Single-sided amplitude spectrum (peak amplitude of a sinusoid per bin), Welch/Hann.

    Parameters
    ----------
    x : (N,) array_like
        Signal (e.g. actuator stroke [m] or force [N]).
    fs : float
        Sampling rate [Hz].
    nperseg : int, optional
        Segment length; default N // 8.

    Returns
    -------
    freq : (F,) ndarray
        Frequency [Hz].
    amplitude : (F,) ndarray
        Peak amplitude in the unit of x (sqrt(2 * power spectrum)).
    """
    x = np.asarray(x, dtype=float)
    nperseg = int(min(max(nperseg or len(x) // 8, 16), len(x)))
    freq, power = signal.welch(x, fs=fs, window='hann', nperseg=nperseg, scaling='spectrum')
    return freq, np.sqrt(2.0 * power)
