"""
Chatter seen in a record of the TCP displacement: Poincare section, growth, off-harmonic energy.

A stable cut vibrates at the tooth-passing frequency and its harmonics only, so the
displacement sampled once per tooth period (the Poincare section) is a fixed point once the
entry transient has died out. Regenerative chatter adds a self-excited vibration: the section
spreads (a circle for a Hopf instability, two alternating points for period doubling), its
spread grows while the cut is linear, and energy appears off the tooth-passing harmonics.
When the vibration exceeds the chip, teeth leave the cut and the growth stops (saturated
chatter).

:func:`detect_chatter` measures, over the record after ``settle``:

* ``growth_rate`` [1/s]: slope of the log RMS, per block, of successive differences of the
  Poincare samples (the difference removes the forced fixed point);
* ``off_harmonic_share``: share of the displacement's AC power farther than ``band`` from every
  tooth-passing harmonic (Hann-windowed periodogram), and the chatter frequency, the strongest
  off-harmonic line;
* ``left_cut_share`` (if the tooth engagement is given): share of engaged tooth samples with
  no chip.

The verdict: 'chatter' if the spread grows by more than a factor ``growth_factor`` over the
window, or if more than ``share_limit`` of the power is off the harmonics and the spread is not
decaying by that factor; else 'tool left the cut' if more than ``left_cut_limit`` of the engaged
samples had no chip (a cut without chatter whose forced vibration exceeds the chip); else
'stable'. Chatter that has saturated leaves the cut too (that bounds it); it is called
chatter. The share catches saturated chatter: when the entry transient is as large as the
limit cycle (a cut just above the limit on a well-damped mode), the spread stops growing within
a few tooth periods while 10-30 % of the power stays off the harmonics; stable cuts leave
0.1-1 % there (the cutting runs of test/test_cutting_node.py and docs/machining.md). A spread
below ``1e-6`` of the vibration's RMS (numeric
noise on a settled cut) is left out of the growth rate.
"""
from __future__ import annotations

from dataclasses import dataclass
import math

import numpy as np
import numpy.typing as npt

from pentapod_sim.errors import ConfigError

VERDICTS = ('stable', 'chatter', 'tool left the cut')
#: Spread of the Poincare section below this share of the vibration RMS is numeric noise.
NOISE_FLOOR = 1e-6


@dataclass(frozen=True)
class ChatterVerdict:
    """
    What a displacement record says about chatter.

    Attributes
    ----------
    verdict : str
        One of :data:`VERDICTS`.
    growth_rate : float
        Growth rate of the Poincare spread [1/s] (negative: decaying; 0 if none).
    off_harmonic_share : float
        Share of the AC power off the tooth-passing harmonics [-].
    chatter_freq : float
        Strongest off-harmonic frequency [Hz] (nan if the verdict is 'stable').
    tooth_freq : float
        Tooth-passing frequency N n / 60 [Hz].
    left_cut_share : float
        Share of engaged tooth samples without a chip (nan if not given).
    poincare : (n_p, d) ndarray
        Displacement sampled once per tooth period after ``settle``.
    """

    verdict: str
    growth_rate: float
    off_harmonic_share: float
    chatter_freq: float
    tooth_freq: float
    left_cut_share: float
    poincare: np.ndarray

    @property
    def is_chatter(self) -> bool:
        """True unless the verdict is 'stable'."""
        return self.verdict != 'stable'


