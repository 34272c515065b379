"""
Actuator demand and the run's faults, from the bags.

**Demand** (multisine runs, over the averaged periods: steady state): per port the controller
answers, the RMS and the peak of its effort per newton of excitation (RMS over RMS, peak over
peak of the TCP force along the excited direction), the mean power it absorbs ``-mean(u v)``
with ``v`` the collocated velocity, per squared newton of RMS excitation [W/N^2], the share of
the steps at which ``|u|`` reaches the force limit at the multisine's amplitude, and, for a
proof-mass actuator (``/pentapod/pma/state``), its peak stroke per newton of peak excitation.

**Faults** (every run of a controller): from the plant's last run status the end state, the
steps run and the answers it rejected; from the recorder's report the messages missing; from
the recorded steps the repeats (a step the plant had to publish again because an answer was
late, and answers sent again for it) and the steps absent between the first and the last.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np
import numpy.typing as npt

from pentapod_damper.judge.robustness import answered_ports
from pentapod_sim.analysis.bag.excitation_record import excitation_of
from pentapod_sim.analysis.bag.reader import Bag, open_bag
from pentapod_sim.analysis.bag.run_record import recording_report, run_statuses, step_answers
from pentapod_sim.errors import BagError
from pentapod_sim.interface import EXCITATION, force_topic, PMA_STATE, port_location, TCP_STATE
from pentapod_sim.plant.ports import collocated_output
from pentapod_sim.sim.excitation import Excitation


@dataclass(frozen=True)
class PortDemand:
    """What one port asked of its actuator in one multisine run."""

    direction: str
    port: str
    force_rms_per_n: float          # [N/N] or [N m/N]
    force_peak_per_n: float
    power_per_n2: float             # [W/N^2]; NaN without the collocated velocity
    share_at_limit: float           # [-]
    stroke_per_n: float             # [m/N]; NaN if the port is no PMA


def _window(bag: Bag, spec: str, first: int, end: int, dt: float) -> npt.NDArray[np.float64]:
    series = bag.series(spec)
    steps = np.rint(series.time_ns / (dt * 1e9)).astype(np.int64)
    values = np.full(end - first, np.nan)
    inside = (steps >= first) & (steps < end)
    values[steps[inside] - first] = np.asarray(series.values, dtype=float)[inside]
    return values


def demand(bag_path: Path, direction: str, sources: Sequence[str],
           force_limit: float) -> list[PortDemand]:
    """Demand per port of one multisine run (module docstring)."""
    found = excitation_of(bag_path)
    if found is None:
        raise BagError(f'{bag_path} holds no excitation record')
    spec, dt = found
    exc = Excitation(spec, dt)
    period = int(exc.period_steps or 0)
    first = exc.first + exc.settle_periods * period
    end = exc.first + int(round(spec.duration / dt))
    bag = open_bag(bag_path)
    weights = np.asarray(exc.direction, dtype=float)
    force = sum(w * _window(bag, f'{EXCITATION}.force.{a}', first, end, dt)
                for w, a in zip(weights, 'xyz'))
    f_rms = float(np.sqrt(np.nanmean(force ** 2)))
    f_peak = float(np.nanmax(np.abs(force)))
    out = []
    for port in answered_ports(bag, sources):
        u = np.zeros(end - first)
        for source in sources:
            try:
                u = u + _window(bag, f'{force_topic(source)}.effort.{port}', first, end, dt)
            except BagError:
                continue
        power = stroke = float('nan')
        topic, joint, what = port_location(collocated_output(port))
        if topic in bag.topics:
            v = _window(bag, f'{topic}.{what}.{joint}', first, end, dt)
            power = float(-np.nanmean(u * v) / f_rms ** 2)
        axis = port.rsplit('_', 1)[-1]
        if port.startswith('pma_force_') and PMA_STATE in bag.topics:
            x = _window(bag, f'{PMA_STATE}.position.pma_{axis}', first, end, dt)
            stroke = float(np.nanmax(np.abs(x - np.nanmean(x))) / f_peak)
        out.append(PortDemand(direction, port, float(np.sqrt(np.nanmean(u ** 2)) / f_rms),
                              float(np.nanmax(np.abs(u)) / f_peak), power,
                              float(np.nanmean(np.abs(u) >= force_limit)), stroke))
    return out


@dataclass(frozen=True)
class RunFaults:
    """How one run ended and what it lost."""

    run: str
    state: str
    steps: int
    planned: int
    rejected: int
    missing: int
    late_steps: int           # steps the plant published again (an answer was late)
    repeated_answers: int     # answers recorded twice for a step
    absent_answers: int       # steps without an answer between the first and the last
    error: str = ''           # why the run ended early ('' if it did not)


#: Rejections that are no fault: copies of an answer to a step the plant published again.
EXPECTED = ('stale', 'duplicate')


def _refused(status: dict[str, str]) -> int:
    """Answers the plant refused, less the expected copies (older bags: every rejection)."""
    by_reason = status.get('rejected_by_reason')
    if by_reason is None:
        return int(status.get('rejected_messages', 0) or 0)
    total = 0
    for item in filter(None, by_reason.split(',')):
        what, count = item.rsplit('=', 1)
        if what.rsplit('/', 1)[-1] not in EXPECTED:
            total += int(count)
    return total


def faults(bag_path: Path, run: str, planned: int, sources: Sequence[str],
           dt: float) -> RunFaults:
    """The faults one run's bag shows (module docstring)."""
    bag = open_bag(bag_path)
    statuses = run_statuses(bag)
    last = statuses[-1] if statuses else {}
    report = recording_report(bag)
    state = last.get('state', 'no run status')
    steps = int(last.get('steps', 0) or 0)
    rejected = _refused(last)
    missing = sum(report['missing'].values())
    state_steps = step_answers(bag, TCP_STATE, dt)
    repeated = absent = 0
    for source in sources:
        answers = step_answers(bag, force_topic(source), dt)
        repeated += answers.repeats
        absent += max(0, steps - answers.unique_steps)
    return RunFaults(run, state, steps, planned, rejected, missing, state_steps.repeats,
                     repeated, absent)
