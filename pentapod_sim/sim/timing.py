"""
How a plant run steps against its force sources: one object per timing, one small interface.

Every step k the plant publishes its outputs y_k, takes in the answers u_k of its sources (the
:class:`~pentapod_sim.sim.stepping.ForceMixer` collects them), applies their sum over
[t_k, t_k+1) and advances. *When it stops waiting* is the timing (plant parameter ``timing``):

* :class:`Lockstep` waits for every source's answer to step k: deterministic, a run equals the
  offline loop bit for bit; a silent source, or one whose publisher left, ends the run with a
  RunError naming it;
* :class:`pentapod_sim.sim.realtime.RealTime` paces the steps by the wall clock and holds the
  last force of a source that missed its deadline (its catch-up rules are documented there).

Both implement :class:`Timing` and see the middleware only through an :class:`Exchange`
(publish y_k, spin for answers, poll, check the graph, record the step) and the clock and stop
test they are given, so they run without ROS: test/test_timing.py steps them with a fake clock
and a scripted exchange. The plant node implements the exchange over its publishers,
subscriptions and executor (:mod:`pentapod_sim.nodes.plant_exchange`). Each timing owns its
counters (deadline misses, lost sources, lateness) and reports them through its methods.
"""
from __future__ import annotations

from dataclasses import dataclass
import math
import time
from typing import Any, Callable, Protocol, Sequence

import numpy as np
import numpy.typing as npt

from pentapod_sim import shutdown
from pentapod_sim.errors import RunError
from pentapod_sim.interface import force_topic
from pentapod_sim.sim.stepping import DiscretePlant, ForceMixer

#: Wall time [s] between two checks of the force topics' publishers during a run.
GRAPH_CHECK_PERIOD = 0.25
#: Queued events a lockstep plant runs, without waiting, before it calls a source silent.
DRAIN_EVENTS = 64

FloatArray = npt.NDArray[np.float64]
#: A monotonic clock [s] (``time.monotonic`` in a node, a fake one in the tests).
Clock = Callable[[], float]


class Exchange(Protocol):
    """What a timing needs from the plant node for one run: the middleware side of a step."""

    def publish(self, k: int, y: FloatArray) -> None:
        """Publish y_k (stamp t_k) on the plant's per-step topics."""

    def resend(self, k: int, y: FloatArray) -> None:
        """Publish y_k again, subscribers looked up anew (for sources that have not answered)."""

    def spin(self, timeout: float) -> None:
        """Run what comes in within ``timeout`` s (answers reach the mixer); 0: what is queued."""

    def poll(self, k: int) -> None:
        """Take step k's answers straight from the subscriptions where that pays (or nothing)."""

    def gone(self) -> list[str]:
        """The sources whose publisher left the graph (RunError for a shared force topic)."""

    def record(self, k: int, y: FloatArray, u: FloatArray) -> None:
        """Keep step k: trace, full-rate outputs, display batches."""

    def stepped(self) -> None:
        """After a step: let the executor run what queued up meanwhile, when that is due."""

    def buffers(self) -> Sequence[npt.NDArray[Any] | None]:
        """The arrays the run writes step by step (a paced run writes each page before step 0)."""


class Timing(Protocol):
    """A plant run's timing: runs the steps, owns and reports its counters."""

    def run(self, exchange: Exchange) -> None:
        """Run from the core's current step to the last planned one, or until a stop request."""

    def deadline_misses(self) -> int:
        """Answers that missed their deadline so far (the run status)."""

    def figures(self) -> dict[str, Any]:
        """The run's timing figures for the trace file (after :meth:`run`)."""

    def summary(self) -> str | None:
        """A last log line about the timing (after :meth:`run`), or None."""


@dataclass(frozen=True)
class Waits:
    """How long a lockstep step waits for its answers (plant parameters, all in s)."""

    startup_timeout: float       # step 0 (the sources may still be starting)
    source_timeout: float        # every later step
    resend_period: float         # y_k is published again after this long without all answers


def unanswered(mixer: ForceMixer, k: int, t: float, waited: float, waits: Waits) -> str:
    """
    Why step k got no accepted answer from some sources within the wait: rejected or silent.

    A source whose last message answered step k and was rejected (above ``max_effort``, not
    its ports, NaN, ...) is named as *rejected* with the reason; the others as *silent*.
    """
    missing = mixer.missing(k)
    rejected = mixer.rejected_at(k, missing)
    silent = [s for s in missing if s not in rejected]
    parts = [f'force source(s) {", ".join(silent)} silent'] if silent else []
    parts += [f'force source {s} rejected (every answer to the step refused; last: {why})'
              for s, why in rejected.items()]
    return (f'{"; ".join(parts)} for {waited:.3g} s at step {k} (t = {t:.6g} s); '
            f'source_timeout = {waits.source_timeout} s')


