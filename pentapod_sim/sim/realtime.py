"""
The plant's real-time timing (``timing: realtime``): steps paced by the wall clock.

The lockstep contract is kept whenever an answer comes in time; a missed deadline holds the
source's last force and is counted (:class:`~pentapod_sim.sim.lateness.LatenessStats`). One of
the two timings of :mod:`pentapod_sim.sim.timing`; docs/interface.md, "Timing ``realtime``".
"""
from __future__ import annotations

import math
import time
from typing import Any, Callable, Protocol, Sequence

import numpy.typing as npt

from pentapod_sim import shutdown
from pentapod_sim.sim.lateness import fault_in, LatenessStats
from pentapod_sim.sim.stepping import DiscretePlant, ForceMixer
from pentapod_sim.sim.timing import (
    apply_answers,
    Clock,
    Exchange,
    GRAPH_CHECK_PERIOD,
    Lockstep,
    Waits,
)

#: A step that began late waits for its answers until this many periods after it began. A
#: plant that stalled (the machine took its CPU for a few ms) starts its next steps late and
#: catches up; with the period's end as the only deadline, every catch-up step counted as
#: missed by its sources, which had no time to answer, and ran on held forces (1 kHz
#: exchange, separate processes: about half the misses of a run, 13 in a row after an 11 ms
#: stall). A late step then gains about half a period on the clock. Only while the sources
#: answer most steps that began on time: where they cannot keep up anyway (5 kHz in separate
#: processes, a round trip longer than the period) the wait only kept the plant behind the
#: clock (4,929 of 5,000 steps/s, lateness p50 11 ms).
ANSWER_WINDOW = 0.5
#: The plant sleeps in its executor until this long before a period starts, then polls the
#: clock [s]: the executor's wake-up comes late by tens of microseconds (bench/bench_plant.py
#: rows ``realtime 1 kHz exchange, ...``).
POLL_AHEAD = 150e-6
#: The share of answered steps (among those begun on time) below which a late step gets no
#: answer window, and the weight of each new step in that running share (about the last 10).
KEEPING_UP, SHARE_WEIGHT = 0.5, 0.1


class Log(Protocol):
    """The logger a timing reports to (a ROS node's or a Python ``logging.Logger``)."""

    def info(self, message: str) -> Any:
        """Log at INFO."""

    def warning(self, message: str) -> Any:
        """Log at WARNING."""


