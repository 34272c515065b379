"""
Force signals for exciting the machine at the TCP.

Kinds: impulse (shaped pulse), step, sine, chirp, random, and for lightly damped structures
multisine, periodic chirp and stepped sine (:mod:`pentapod_sim.sim.excitation_signals` defines
them). Signals are sampled at the plant steps t_k = k dt (the exciter answers step k with the
force for t_k, exactly as the offline closed loop does). Force [N] = magnitude(t_k) *
direction, with direction a unit vector in the machine frame. Nothing is applied before
``start_delay`` or after ``start_delay + duration``. Every signal is deterministic: random
ones are seeded.

The parameters are an :class:`ExcitationSpec` (:mod:`pentapod_sim.sim.excitation_spec`, with
its JSON form :func:`spec_to_dict` / :func:`spec_from_dict`); :class:`Excitation` also tells
the analysis what it needs: samples per period, excited lines, settling periods, stepped-sine
measurement windows and the crest factor.
"""
from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt
import scipy.signal

from pentapod_sim.errors import ConfigError
from pentapod_sim.sim import excitation_signals as signals
from pentapod_sim.sim.excitation_spec import (
    check_spec,
    ExcitationSpec,
    KINDS,
    period_samples,
    PERIODIC_KINDS,
    PHASES,
    PULSE_SHAPES,
    spec_from_dict,
    spec_to_dict,
)

__all__ = ['Excitation', 'ExcitationSpec', 'KINDS', 'PERIODIC_KINDS', 'PHASES', 'PULSE_SHAPES',
           'spec_from_dict', 'spec_to_dict']


