"""
Force signals for exciting the machine at the TCP: impulse, step, sine, chirp, random.

Signals are sampled at the plant steps t_k = k dt (the exciter answers step k with the force
for t_k, exactly as the offline closed loop does). Force [N] = magnitude(t_k) * direction,
with direction a unit vector in the machine frame. Nothing is applied before ``start_delay``
or after ``start_delay + duration``.
"""
from __future__ import annotations

from dataclasses import dataclass, field
import math

import numpy as np
import numpy.typing as npt
import scipy.signal

from pentapod_sim.errors import ConfigError

KINDS = ('impulse', 'step', 'sine', 'chirp', 'random', 'none')


@dataclass
class ExcitationSpec:
    """
    Parameters of an excitation signal.

    Attributes
    ----------
    kind : str
        One of ``impulse`` (hammer: ``amplitude`` held for ``pulse_width``), ``step``,
        ``sine`` (at ``frequency``), ``chirp`` (linear sweep ``f_start`` -> ``f_end`` over
        ``duration``), ``random`` (Gaussian, band-limited to [f_start, f_end], RMS
        ``amplitude``, seeded), ``none``.
    amplitude : float
        Peak force [N] (RMS for random).
    direction : (3,) array_like
        Direction of the force in the machine frame (normalised here).
    frequency : float
        Sine frequency [Hz].
    f_start, f_end : float
        Chirp start/end frequency, random band edges [Hz].
    duration : float
        Length of the signal [s]; inf for a step or sine without end.
    start_delay : float
        Time of the first non-zero sample [s].
    pulse_width : float
        Impulse length [s]; 0 = one sample.
    seed : int
        Seed of the random generator.
    """

    kind: str = 'impulse'
    amplitude: float = 100.0
    direction: npt.ArrayLike = field(default_factory=lambda: [1.0, 0.0, 0.0])
    frequency: float = 40.0
    f_start: float = 5.0
    f_end: float = 300.0
    duration: float = math.inf
    start_delay: float = 0.0
    pulse_width: float = 0.0
    seed: int = 0


class Excitation:
    """
    A sampled excitation signal.

    Parameters
    ----------
    spec : ExcitationSpec
        Signal parameters (ConfigError names a bad one).
    dt : float
        Sample time of the plant [s].
    """

    def __init__(self, spec: ExcitationSpec, dt: float):
        self.spec = spec
        self.dt = float(dt)
        _check(spec, self.dt)
        direction = np.asarray(spec.direction, dtype=float)
        self.direction = direction / np.linalg.norm(direction)
        self.first = int(math.ceil(spec.start_delay / self.dt - 1e-9))
        self._random = None
        if spec.kind == 'random':
            self._random = _band_limited_noise(spec, self.dt, self._n_active())

    def _n_active(self) -> int:
        """Number of samples in the active window (finite for random/chirp)."""
        return int(round(self.spec.duration / self.dt))

    def magnitude(self, k: int) -> float:
        """Signed magnitude of the force [N] at step k."""
        spec, j = self.spec, k - self.first
        if spec.kind == 'none' or j < 0 or j * self.dt >= spec.duration - 1e-12 * self.dt:
            return 0.0
        tau = j * self.dt  # time since the start of the signal [s]
        if spec.kind == 'impulse':
            width = max(1, int(round(spec.pulse_width / self.dt)))
            return spec.amplitude if j < width else 0.0
        if spec.kind == 'step':
            return spec.amplitude
        if spec.kind == 'sine':
            return spec.amplitude * math.sin(2 * math.pi * spec.frequency * tau)
        if spec.kind == 'chirp':
            return spec.amplitude * float(scipy.signal.chirp(
                tau, spec.f_start, spec.duration, spec.f_end, method='linear', phi=-90))
        return float(self._random[j])

    def force(self, k: int) -> npt.NDArray[np.float64]:
        """Force vector [N] (x, y, z) at step k."""
        return self.magnitude(k) * self.direction

    def series(self, n_steps: int) -> npt.NDArray[np.float64]:
        """Forces (n_steps, 3) [N] of steps 0..n_steps-1."""
        mags = np.array([self.magnitude(k) for k in range(n_steps)])
        return mags[:, None] * self.direction[None, :]


def _check(spec: ExcitationSpec, dt: float) -> None:
    """Raise ConfigError naming the first bad parameter."""
    if spec.kind not in KINDS:
        raise ConfigError(f'excitation kind {spec.kind!r} is not one of {", ".join(KINDS)}')
    if not np.isfinite(dt) or dt <= 0:
        raise ConfigError(f'sample time must be > 0 s, got {dt!r}')
    direction = np.asarray(spec.direction, dtype=float)
    if direction.shape != (3,) or not np.all(np.isfinite(direction)) or not direction.any():
        raise ConfigError(f'direction must be a non-zero 3-vector, got {spec.direction!r}')
    if not np.isfinite(spec.amplitude):
        raise ConfigError(f'amplitude must be finite [N], got {spec.amplitude!r}')
    if not spec.start_delay >= 0 or not np.isfinite(spec.start_delay):
        raise ConfigError(f'start_delay must be >= 0 s, got {spec.start_delay!r}')
    if not spec.duration > 0:
        raise ConfigError(f'duration must be > 0 s, got {spec.duration!r}')
    if spec.pulse_width < 0:
        raise ConfigError(f'pulse_width must be >= 0 s, got {spec.pulse_width!r}')
    nyquist = 0.5 / dt
    if spec.kind == 'sine' and not 0 < spec.frequency < nyquist:
        raise ConfigError(f'frequency {spec.frequency} Hz must lie in (0, {nyquist}) Hz')
    if spec.kind in ('chirp', 'random'):
        if not math.isfinite(spec.duration):
            raise ConfigError(f'a {spec.kind} excitation needs a finite duration [s]')
        if not 0 <= spec.f_start < spec.f_end < nyquist:
            raise ConfigError(f'band f_start={spec.f_start}, f_end={spec.f_end} Hz must '
                              f'satisfy 0 <= f_start < f_end < {nyquist} Hz')


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