def apply_answers(core: DiscretePlant, mixer: ForceMixer, exchange: Exchange, k: int,
                  y: FloatArray) -> None:
    """Step k's end, the same in every timing: u_k = the held forces' sum; record; advance."""
    u = mixer.total()
    exchange.record(k, y, u)
    core.advance(u)
    exchange.stepped()


class Lockstep:
    """
    Each step: publish y_k, wait for every source's u_k, advance (timing ``lockstep``).

    A source that has not answered within ``resend_period`` gets y_k again; one silent for
    ``source_timeout`` (``startup_timeout`` at step 0) ends the run with a RunError naming it,
    as does one whose publisher left the graph. The graph is also checked every
    :data:`GRAPH_CHECK_PERIOD` s of wall time, so a second publisher on a force topic that
    appears mid-run ends it (:meth:`Exchange.gone` raises).

    Parameters
    ----------
    core : DiscretePlant
        The plant core (a MultiRatePlant too); its step counter is the run's.
    mixer : ForceMixer
        Collects the answers the exchange delivers.
    n_steps : int
        Last step + 1.
    waits : Waits
        The waiting limits.
    clock, stopped : callable
        The monotonic clock [s] and the stop test (:func:`pentapod_sim.shutdown.requested`).
    """

    def __init__(self, core: DiscretePlant, mixer: ForceMixer, n_steps: int, waits: Waits,
                 clock: Clock = time.monotonic,
                 stopped: Callable[[], bool] = shutdown.requested):
        self.core, self.mixer, self.n_steps, self.waits = core, mixer, n_steps, waits
        self.clock, self.stopped = clock, stopped
        self._next_check = -math.inf

    def run(self, exchange: Exchange) -> None:
        """Run the steps in lockstep until ``n_steps`` or a stop request."""
        self._next_check = self.clock() + GRAPH_CHECK_PERIOD
        while self.core.k < self.n_steps and not self.stopped():
            if not self.step(exchange):
                return

    def step(self, exchange: Exchange) -> bool:
        """Step k = ``core.k``; False if a stop request came while it waited (not advanced)."""
        core, mixer, waits = self.core, self.mixer, self.waits
        k = core.k
        y = core.outputs()
        exchange.publish(k, y)
        start = last_sent = self.clock()
        if start > self._next_check:
            exchange.gone()
            self._next_check = start + GRAPH_CHECK_PERIOD
        limit = waits.startup_timeout if k == 0 else waits.source_timeout
        if k > 0:
            exchange.poll(k)
        while mixer.missing(k):
            exchange.spin(waits.resend_period / 4)
            if self.stopped():
                return False
            now = self.clock()
            if now - start > limit and self._drained(exchange, k):
                # a plant frozen (SIGSTOP) and continued with a stop signal, as the scenario
                # runner stops a stalled plant, stops on the request: it does not call its
                # sources silent for the time it was frozen
                shutdown.deliver()
                if self.stopped():
                    return False
                raise RunError(unanswered(mixer, k, core.time, now - start, waits))
            if now - last_sent > waits.resend_period:
                gone = [s for s in exchange.gone() if s in mixer.missing(k)]
                if gone:
                    raise RunError(f'force source(s) {", ".join(gone)} left the ROS graph (no '
                                   f'publisher on {force_topic(gone[0])}) at step {k} '
                                   f'(t = {core.time:.6g} s)')
                exchange.resend(k, y)
                last_sent = now
        apply_answers(core, mixer, exchange, k, y)
        return True

    def _drained(self, exchange: Exchange, k: int) -> bool:
        """
        True if step k still misses answers once what is queued has run.

        A wait that ended late because the plant had no CPU (a loaded machine, a debugger) may
        have queued answers that came in time; they count, at most :data:`DRAIN_EVENTS` events.
        """
        for _ in range(DRAIN_EVENTS):
            if not self.mixer.missing(k):
                return False
            exchange.spin(0.0)
        return bool(self.mixer.missing(k))

    def deadline_misses(self) -> int:
        """None: lockstep has no deadline."""
        return 0

    def figures(self) -> dict[str, Any]:
        """Nothing beyond the plant's own figures."""
        return {}

    def summary(self) -> str | None:
        """Nothing to add."""
        return None
