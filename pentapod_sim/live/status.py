"""
Run status of the live view: the plant's run-status figures, else its own from the stamps.

The plant publishes /pentapod/run_status (diagnostic_msgs/DiagnosticStatus, keys
:data:`pentapod_sim.interface.RUN_STATUS_KEYS` and ``RUN_PROGRESS_KEYS``) at the start, every
``status_period`` s of a run and at the end. The live view passes its figures through: steps
run, step rate [steps/s], deadline misses and rejected force messages. Until a status message
arrives (a plant that publishes none, or a topic selection without it), the step and the rate
come from what every subscriber sees: the step index k = t_k / dt of the newest state message
(dt = the smallest stamp step seen) and its advance over the last status period; the plant's
counters are then NaN. The simulated time and the real-time factor always come from the
stamps; ``dropped_by_live_view`` counts messages the live view itself lost (its backlog was
full, best-effort delivery skipped them, or they could not be decoded).
"""
from __future__ import annotations

import math
from typing import Mapping

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
#: Run-status keys passed through as numbers: key -> status field.
PLANT_FIGURES = {'step_rate': 'steps_per_second', 'deadline_misses': 'deadline_misses',
                 'rejected_messages': 'rejected_messages'}


def status_index(name: str) -> int:
    """Position of a status figure in the message."""
    return STATUS_NAMES.index(name)


def _number(values: Mapping[str, str], key: str) -> float:
    try:
        return float(values[key])
    except (KeyError, ValueError):    # an older plant, or text that is no number
        return math.nan


def plant_figures(values: Mapping[str, str]) -> dict[str, float]:
    """
    Status fields of one run-status message's key/value pairs (text values).

    ``step`` is the index of the last step run (``steps - 1``, NaN before the first); a key
    the message lacks or whose value is no number gives NaN.
    """
    figures = {field: _number(values, key) for key, field in PLANT_FIGURES.items()}
    steps = _number(values, 'steps')
    figures['step'] = steps - 1 if steps >= 1 else math.nan
    return figures


class RunStatus:
    """Step, rate and counters of the plant's status, or from the stamps of its outputs."""

    def __init__(self) -> None:
        self.plant: dict[str, float] | None = None
        self.reset()

    def reset(self) -> None:
        """Forget the stamps of the run (a new run starts; the plant's status stays)."""
        self.newest = -1      # newest stamp [ns]
        self.dt_ns = 0        # smallest positive stamp step [ns]
        # (wall time [s], stamp [ns]) of the previous report
        self._last: tuple[float, int] | None = None

    def add_plant(self, values: Mapping[str, str]) -> None:
        """Take the key/value pairs of a run-status message of the plant."""
        self.plant = plant_figures(values)

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

        The plant's figures where a run-status message arrived (the step: the newer of its
        step and that of the newest stamp); else the step of the newest stamp and the rate
        over the time since the previous report. The real-time factor is always taken over
        that time.
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
        figures = {'step': self.step(), 'sim_time': sim_time, 'steps_per_second': rate,
                   'real_time_factor': factor, 'deadline_misses': math.nan,
                   'rejected_messages': math.nan, 'dropped_by_live_view': float(dropped)}
        if self.plant is not None:
            figures.update(self.plant, step=float(np.fmax(self.plant['step'], figures['step'])))
        return np.array([figures[name] for name in STATUS_NAMES])