def poincare_section(time: npt.ArrayLike, displacement: npt.ArrayLike, period: float,
                     start: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """
    Displacement once per period from ``start`` (linear interpolation between samples).

    Returns
    -------
    times : (n_p,) ndarray
        ``start + i T`` [s] within the record.
    samples : (n_p, d) ndarray
        Displacement at those times.
    """
    t = np.asarray(time, dtype=float)
    x = np.asarray(displacement, dtype=float).reshape(t.size, -1)
    start = t[0] if start is None else start
    times = start + period * np.arange(int(math.floor((t[-1] - start) / period)) + 1)
    return times, np.column_stack([np.interp(times, t, col) for col in x.T])


def spread_growth_rate(samples: npt.ArrayLike, period: float, blocks: int = 8,
                       floor: float = 0.0) -> float:
    """
    Growth rate [1/s] of the spread of a Poincare section.

    Successive differences of the samples are grouped in ``blocks`` blocks; the slope of log
    RMS per block against the block's time is the rate (RMS over a block, not single samples,
    so that a rotating Hopf spread does not dip through zero). Blocks whose RMS is at or below
    ``floor`` (numeric noise of a settled cut) are left out; if fewer than two remain, the rate
    is that of the first block down to the floor (0 if even the first one is at the floor).
    """
    diff = np.diff(np.asarray(samples, dtype=float), axis=0)
    if diff.shape[0] < 2 * blocks:
        raise ConfigError(f'{diff.shape[0] + 1} tooth periods are too few to measure growth; '
                          f'record at least {2 * blocks + 1}')
    parts = np.array_split(np.sum(diff ** 2, axis=1), blocks)
    rms = np.sqrt([p.mean() for p in parts])
    centres = np.array([np.mean(idx) for idx in np.array_split(np.arange(diff.shape[0]),
                                                               blocks)]) * period
    above = rms > max(floor, 0.0)
    if above.sum() >= 2:
        return float(np.polyfit(centres[above], np.log(rms[above]), 1)[0])
    if not above[0]:
        return 0.0
    return float(np.log(max(floor, 1e-300) / rms[0]) / (centres[1] - centres[0]))


def off_harmonic_power(time: npt.ArrayLike, signal: npt.ArrayLike, tooth_freq: float,
                       band: float) -> tuple[float, float]:
    """
    (share of AC power off the tooth harmonics, frequency [Hz] of the strongest such line).

    Parameters
    ----------
    time, signal : (n,) and (n, d) array_like
        Evenly sampled record.
    tooth_freq : float
        Tooth-passing frequency [Hz].
    band : float
        Half-width [Hz] around each harmonic k * tooth_freq (k >= 0) counted as harmonic.
    """
    t = np.asarray(time, dtype=float)
    x = np.asarray(signal, dtype=float).reshape(t.size, -1)
    dt = float(np.median(np.diff(t)))
    x = x - x.mean(axis=0)
    spec = np.sum(np.abs(np.fft.rfft(x * np.hanning(t.size)[:, None], axis=0)) ** 2, axis=1)
    freq = np.fft.rfftfreq(t.size, dt)
    near = np.abs(freq - tooth_freq * np.round(freq / tooth_freq)) <= band
    total = spec[1:].sum()
    if not total > 0:
        return 0.0, math.nan
    off = np.where(near, 0.0, spec)
    return float(off[1:].sum() / total), float(freq[int(np.argmax(off))])


def detect_chatter(time: npt.ArrayLike, displacement: npt.ArrayLike, spindle_speed: float,
                   teeth: int, settle: float = 0.0, engaged: npt.ArrayLike | None = None,
                   in_cut: npt.ArrayLike | None = None, growth_factor: float = 2.0,
                   share_limit: float = 0.05, left_cut_limit: float = 0.05,
                   band: float | None = None) -> ChatterVerdict:
    """
    Verdict on a record of the TCP displacement (module docstring).

    Parameters
    ----------
    time : (n,) array_like
        Sample times [s], evenly spaced.
    displacement : (n,) or (n, d) array_like
        TCP displacement [m] (e.g. x and y).
    spindle_speed : float
        Spindle speed [rpm].
    teeth : int
        Number of teeth.
    settle : float
        Time [s] from the start left out (the entry transient).
    engaged, in_cut : (n, N) bool array_like, optional
        Per step and tooth: within the engaged angles; cutting a chip (a cutting process's
        state). Both or neither.
    growth_factor, share_limit, left_cut_limit : float
        Thresholds of the verdict (module docstring).
    band : float, optional
        Half-width [Hz] around each harmonic; default 2 % of the tooth-passing frequency or 3
        frequency lines, whichever is wider.
    """
    t = np.asarray(time, dtype=float)
    x = np.asarray(displacement, dtype=float).reshape(t.size, -1)
    if not (spindle_speed > 0 and teeth >= 1):
        raise ConfigError(f'spindle speed {spindle_speed!r} rpm and teeth {teeth!r} must be > 0')
    tooth_freq = teeth * spindle_speed / 60.0
    keep = t >= t[0] + settle
    t, x = t[keep], x[keep]
    if t.size < 16:
        raise ConfigError(f'settle = {settle!r} s leaves {t.size} samples of the record')
    span = t[-1] - t[0]
    _, section = poincare_section(t, x, 1.0 / tooth_freq)
    vibration = np.sqrt(np.mean(np.sum((x - x.mean(axis=0)) ** 2, axis=1)))
    rate = spread_growth_rate(section, 1.0 / tooth_freq, floor=NOISE_FLOOR * vibration)
    band = max(0.02 * tooth_freq, 3.0 / span) if band is None else band
    share, freq = off_harmonic_power(t, x, tooth_freq, band)
    left = math.nan
    if (engaged is None) != (in_cut is None):
        raise ConfigError('give both the engagement and the in-cut flags, or neither')
    if engaged is not None and in_cut is not None:
        eng = np.asarray(engaged, dtype=bool)[keep]
        cuts = np.asarray(in_cut, dtype=bool)[keep]
        left = float((eng & ~cuts).sum() / max(eng.sum(), 1))
    growth = rate * span
    if growth > math.log(growth_factor) or (share > share_limit
                                            and growth > -math.log(growth_factor)):
        verdict = 'chatter'
    elif left > left_cut_limit:
        verdict = 'tool left the cut'
    else:
        verdict = 'stable'
    return ChatterVerdict(verdict, rate, share, freq if verdict != 'stable' else math.nan,
                          tooth_freq, left, section)
