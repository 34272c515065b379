"""
The plant's run status on /pentapod/run_status: at the start, periodically, at the end.

Each message (diagnostic_msgs/DiagnosticStatus, reliable, transient local) carries the keys
:data:`pentapod_sim.interface.RUN_STATUS_KEYS` and :data:`pentapod_sim.interface.RUN_PROGRESS_KEYS`
as text values; ``message`` is the state. During a run a timer on the steady clock publishes a
``running`` message every ``status_period`` s of wall time; it fires inside the plant's
``spin_once`` calls, so it never interrupts a step. See docs/recording.md. The force sources
watch it (:class:`PlantRunWatch`): stopped after the plant's run ended, they say so and exit 0.
"""
from __future__ import annotations

import time
from typing import Callable

from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
from rclpy.clock import Clock, ClockType

from pentapod_sim import interface, shutdown
from pentapod_sim.interface import stamp_ns
from pentapod_sim.nodes.common import qos


def status_values(state: str, steps: int, dt: float, step_topics: list[str],
                  step_rate: float, deadline_misses: int, rejected: int,
                  by_reason: str = '', initial_state: str = 'rest',
                  drives: str = 'none') -> dict[str, str]:
    """Key/value pairs of one run-status message (units: dt [s], step_rate [steps/s])."""
    values = {'state': state, 'steps': steps, 'dt': repr(dt),
              'last_stamp_ns': stamp_ns(steps - 1, dt) if steps else -1,
              'step_topics': ','.join(step_topics), 'step_rate': f'{step_rate:.6g}',
              'deadline_misses': deadline_misses, 'rejected_messages': rejected,
              'rejected_by_reason': by_reason, 'initial_state': initial_state,
              'drives': drives}
    return {k: str(v) for k, v in values.items()}


class RunStatusPublisher:
    """
    The run-status publisher of a plant node and its periodic timer.

    Parameters
    ----------
    node : rclpy.node.Node
        The plant node (creates the publisher and the timer; its name goes into each message).
    dt : float
        The plant's step [s].
    period : float
        Wall time between two ``running`` messages [s] (parameter ``status_period``).
    tick : callable
        Called by the timer; publishes a ``running`` message (:meth:`publish`).
    initial_state : str
        Where the run started: ``rest``, or ``file <path>`` (parameter ``initial_state_file``).
    drives : str
        The feed drives the plant steps: ``none``, or ``<file> on struts [...]``.
    """

    def __init__(self, node, dt: float, period: float, tick: Callable[[], None],
                 initial_state: str = 'rest', drives: str = 'none'):
        self.dt = dt
        self.initial_state, self.drives = initial_state, drives
        self.name = node.get_fully_qualified_name()
        self.pub = node.create_publisher(DiagnosticStatus, interface.RUN_STATUS, qos('status'))
        self.timer = node.create_timer(period, tick,
                                       clock=Clock(clock_type=ClockType.STEADY_TIME))
        self.timer.cancel()                # started by start()
        self.last = (time.monotonic(), 0)  # (wall time, steps) of the last message

    def start(self, steps: int) -> None:
        """Publish ``running`` every period from now on (``steps``: run so far)."""
        self.last = (time.monotonic(), steps)
        self.timer.reset()

    def stop(self) -> None:
        """No more periodic messages."""
        self.timer.cancel()

    def publishers(self) -> list:
        """The status publisher (the plant waits for its acknowledgements at the end)."""
        return [self.pub]

    def publish(self, state: str, steps: int, step_topics: list[str], deadline_misses: int,
                rejected: int, by_reason: str = '') -> None:
        """Publish one status message: ``state`` after ``steps`` steps (docs/recording.md)."""
        now = time.monotonic()
        last_time, last_steps = self.last
        rate = (steps - last_steps) / (now - last_time) if now > last_time else 0.0
        self.last = (now, steps)
        values = status_values(state, steps, self.dt, step_topics, rate, deadline_misses,
                               rejected, by_reason, self.initial_state, self.drives)
        level = DiagnosticStatus.WARN if state == interface.RUN_STOPPED else DiagnosticStatus.OK
        self.pub.publish(DiagnosticStatus(
            level=level, name=self.name, message=state,
            values=[KeyValue(key=k, value=v) for k, v in values.items()]))


class PlantRunWatch:
    """
    A source's view of the plant's run status: whether the run ended before a stop signal.

    The scenario runner and the launch file stop the sources once the plant has ended. A
    source that saw the plant announce the end of its run (``finished`` or ``stopped``)
    before its stop signal came was stopped because it was no longer needed: it says so and
    exits 0 (:func:`pentapod_sim.nodes.common.run_node` asks the node's
    ``stopped_after_run_end``), instead of ending with ``stopped by SIGINT`` and 130 like a
    run cut short. A status that arrives after the signal explains nothing (a plant stopped by
    the same Ctrl-C announces ``stopped`` too), and a new run (``running``) clears the end.

    Parameters
    ----------
    node : rclpy.node.Node
        The source node (creates the subscription; its logger says why it stopped).
    """

    def __init__(self, node):
        self.log = node.get_logger()
        self.ended: str | None = None       # the end state the plant announced
        self.running = False                # the plant announced a run (and no end since)
        self.sub = node.create_subscription(DiagnosticStatus, interface.RUN_STATUS,
                                            self.on_status, qos('status'))

    def on_status(self, msg: DiagnosticStatus) -> None:
        """Note the end of the plant's run (or a new run) announced before any stop signal."""
        if shutdown.requested():
            return
        if msg.message in (interface.RUN_FINISHED, interface.RUN_STOPPED):
            self.ended = msg.message
        elif msg.message == interface.RUN_RUNNING:
            self.ended = None
        self.running = msg.message == interface.RUN_RUNNING

    def explains_stop(self) -> bool:
        """After a stop signal: True, and logged, if the plant's run had ended before it."""
        if self.ended is None:
            return False
        self.log.info(f"the plant's run ended ({self.ended}); stopped")
        return True