class RealTime:
    """
    Wall-clock periods with the lockstep contract kept whenever an answer is in time.

    Step 0 waits for every source as in lockstep (discovery). Period k then starts at
    ``t0 + k dt``: the plant publishes y_k and takes in answers until every source answered
    step k or the deadline passes: the period's end, or :data:`ANSWER_WINDOW` periods after the
    step began if that is later and the sources answered most of the last steps that began on
    time (a plant that fell behind the clock catches up without taking the sources' time to
    answer). Answers that arrived while the plant itself had no CPU inside that wait (it woke
    past the deadline) are taken before a miss is counted. In time, u_k answers y_k exactly as
    in lockstep, so a run without misses equals the lockstep run bit for bit. A source that
    missed the deadline keeps its last force for step k and the miss is counted; a source
    whose publisher left the graph gets ``lost_policy`` (``zero`` or ``hold``) with a warning
    and is no longer counted as missing.

    Parameters
    ----------
    core, mixer, n_steps, waits, clock, stopped
        As :class:`~pentapod_sim.sim.timing.Lockstep` (``waits`` serve step 0).
    report_period : float
        Wall time [s] between two log lines of the timing figures.
    lost_policy : str
        ``zero`` or ``hold``: the force of a source whose publisher left.
    log : Log
        Where the reports and warnings go.
    """

    def __init__(self, core: DiscretePlant, mixer: ForceMixer, n_steps: int, waits: Waits, *,
                 report_period: float, lost_policy: str, log: Log,
                 clock: Clock = time.monotonic,
                 stopped: Callable[[], bool] = shutdown.requested):
        self.core, self.mixer, self.n_steps = core, mixer, n_steps
        self.report_period, self.lost_policy, self.log = report_period, lost_policy, log
        self.clock, self.stopped = clock, stopped
        self.stats = LatenessStats(n_steps, core.dt)
        self.misses = dict.fromkeys(mixer.sources, 0)     # source -> deadlines missed
        self.lost: set[str] = set()                       # sources whose publisher left
        self._answered = 1.0         # share of answered steps among the last begun on time
        self._first = Lockstep(core, mixer, 1, waits, clock, stopped)
        self._t0 = 0.0
        self._next_check = self._next_report = math.inf
        self._prepared = False

    def prepare(self, buffers: Sequence[npt.NDArray[Any] | None]) -> None:
        """
        Write every page of ``buffers`` and of the lateness record (:func:`fault_in`), once.

        Seconds for a long run: the plant does it before it announces its run, so that its
        sources do not take that time for a stalled plant (``plant_stall_timeout``).
        """
        if not self._prepared:
            fault_in(*buffers, self.stats.lateness, self.stats.misses)
            self._prepared = True

    def run(self, exchange: Exchange) -> None:
        """Step 0 in lockstep, then the paced steps until ``n_steps`` or a stop request."""
        self.prepare(exchange.buffers())          # before step 0
        self._first.run(exchange)
        self._t0 = t0 = self.clock() - self.core.dt
        self._next_report = t0 + self.report_period
        self._next_check = t0 + GRAPH_CHECK_PERIOD
        while self.core.k < self.n_steps and not self.stopped():
            self.step(exchange)
        self.stats.elapsed = self.clock() - t0

    def step(self, exchange: Exchange) -> None:
        """Paced step k = ``core.k`` (k >= 1): wait for its period, exchange, advance."""
        core, mixer, dt, clock = self.core, self.mixer, self.core.dt, self.clock
        k = core.k
        start = self._t0 + k * dt
        now = clock()
        while now < start:   # sleep in the executor, poll the clock for the last POLL_AHEAD
            if start - now > POLL_AHEAD:
                exchange.spin(start - POLL_AHEAD - now)
            now = clock()
        self.stats.add(k, now - start)
        began = now
        y = core.outputs()
        exchange.publish(k, y)
        on_time = began + ANSWER_WINDOW * dt <= start + dt
        # a late step still gives the sources time if they mostly answer steps begun on time
        deadline = (start + dt if on_time or self._answered < KEEPING_UP
                    else began + ANSWER_WINDOW * dt)
        while mixer.missing(k) and now < deadline:
            exchange.spin(deadline - now)
            now = clock()
        # answers that arrived while the plant itself had no CPU (stopped inside this wait, so
        # it woke past the deadline) came in time: take them before counting a miss
        for _ in mixer.missing(k):
            exchange.spin(0.0)
        late = [s for s in mixer.missing(k) if s not in self.lost]
        if on_time:
            self._answered += SHARE_WEIGHT * ((not late) - self._answered)
        for source in late:
            self.misses[source] += 1
        self.stats.missed(k, len(late))
        apply_answers(core, mixer, exchange, k, y)
        if now > self._next_check:
            self._watch_lost(exchange)
            self._next_check = now + GRAPH_CHECK_PERIOD
        if now > self._next_report:
            self.log.info('realtime, last period: ' + self.stats.report(k + 1, now, self._t0))
            self._next_report = now + self.report_period

    def _watch_lost(self, exchange: Exchange) -> None:
        """Apply ``lost_policy`` to sources whose publisher left, warn once per source."""
        for source in exchange.gone():
            if source in self.lost:
                continue
            self.lost.add(source)
            if self.lost_policy == 'zero':
                self.mixer.drop(source)
            self.log.warning(
                f'force source {source!r} left the ROS graph at step {self.core.k}; its force '
                f'is {"set to zero" if self.lost_policy == "zero" else "held"} '
                '(lost_source_policy)')

    def deadline_misses(self) -> int:
        """Answers that missed their deadline so far, over every source."""
        return sum(self.misses.values())

    def figures(self) -> dict[str, Any]:
        """Rate, lateness percentiles, overruns, misses (per source and per step) of the run."""
        n = self.core.k
        return dict(self.stats.as_dict(n), misses_per_source=str(self.misses),
                    missed_per_step=self.stats.misses[:n],
                    lateness_per_step=self.stats.lateness[:n])

    def summary(self) -> str | None:
        """The final figures as one log line."""
        return 'realtime final: ' + self.stats.summary(self.core.k, self.stats.elapsed)
