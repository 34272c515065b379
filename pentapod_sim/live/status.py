"""
Run status of the live view, derived from the stamps of the plant's state topics (ROS-free).

The plant publishes no status topic, so the figures come from what every subscriber sees: the
step index k = t_k / dt of the newest state message (dt = the smallest stamp step seen), the
simulated time, the stepping rate over the last status period (steps per wall second) and the
real-time factor. Deadline misses and rejected force messages are counted inside the plant
(its log) and not published: those fields are NaN. ``dropped_by_live_view`` counts messages
the live view itself discarded because its worker fell behind.
"""
from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

#: Joint names of the status message (sensor_msgs/JointState, value in ``position``) and units.
STATUS_FIELDS = (
    ('step', ''),
    ('sim_time', 's'),
    ('steps_per_second', '1/s'),
    ('real_time_factor', ''),
    ('deadline_misses', ''),
    ('rejected_messages', ''),
    ('dropped_by_live_view', ''),
)
STATUS_NAMES = tuple(name for name, _ in STATUS_FIELDS)


def status_index(name: str) -> int:
    """Position of a status figure in the message."""
    return STATUS_NAMES.index(name)


class RunStatus:
    """Step, rate and real-time factor from the stamps of the plant's outputs."""

    def __init__(self) -> None:
        self.reset()

    def reset(self) -> None:
        """Forget the run (a new run starts)."""
        self.newest = -1      # newest stamp [ns]
        self.dt_ns = 0        # smallest positive stamp step [ns]
        self._last = None     # (wall time [s], stamp [ns]) of the previous report

    def add(self, stamps: npt.NDArray[np.int64]) -> None:
        """Take the (deduplicated, increasing) stamps of one state topic."""
        if len(stamps) == 0:
            return
        steps = np.diff(stamps)
        steps = steps[steps > 0]
        if self.newest >= 0 and stamps[0] > self.newest:
            steps = np.append(steps, stamps[0] - self.newest)
        if len(steps):
            smallest = int(steps.min())
            self.dt_ns = smallest if self.dt_ns == 0 else min(self.dt_ns, smallest)
        self.newest = max(self.newest, int(stamps[-1]))

    def step(self) -> float:
        """Step index of the newest stamp (NaN before two stamps were seen)."""
        if self.newest < 0:
            return math.nan
        if self.newest == 0:
            return 0.0
        return float(round(self.newest / self.dt_ns)) if self.dt_ns else math.nan

    def report(self, wall: float, dropped: int) -> npt.NDArray[np.float64]:
        """
        Figures in :data:`STATUS_FIELDS` order at wall time ``wall`` [s].

        The rate and the real-time factor are taken over the time since the previous report.
        """
        rate = factor = math.nan
        if self._last is not None and self.newest >= 0 and wall > self._last[0]:
            elapsed = wall - self._last[0]
            advanced = (self.newest - self._last[1]) * 1e-9
            factor = advanced / elapsed
            if self.dt_ns:
                rate = advanced / (self.dt_ns * 1e-9) / elapsed
        if self.newest >= 0:
            self._last = (wall, self.newest)
        sim_time = self.newest * 1e-9 if self.newest >= 0 else math.nan
        return np.array([self.step(), sim_time, rate, factor, math.nan, math.nan,
                         float(dropped)])
