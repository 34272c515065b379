"""
Lockstep in separate processes: the plant polls for its sources' answers before it blocks.

After publishing y_k the plant needs the answers u_k of its sources. Blocking in the executor
until they come costs more than the message itself: rclpy's ``spin_once`` and the wake-up of
a thread that slept. Taking the answers straight from the force subscriptions in a loop
(``take_message``, under 1 us when nothing is there) for up to ``answer_poll_time`` seconds
makes plant + 1 damper node about 1.4x faster here. The loop keeps one CPU busy, so it pays
only while every process that works each step has a CPU of its own; with 3 damper nodes, or a
damper and a recorder, on 2 CPUs it made the run slower (docs/nodes.md, "Where a lockstep
step's time goes"). :func:`polling_pays` is that rule; :class:`AnswerPoller` re-applies it
whenever the plant checks its subscribers, so a recorder or ``ros2 topic echo`` joining
mid-run turns polling off.

Answers taken here leave their event in rclpy's EventsExecutor, which then takes nothing
(about 4 us each). While the plant polls, no ``spin_once`` may run for many steps, so the
poller drains the executor every :data:`POLL_DRAIN_PERIOD` s as a composed plant does
(:class:`~pentapod_sim.nodes.local_bus.Drain`): timers (run status), parameter services and
graph events keep flowing. The values are those the executor would have delivered: how the
plant waits never changes a trace.
"""
from __future__ import annotations

import os
import time
from typing import Iterable

from pentapod_sim.nodes.local_bus import Drain

#: Wall time [s] between two drains of the executor while the plant polls (timers such as the
#: run status, parameter services and graph events wait at most this long).
POLL_DRAIN_PERIOD = 0.05


def usable_cpus() -> int:
    """CPUs this process may run on (its affinity mask, else the machine's count)."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:        # not on Linux
        return os.cpu_count() or 1


def polling_pays(poll_time: float, cpus: int, peers: int) -> bool:
    """
    True if the plant should poll: ``poll_time`` > 0 and the plant and ``peers`` fit on ``cpus``.

    ``peers``: the other processes that work every step (those of the sources and of the
    subscribers of the plant's per-step topics).
    """
    return poll_time > 0 and peers + 1 <= cpus


def process_of(info) -> bytes:
    """
    The DDS participant of a graph endpoint (``TopicEndpointInfo``): its process, in ROS 2.

    Every node of an rclpy context shares one participant, and a participant's endpoints share
    the 12-byte prefix of their GUIDs (the first bytes of ``endpoint_gid``).
    """
    return bytes(info.endpoint_gid[:12])


def busy_peers(node, output_topics: Iterable[str], force_topics: Iterable[str]) -> set:
    """
    Processes other than ``node``'s that work each step, as DDS participants (:func:`process_of`).

    Those with a node that subscribes to one of the per-step ``output_topics`` or publishes on
    one of the ``force_topics``. A process counts once however many such nodes and topics it
    has: two controllers spun by one executor share a CPU.
    """
    output_topics = list(output_topics)
    me = (node.get_name(), node.get_namespace())
    infos = [i for t in output_topics for i in node.get_subscriptions_info_by_topic(t)]
    infos += [i for t in force_topics for i in node.get_publishers_info_by_topic(t)]
    mine = {process_of(i) for t in output_topics[:1]
            for i in node.get_publishers_info_by_topic(t)
            if (i.node_name, i.node_namespace) == me}
    return {process_of(i) for i in infos} - mine


class AnswerPoller:
    """
    The plant's polling for answers (lockstep, separate processes).

    Parameters
    ----------
    node : rclpy.node.Node
        The plant node (graph queries, the drain's topic, the log).
    inputs : ForceInputs
        The plant's force subscriptions (:mod:`pentapod_sim.nodes.force_inputs`).
    poll_time : float
        Longest poll per step [s] (parameter ``answer_poll_time``; 0: never).
    """

    def __init__(self, node, inputs, poll_time: float):
        self.node = node
        self.inputs = inputs
        self.poll_time = poll_time
        self.cpus = usable_cpus()
        self.active = False
        self.logging = False     # the lockstep run started: changes are logged from then on
        self.composed = False    # a composed plant drains the executor itself
        self.peers: set = set()
        self.polled = 0          # steps whose answers all came by polling
        self.drain: Drain | None = None

    def in_composition(self) -> None:
        """
        A composed plant: never poll.

        Its in-process sources answer inside its publish, and it drains the executor itself
        (:func:`pentapod_sim.nodes.local_bus.connect`).
        """
        self.composed = True

    def prepare(self) -> None:
        """
        Create the drain (before the run: it must find its own subscription first).

        Until it has, a drain runs one queued event only, and the events of the answers taken
        by polling would bury the timers' (the run status stopped for whole runs so).
        """
        if (self.poll_time > 0 and self.inputs.on_dds() and self.drain is None
                and not self.composed):
            self.drain = Drain(self.node, POLL_DRAIN_PERIOD)

    def start(self, log_changes: bool) -> None:
        """The run starts: from now on log when polling turns on or off (if ``log_changes``)."""
        self.logging = log_changes

    def refresh(self, output_topics: Iterable[str], force_topics: Iterable[str],
                step: int) -> None:
        """Apply :func:`polling_pays` to the graph as it is now (log a change during the run)."""
        if self.poll_time <= 0 or not self.inputs.on_dds():
            self.active = False
            return
        self.prepare()
        was = self.active
        self.peers = busy_peers(self.node, output_topics, force_topics)
        self.active = (polling_pays(self.poll_time, self.cpus, len(self.peers))
                       and self.drain is not None and self.drain.ready())
        if self.logging and self.active != was:
            self.node.get_logger().info(f'from step {step} on, {self.describe()}')

    def describe(self) -> str:
        """One line for the log: polling or not, and why."""
        if self.poll_time <= 0:
            return 'answers: blocking (answer_poll_time = 0)'
        how = 'polled' if self.active else 'blocking'
        if not self.active and polling_pays(self.poll_time, self.cpus, len(self.peers)):
            how += ' until the executor drain is matched'
        return (f'answers: {how} ({len(self.peers)} other process(es) working each step, '
                f'{self.cpus} CPU(s))')

    def poll(self, step: int) -> None:
        """Take step ``step``'s answers from the subscriptions until all are in or time is up."""
        if not self.active:
            return
        end = time.perf_counter() + self.poll_time
        while not self.inputs.take_waiting(step):
            if time.perf_counter() > end:
                return
        self.polled += 1

    def tick(self, executor) -> None:
        """While polling: let the executor run what queued up meanwhile (every drain period)."""
        if self.active and self.drain is not None:
            self.drain.tick(executor)

    def polled_steps(self) -> int:
        """Steps whose answers all came by polling."""
        return self.polled
