"""
Min/max envelope downsampling of sampled signals to a display rate (ROS-free).

The time axis is cut into windows of ``period_ns`` of simulated time, ``[j T, (j + 1) T)``.
A window with samples ``s_0 .. s_{n-1}`` at stamps ``t_0 .. t_{n-1}`` becomes two display
samples: the first stamped ``t_0``, the second ``t_{n-1}``. Per column, they carry the window's
minimum and maximum in the order in which they occur (the earlier one first), so a plot through
the display samples draws the band the signal sweeps, and a signal that rises or falls through a
window is drawn through its exact first and last samples. A window of one sample gives one
display sample. NaN columns stay NaN.
"""
from __future__ import annotations

import numpy as np
import numpy.typing as npt

#: One display sample: (stamp [ns], values of the columns).
Sample = tuple[int, npt.NDArray[np.float64]]


def envelope(stamps: npt.NDArray[np.int64], values: npt.NDArray[np.float64]) -> list[Sample]:
    """
    Envelope display samples of one window.

    Parameters
    ----------
    stamps : (n,) int ndarray
        Sample stamps [ns], increasing.
    values : (n, c) float ndarray
        Sample values.

    Returns
    -------
    list of (int, (c,) ndarray)
        One sample if n == 1, else two: (t_0, earlier extreme), (t_{n-1}, later extreme).
    """
    if len(stamps) == 0:
        return []
    if len(stamps) == 1:
        return [(int(stamps[0]), values[0].copy())]
    nan = np.isnan(values)
    low = np.argmin(np.where(nan, np.inf, values), axis=0)
    high = np.argmax(np.where(nan, -np.inf, values), axis=0)
    cols = np.arange(values.shape[1])
    first, last = np.minimum(low, high), np.maximum(low, high)
    return [(int(stamps[0]), values[first, cols]), (int(stamps[-1]), values[last, cols])]


class EnvelopeDownsampler:
    """
    Streaming envelope of one signal: windows are emitted once a later window starts.

    Parameters
    ----------
    period_ns : int
        Window length T [ns of simulated time] (1 / display rate).
    """

    def __init__(self, period_ns: int):
        if period_ns <= 0:
            raise ValueError(f'envelope window must be positive, got {period_ns} ns')
        self.period_ns = int(period_ns)
        self.reset()

    def reset(self) -> None:
        """Forget the open window (a new run starts)."""
        self._stamps = np.zeros(0, dtype=np.int64)
        self._values: npt.NDArray[np.float64] | None = None

    @property
    def pending(self) -> int:
        """Samples of the open window."""
        return len(self._stamps)

    def add(self, stamps: npt.NDArray[np.int64], values: npt.NDArray[np.float64]) -> list[Sample]:
        """
        Take samples (stamps increasing, after any held ones); return completed windows.

        Parameters
        ----------
        stamps : (n,) int ndarray
            Stamps [ns].
        values : (n, c) float ndarray
            Values.
        """
        if len(stamps) == 0:
            return []
        if self._values is not None:
            stamps = np.concatenate([self._stamps, stamps])
            values = np.concatenate([self._values, values])
        window = stamps // self.period_ns
        done = int(np.searchsorted(window, window[-1]))     # samples of closed windows
        out: list[Sample] = []
        if done:
            cuts = np.flatnonzero(np.diff(window[:done])) + 1
            for part in np.split(np.arange(done), cuts):
                out += envelope(stamps[part], values[part])
        self._stamps, self._values = stamps[done:], values[done:]
        return out

    def flush(self) -> list[Sample]:
        """Emit the open window as it is (the stream went quiet); later samples start anew."""
        out = envelope(self._stamps, self._values) if self._values is not None else []
        self.reset()
        return out
