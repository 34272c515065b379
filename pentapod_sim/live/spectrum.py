"""
Running amplitude spectrum of the newest samples of a signal (ROS-free).

:func:`amplitude_spectrum` is a Hann-windowed periodogram (scipy.signal.periodogram, mean
removed) scaled so that a sine of amplitude A [unit] whose frequency falls on a bin shows a
peak of exactly A at that bin (between 0.85 A and A between bins: the Hann scalloping loss).
:class:`RunningSpectrum` keeps the newest ``n`` samples of a stream; lost samples (a best
effort subscription) are filled by linear interpolation on the step grid.
"""
from __future__ import annotations

import numpy as np
import numpy.typing as npt
import scipy.signal


def amplitude_spectrum(x: npt.NDArray[np.float64], dt: float
                       ) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """
    Single-sided amplitude spectrum of the columns of x.

    Parameters
    ----------
    x : (n,) or (n, c) float ndarray
        Uniformly sampled signal(s).
    dt : float
        Sample period [s].

    Returns
    -------
    f : (n // 2 + 1,) ndarray
        Frequencies [Hz].
    amplitude : (n // 2 + 1,) or (n // 2 + 1, c) ndarray
        Peak amplitude of the sine at each frequency [unit of x]; the mean is removed, so the
        0 Hz bin is about 0.
    """
    n = x.shape[0]
    f, power = scipy.signal.periodogram(x, fs=1.0 / dt, window='hann', detrend='constant',
                                        scaling='spectrum', axis=0)
    # 'spectrum' scaling gives the mean square of each sine (A^2 / 2) in the bins that scipy
    # doubled for the one-sided spectrum; 0 Hz (and n/2 for even n) hold A^2
    factor = np.full(len(f), 2.0)
    factor[0] = 1.0
    if n % 2 == 0:
        factor[-1] = 1.0
    shape = (-1,) + (1,) * (power.ndim - 1)
    return f, np.sqrt(power * factor.reshape(shape))


class RunningSpectrum:
    """
    Amplitude spectrum over the newest ``n`` samples of a stream.

    Parameters
    ----------
    n : int
        Samples per spectrum (frequency resolution 1 / (n dt)).
    """

    def __init__(self, n: int):
        if n < 8:
            raise ValueError(f'a spectrum needs at least 8 samples, got {n}')
        self.n = int(n)
        self.reset()

    def reset(self) -> None:
        """Forget every sample (a new run starts)."""
        self.stamps = np.zeros(0, dtype=np.int64)
        self.values = np.zeros((0, 0))
        self.dt_ns = 0   # smallest stamp step seen [ns] = the sample period

    def add(self, stamps: npt.NDArray[np.int64], values: npt.NDArray[np.float64]) -> None:
        """Append samples (stamps increasing, later than the held ones)."""
        if len(stamps) == 0:
            return
        if self.values.shape[1:] != values.shape[1:]:
            self.reset()
            self.values = np.zeros((0,) + values.shape[1:])
        steps = np.diff(np.concatenate([self.stamps[-1:], stamps]))
        steps = steps[steps > 0]
        if len(steps):
            smallest = int(steps.min())
            self.dt_ns = smallest if self.dt_ns == 0 else min(self.dt_ns, smallest)
        self.stamps = np.concatenate([self.stamps, stamps])[-self.n:]
        self.values = np.concatenate([self.values, values])[-self.n:]

    @property
    def newest(self) -> int:
        """Stamp of the newest sample [ns] (-1 if none)."""
        return int(self.stamps[-1]) if len(self.stamps) else -1

    def ready(self) -> bool:
        """True once the newest n steps are covered (ends included)."""
        return (self.dt_ns > 0 and len(self.stamps) > 1
                and self.stamps[-1] - self.stamps[0] >= (self.n - 1) * self.dt_ns)

    def compute(self) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]] | None:
        """
        Spectrum of the n steps ending at the newest sample, or None if not :meth:`ready`.

        Returns
        -------
        f : (n // 2 + 1,) ndarray
            Frequencies [Hz].
        amplitude : (n // 2 + 1, c) ndarray
            Amplitudes per column (see :func:`amplitude_spectrum`).
        """
        if not self.ready():
            return None
        grid = self.stamps[-1] - self.dt_ns * np.arange(self.n - 1, -1, -1, dtype=np.int64)
        if len(self.stamps) == self.n and np.array_equal(grid, self.stamps):
            x = self.values
        else:   # samples were lost: interpolate on the step grid
            t = (self.stamps - grid[0]).astype(float)
            tg = (grid - grid[0]).astype(float)
            x = np.column_stack([np.interp(tg, t, col) for col in self.values.T])
        return amplitude_spectrum(x, self.dt_ns * 1e-9)
