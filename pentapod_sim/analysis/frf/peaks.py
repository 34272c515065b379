"""
Resonance peaks of a measured FRF and their damping ratios; peak reductions between two FRFs.

Damping is identified with the half-power bandwidth: around a peak of magnitude |H|max the
magnitude crosses |H|max / sqrt(2) at f1 < fn < f2 (linear interpolation between bins), and for
light damping zeta = (f2 - f1) / (2 fn). The peak frequency and magnitude are refined by a
parabola through the log magnitude of the three highest bins. If the FRF used an exponential
window with time constant tau, its added damping 1 / (2 pi fn tau) is subtracted.
"""
import dataclasses
import logging
from typing import Optional, Sequence
import warnings

import numpy as np
from scipy import signal

from pentapod_sim.analysis.frf.estimation import FrfResult

LOGGER = logging.getLogger(__name__)


@dataclasses.dataclass
class Resonance:
    """
    One identified resonance.

    Attributes
    ----------
    freq : float
        Peak frequency [Hz].
    magnitude : float
        Peak |H| [unit of the FRF].
    damping_ratio : float
        Identified damping ratio [-] (NaN when the half-power points are not resolved).
    coherence : float
        Coherence at the peak bin (NaN if undefined).
    """

    freq: float
    magnitude: float
    damping_ratio: float
    coherence: float


@dataclasses.dataclass
class PeakReduction:
    """A resonance of a reference FRF matched with one of a compared FRF."""

    freq_ref: float
    freq_cmp: float
    magnitude_ref: float
    magnitude_cmp: float
    reduction_db: float  # 20 log10(ref / cmp), > 0 means the compared run is lower
    damping_ref: float
    damping_cmp: float


def find_resonances(result: FrfResult, fmin: float = 0.0, fmax: Optional[float] = None,
                    prominence_db: float = 6.0, max_peaks: int = 20) -> list[Resonance]:
    """
    Find resonance peaks of ``|H|`` and identify their damping ratios.

    Parameters
    ----------
    result : FrfResult
        Measured FRF.
    fmin, fmax : float
        Frequency band searched [Hz] (fmax default: Nyquist).
    prominence_db : float
        Minimal peak prominence [dB].
    max_peaks : int
        Keep at most this many (the most prominent), sorted by frequency.

    Returns
    -------
    list of Resonance
    """
    freq, mag = result.freq, np.abs(result.H)
    band = (freq >= fmin) & (freq <= (fmax if fmax is not None else freq[-1])) & (freq > 0)
    band &= np.isfinite(mag) & (mag > 0)
    idx = np.flatnonzero(band)
    if len(idx) < 3:
        return []
    mag_db = 20 * np.log10(mag[idx])
    found, props = signal.find_peaks(mag_db, prominence=prominence_db)
    order = np.argsort(props['prominences'])[::-1][:max_peaks]
    peaks = sorted(idx[found[order]])
    out = [_identify(result, k) for k in peaks]
    LOGGER.info('found %d resonances in %s', len(out), result.label or 'FRF')
    return out


def _identify(result: FrfResult, k: int) -> Resonance:
    freq, mag = result.freq, np.abs(result.H)
    df = freq[1] - freq[0]
    a, b, c = np.log(mag[k - 1:k + 2])
    shift = 0.5 * (a - c) / (a - 2 * b + c) if (a - 2 * b + c) < 0 else 0.0
    fn = freq[k] + shift * df
    peak = float(np.exp(b - 0.25 * (a - c) * shift))
    half = peak / np.sqrt(2.0)
    f1 = _crossing(freq, mag, half, k, -1)
    f2 = _crossing(freq, mag, half, k, +1)
    zeta = np.nan
    if f1 is not None and f2 is not None:
        zeta = (f2 - f1) / (2.0 * fn)
        if np.isfinite(zeta) and (f2 - f1) < 3 * df:
            warnings.warn(f'half-power band at {fn:.2f} Hz spans only {(f2 - f1) / df:.1f} '
                          'bins; damping ratio is coarse (use longer segments)')
    if result.exp_window_tau and np.isfinite(zeta):
        zeta -= 1.0 / (2 * np.pi * fn * result.exp_window_tau)
    coh = float(result.coherence[k]) if result.coherence is not None else np.nan
    return Resonance(float(fn), peak, float(zeta), coh)


def _crossing(freq: np.ndarray, mag: np.ndarray, level: float, k: int, step: int
              ) -> Optional[float]:
    """Frequency where |H| falls below ``level`` walking from bin k in direction step."""
    j = k
    while 0 <= j + step < len(mag):
        if mag[j + step] < level:
            lo, hi = mag[j + step], mag[j]
            frac = (hi - level) / (hi - lo)
            return freq[j] + frac * (freq[j + step] - freq[j])
        j += step
    return None


def peak_reductions(reference: Sequence[Resonance], compared: Sequence[Resonance],
                    rel_tol: float = 0.15) -> list[PeakReduction]:
    """
    Match the resonances of two runs by frequency and give the peak reduction.

    Parameters
    ----------
    reference, compared : list of Resonance
        Resonances of the reference (e.g. undamped) and compared (damped) run.
    rel_tol : float
        Largest relative frequency distance for a match [-].

    Returns
    -------
    list of PeakReduction
        One per reference resonance with a match.
    """
    rows = []
    for ref in reference:
        if not compared:
            break
        best = min(compared, key=lambda r: abs(r.freq - ref.freq))
        if abs(best.freq - ref.freq) > rel_tol * ref.freq:
            continue
        rows.append(PeakReduction(ref.freq, best.freq, ref.magnitude, best.magnitude,
                                  float(20 * np.log10(ref.magnitude / best.magnitude)),
                                  ref.damping_ratio, best.damping_ratio))
    return rows