class Excitation:
    """
    A sampled excitation signal.

    Parameters
    ----------
    spec : ExcitationSpec
        Signal parameters (ConfigError names a bad one).
    dt : float
        Sample time of the plant [s].

    Attributes
    ----------
    first : int
        Plant step of the signal's first sample (start_delay / dt, rounded up).
    direction : (3,) ndarray
        Unit direction of the force.
    """

    def __init__(self, spec: ExcitationSpec, dt: float):
        self.spec = spec
        self.dt = float(dt)
        check_spec(spec, self.dt)
        direction = np.asarray(spec.direction, dtype=float)
        self.direction = direction / np.linalg.norm(direction)
        self.first = int(math.ceil(spec.start_delay / self.dt - 1e-9))
        self._random: npt.NDArray[np.float64] | None = None
        # one period (periodic kinds) or the pulse (impulse)
        self._table: npt.NDArray[np.float64] | None = None
        self._bins = np.zeros(0, dtype=np.intp)
        self._stepped: signals.SteppedLayout | None = None
        kind = spec.kind
        if kind == 'random':
            self._random = _band_limited_noise(spec, self.dt, self._n_active())
        elif kind == 'impulse':
            n = max(1, int(round(spec.pulse_width / self.dt)))
            self._table = spec.amplitude * signals.pulse(n, spec.pulse_shape)
        elif kind in PERIODIC_KINDS:
            n = period_samples(spec.period, self.dt)
            freqs = spec.frequencies if kind == 'multisine' else []
            self._bins = signals.multisine_bins(n, self.dt, spec.f_start, spec.f_end, freqs)
            if kind == 'multisine':
                phases = signals.line_phases(len(self._bins), spec.phases, spec.seed)
                unit = signals.multisine_period(n, self._bins, phases)
            else:
                unit = signals.periodic_chirp_period(n, self.dt, spec.f_start, spec.f_end)
            self._table = spec.amplitude * unit
        elif kind == 'stepped_sine':
            requested = (spec.frequencies if len(spec.frequencies) else
                         signals.stepped_frequencies(spec.f_start, spec.f_end,
                                                     spec.line_spacing))
            self._stepped = signals.stepped_layout(requested, self.dt, spec.settle_time,
                                                   int(spec.periods_per_line))
            needed = self._stepped.end * self.dt
            if needed > spec.duration * (1 + 1e-12):
                raise ConfigError(f'duration {spec.duration!r} s ends before the last '
                                  f'stepped-sine line (the lines need {needed:.6g} s)')

    def _n_active(self) -> int:
        """Number of samples in the active window (finite for random/chirp)."""
        return int(round(self.spec.duration / self.dt))

    # --- what the analysis needs -----------------------------------------------------------

    @property
    def period_steps(self) -> int | None:
        """Samples per period of a periodic kind (multisine, periodic chirp), else None."""
        table = self._table
        return len(table) if self.spec.kind in PERIODIC_KINDS and table is not None else None

    @property
    def lines_hz(self) -> npt.NDArray[np.float64]:
        """
        Excited frequencies [Hz].

        Multisine lines; for a periodic chirp the multiples of 1/period in [f_start, f_end]
        (where its energy lies; a little spills outside); stepped-sine frequencies as applied;
        empty for the other kinds.
        """
        period = self.period_steps
        if period is not None:
            return self._bins / (period * self.dt)
        if self._stepped is not None:
            return self._stepped.frequencies.copy()
        return np.zeros(0)

    @property
    def settle_periods(self) -> int:
        """Leading periods the analysis discards (periodic kinds; 0 for the others)."""
        return int(self.spec.settle_periods) if self.spec.kind in PERIODIC_KINDS else 0

    def stepped_windows(self) -> list[tuple[float, int, int]]:
        """
        Measurement windows of a stepped sine (empty list for other kinds).

        Returns
        -------
        list of (frequency [Hz], first step, end step)
            Per line, after its settling: plant steps first .. end - 1 (start_delay
            included) hold exactly ``periods_per_line`` periods of the frequency.
        """
        lay = self._stepped
        if lay is None:
            return []
        return [(float(f), self.first + int(s) + lay.settle, self.first + int(s) + lay.settle
                 + int(n)) for f, s, n in zip(lay.frequencies, lay.starts, lay.window)]

    @property
    def crest_factor(self) -> float:
        """
        Peak / RMS of the signal.

        Over one period for periodic kinds, over the pulse for an impulse, over the record
        for random; sqrt(2) for sine, chirp and stepped sine, 1 for a step, NaN for none.
        """
        kind = self.spec.kind
        values = self._random if kind == 'random' else self._table
        if values is not None:
            rms = float(np.sqrt(np.mean(values ** 2)))
            return float(np.max(np.abs(values))) / rms if rms > 0 else math.nan
        if kind in ('sine', 'chirp', 'stepped_sine'):
            return math.sqrt(2.0)
        return 1.0 if kind == 'step' else math.nan

    # --- samples ---------------------------------------------------------------------------

    def magnitude(self, k: int) -> float:
        """Signed magnitude of the force [N] at step k."""
        spec, j = self.spec, k - self.first
        if spec.kind == 'none' or j < 0 or j * self.dt >= spec.duration - 1e-12 * self.dt:
            return 0.0
        tau = j * self.dt  # time since the start of the signal [s]
        kind, table = spec.kind, self._table
        if kind in PERIODIC_KINDS and table is not None:
            return float(table[j % len(table)])
        if kind == 'impulse' and table is not None:
            return float(table[j]) if j < len(table) else 0.0
        if kind == 'step':
            return spec.amplitude
        if kind == 'sine':
            return spec.amplitude * math.sin(2 * math.pi * spec.frequency * tau)
        if kind == 'chirp':
            return spec.amplitude * float(scipy.signal.chirp(
                tau, spec.f_start, spec.duration, spec.f_end, method='linear', phi=-90))
        if kind == 'stepped_sine' and self._stepped is not None:
            return spec.amplitude * self._stepped.value(j)
        assert self._random is not None     # the one kind left
        return float(self._random[j])

    def force(self, k: int) -> npt.NDArray[np.float64]:
        """Force vector [N] (x, y, z) at step k."""
        return self.magnitude(k) * self.direction

    def series(self, n_steps: int) -> npt.NDArray[np.float64]:
        """Forces (n_steps, 3) [N] of steps 0..n_steps-1."""
        mags = np.array([self.magnitude(k) for k in range(n_steps)])
        return mags[:, None] * self.direction[None, :]


def _band_limited_noise(spec: ExcitationSpec, dt: float, n: int) -> npt.NDArray[np.float64]:
    """Seeded Gaussian noise, Butterworth band-pass (zero phase), scaled to RMS amplitude."""
    rng = np.random.default_rng(spec.seed)
    white = rng.standard_normal(n)
    fs = 1.0 / dt
    if spec.f_start > 0:
        sos = scipy.signal.butter(4, [spec.f_start, spec.f_end], 'bandpass', fs=fs,
                                  output='sos')
    else:
        sos = scipy.signal.butter(4, spec.f_end, 'lowpass', fs=fs, output='sos')
    noise = scipy.signal.sosfiltfilt(sos, white)
    rms = float(np.sqrt(np.mean(noise ** 2)))
    return noise * (spec.amplitude / rms if rms > 0 else 0.0)
