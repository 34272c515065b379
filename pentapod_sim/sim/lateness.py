"""
Timing statistics of a wall-clock paced run: lateness of each step, missed deadlines, reports.

Kept by :class:`pentapod_sim.sim.realtime.RealTime` (the plant node's ``timing: realtime``).
"""
from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt


def fault_in(*arrays: npt.NDArray[Any] | None) -> None:
    """
    Write every page of the arrays (None: skipped) before a paced run.

    numpy asks for transparent huge pages for big arrays; the first write to each 2 MiB of a
    trace during the run then stalled the loop about 5 ms here (page compaction), five missed
    deadlines at 1 kHz every ~900 steps.
    """
    for array in arrays:
        if array is not None:
            array.fill(0)


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
        self.lateness: npt.NDArray[np.float64] = np.zeros(n_steps)
        self.misses: npt.NDArray[np.int64] = np.zeros(n_steps, dtype=np.int64)
        self.dt = dt
        self.elapsed = 0.0
        self._reported: tuple[int, float] | None = None   # (first step, its start) of a report

    def add(self, k: int, lateness: float) -> None:
        """Record the lateness [s] of step k."""
        self.lateness[k] = lateness

    def missed(self, k: int, n_sources: int) -> None:
        """Record how many sources missed the deadline of step k."""
        self.misses[k] = n_sources

    def summary(self, n: int, elapsed: float, first: int = 0) -> str:
        """
        Achieved rate, lateness percentiles and overruns over steps ``first`` to ``n - 1``.

        ``elapsed`` is the wall time of those steps [s]. The periodic report of a run passes
        the steps since the last report: percentiles over every step so far cost about 1 ms
        per 2,000 steps, enough to miss the next deadline at 1 kHz.
        """
        d = self.as_dict(n, elapsed, first)
        return (f'{d["achieved_rate"]:.1f} Hz achieved of {1 / self.dt:.1f} Hz; lateness '
                f'p50 {d["lateness_p50"] * 1e6:.0f} us, p99 {d["lateness_p99"] * 1e6:.0f} us, '
                f'max {d["lateness_max"] * 1e6:.0f} us; {d["overruns"]} overruns '
                f'(> {self.dt * 1e6:.0f} us), {d["missed_steps"]} steps with a missed deadline '
                f'in {n - first} steps')

    def report(self, n: int, now: float, t0: float) -> str:
        """
        :meth:`summary` of the steps since the previous report (from step 1 at first).

        ``now`` is the wall time [s], ``t0`` that of step 0's start (step k starts at
        t0 + k dt).
        """
        first, since = self._reported or (1, t0 + self.dt)
        self._reported = (n, now)
        return self.summary(n, now - since, first)

    def as_dict(self, n: int | None = None, elapsed: float | None = None,
                first: int = 0) -> dict[str, Any]:
        """Figures of steps ``first`` to ``n - 1`` as a dict (rates in Hz, lateness in s)."""
        n = self.lateness.size if n is None else n
        elapsed = self.elapsed if elapsed is None else elapsed
        late = self.lateness[first:n]
        pct = np.percentile(late, [50, 90, 99]) if late.size else np.zeros(3)
        return {'achieved_rate': late.size / elapsed if elapsed > 0 else 0.0,
                'lateness_p50': float(pct[0]), 'lateness_p90': float(pct[1]),
                'lateness_p99': float(pct[2]),
                'lateness_max': float(late.max()) if late.size else 0.0,
                'overruns': int(np.count_nonzero(late > self.dt)),
                'missed_steps': int(np.count_nonzero(self.misses[first:n])),
                'missed_answers': int(self.misses[first:n].sum())}
