"""
The ROS side of a plant run's steps, as its timing sees it (``pentapod_sim.sim.timing.Exchange``).

:class:`PlantExchange` binds the plant node's outputs, force inputs and answer poller to the
executor and the trace of one run: publishing y_k, spinning for answers, polling, the graph
check, recording a step and draining the executor afterwards. The timings
(:mod:`pentapod_sim.sim.timing`, :mod:`pentapod_sim.sim.realtime`) hold the rules; this is the
middleware they run on.
"""
from __future__ import annotations

from typing import Callable

import numpy as np

from pentapod_sim.nodes.answer_poll import AnswerPoller
from pentapod_sim.nodes.force_inputs import ForceInputs
from pentapod_sim.nodes.local_bus import Drain
from pentapod_sim.nodes.plant_outputs import PlantOutputs
from pentapod_sim.sim.trace import Trace


class PlantExchange:
    """
    One plant run's exchange over ROS.

    Parameters
    ----------
    outputs, inputs, poller
        The plant node's publishers, force subscriptions and answer poller.
    bus_drain : Drain or None
        A composed plant's drain (:mod:`pentapod_sim.nodes.local_bus`), else None.
    executor
        The executor that spins the plant (and, composed, every node).
    trace : Trace
        The run's record.
    refresh : callable
        The plant's look at its subscribers (outputs and answer polling).
    recheck : callable
        Called with every graph check: the truncation check of models that changed mid-run
        (:meth:`pentapod_sim.nodes.loop_check.TruncationCheck.during_run`).
    """

    def __init__(self, outputs: PlantOutputs, inputs: ForceInputs, poller: AnswerPoller,
                 bus_drain: Drain | None, executor, trace: Trace,
                 refresh: Callable[[], None], recheck: Callable[[], None] = lambda: None):
        self.outputs, self.inputs, self.poller = outputs, inputs, poller
        self.bus_drain, self.executor, self.trace, self.refresh = (bus_drain, executor, trace,
                                                                   refresh)
        self.recheck = recheck

    def publish(self, k: int, y: np.ndarray) -> None:
        """Publish y_k (the subscribers looked up again every REFRESH_PERIOD s)."""
        if self.outputs.due():
            self.refresh()
        self.outputs.publish(k, y)

    def resend(self, k: int, y: np.ndarray) -> None:
        """Publish y_k again after looking up the subscribers."""
        self.refresh()
        self.outputs.publish(k, y)

    def spin(self, timeout: float) -> None:
        """One ``spin_once`` of the executor (answers arrive through the callbacks)."""
        self.executor.spin_once(timeout_sec=timeout)

    def poll(self, k: int) -> None:
        """Poll the force subscriptions for step k's answers, if polling pays now."""
        self.poller.poll(k)

    def gone(self) -> list[str]:
        """
        Sources whose publisher left; the periodic checks of a run.

        RunError for a second writer on a force or output topic
        (:meth:`ForceInputs.gone`), or for a model changed mid-run that the truncation check
        refuses.
        """
        self.recheck()
        return self.inputs.gone()

    def record(self, k: int, y: np.ndarray, u: np.ndarray) -> None:
        """Step k to the trace, the full-rate topic and the display batches."""
        self.outputs.record(k, y, u, self.trace)

    def stepped(self) -> None:
        """Drain the executor if due: a composed plant always, a polling one while it polls."""
        if self.bus_drain is not None:
            self.bus_drain.tick(self.executor)
        else:
            self.poller.tick(self.executor)

    def buffers(self) -> list:
        """The trace's arrays."""
        return self.trace.buffers()
