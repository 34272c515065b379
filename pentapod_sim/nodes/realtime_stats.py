"""Timing statistics of a wall-clock paced run (ROS-free; used by the plant node and bench)."""
from __future__ import annotations

import numpy as np


class LatenessStats:
    """
    Lateness of each step start against its wall-clock target, and missed deadlines.

    Parameters
    ----------
    n_steps : int
        Steps planned.
    dt : float
        Step period [s]; a step later than dt is an overrun.
    """

    def __init__(self, n_steps: int, dt: float):
        self.lateness = np.zeros(n_steps)
        self.misses = np.zeros(n_steps, dtype=np.int64)
        self.dt = dt
        self.elapsed = 0.0

    def add(self, k: int, lateness: float) -> None:
        """Record the lateness [s] of step k."""
        self.lateness[k] = lateness

    def missed(self, k: int, n_sources: int) -> None:
        """Record how many sources missed the deadline of step k."""
        self.misses[k] = n_sources

    def summary(self, n: int, elapsed: float) -> str:
        """Achieved rate, lateness percentiles and overruns over the first n steps."""
        d = self.as_dict(n, elapsed)
        return (f'{d["achieved_rate"]:.1f} Hz achieved of {1 / self.dt:.1f} Hz; lateness '
                f'p50 {d["lateness_p50"] * 1e6:.0f} us, p99 {d["lateness_p99"] * 1e6:.0f} us, '
                f'max {d["lateness_max"] * 1e6:.0f} us; {d["overruns"]} overruns '
                f'(> {self.dt * 1e6:.0f} us), {d["missed_steps"]} steps with a missed deadline '
                f'in {n} steps')

    def as_dict(self, n: int | None = None, elapsed: float | None = None) -> dict:
        """Figures as a dict (rates in Hz, lateness in s)."""
        n = self.lateness.size if n is None else n
        elapsed = self.elapsed if elapsed is None else elapsed
        late = self.lateness[:n]
        pct = np.percentile(late, [50, 90, 99]) if n else np.zeros(3)
        return {'achieved_rate': n / elapsed if elapsed > 0 else 0.0,
                'lateness_p50': float(pct[0]), 'lateness_p90': float(pct[1]),
                'lateness_p99': float(pct[2]),
                'lateness_max': float(late.max()) if n else 0.0,
                'overruns': int(np.count_nonzero(late > self.dt)),
                'missed_steps': int(np.count_nonzero(self.misses[:n])),
                'missed_answers': int(self.misses[:n].sum())}
