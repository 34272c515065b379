"""
The plant node's force inputs: one subscription per source, answers into the force mixer.

Each source answers on /pentapod/forces/<source> (docs/interface.md). An answer's stamp gives
the step it answers; :class:`~pentapod_sim.sim.stepping.ForceMixer` accepts or rejects it
(counted per source and reason, warned about at most once a second; repeated and late
answers are expected and dropped silently). The writer checks live here too
(:mod:`pentapod_sim.nodes.writers`): a message on DDS is taken only while its force topic has one
matched publisher, the one the graph showed before step 0; a second writer stops the run, named
by DDS participant and host (unless ``shared_source_topics``), and a source whose publisher left
is reported to the timing.
"""
from __future__ import annotations

import time
from typing import Iterable

from sensor_msgs.msg import JointState

from pentapod_sim import shutdown
from pentapod_sim.errors import RunError
from pentapod_sim.interface import force_topic, step_of
from pentapod_sim.nodes.common import FORCE_SUB_QOS, spin_until, stamp_to_ns
from pentapod_sim.nodes.local_bus import LocalBus
from pentapod_sim.nodes.writers import WriterCheck

#: Wall time [s] between two warnings about rejected messages of one source and reason.
WARN_PERIOD = 1.0


class ForceInputs:
    """
    The plant's subscriptions to its sources' force topics.

    Parameters
    ----------
    node : rclpy.node.Node
        The plant node (creates the subscriptions, answers the graph queries, logs).
    core : DiscretePlant
        The plant core: the step an answer is for is compared with its step counter.
    mixer : ForceMixer
        Takes the answers.
    exact : bool
        Lockstep (only answers to the current step) or real time (the newest answer to any
        step up to the current one).
    shared_ok : bool
        Accept several publishers on one force topic (parameter ``shared_source_topics``).
    writers : WriterCheck
        The plant's writer check; the force topics are added to it.
    """

    def __init__(self, node, core, mixer, exact: bool, shared_ok: bool, writers: WriterCheck):
        self.node, self.core, self.mixer = node, core, mixer
        self.exact, self.shared_ok, self.writers = exact, shared_ok, writers
        self.sources = list(mixer.sources)
        self.subs = {name: node.create_subscription(
            JointState, force_topic(name), lambda msg, name=name: self.on_wire(name, msg),
            FORCE_SUB_QOS) for name in self.sources}
        for name in self.sources:
            writers.watch(force_topic(name), shared=shared_ok)
        self.last_warn: dict[tuple[str, str], float] = {}

    def on_wire(self, source: str, msg: JointState) -> None:
        """An answer taken from DDS: offered to the mixer only if its writer is the one."""
        if self.writers.message_ok(force_topic(source), self.subs[source]):
            self.on_force(source, msg)
        else:
            self.mixer.rejected[(source, 'foreign')] += 1

    def on_force(self, source: str, msg: JointState) -> None:
        """Offer an answer to the mixer; warn (throttled) about a rejected one."""
        step = step_of(stamp_to_ns(msg.header.stamp), self.core.dt)
        reason = self.mixer.submit(source, msg.name, msg.effort, step, self.core.k,
                                   exact=self.exact)
        if reason is None or reason.startswith(('stale', 'duplicate:')):
            return  # repeated answers to re-published steps, or late ones, are expected
        kind = reason.split(':')[0]
        now = time.monotonic()
        if now - self.last_warn.get((source, kind), -1e9) > WARN_PERIOD:
            self.last_warn[(source, kind)] = now
            self.node.get_logger().warning(
                f'rejected message from source {source!r}: {reason} '
                f'({self.mixer.rejected[(source, kind)]} so far)')

    def topics(self) -> list[str]:
        """The force topics of every source."""
        return [force_topic(s) for s in self.sources]

    def on_dds(self) -> bool:
        """True if some source answers over DDS (not every one in-process)."""
        return bool(self.subs)

    def take_waiting(self, step: int) -> bool:
        """
        Take one queued answer from each source that has not answered ``step``.

        True if none was waiting (every answer to ``step`` is in). Under 1 us per empty
        subscription (:mod:`pentapod_sim.nodes.answer_poll`).
        """
        waiting = self.mixer.missing(step)
        for name in waiting:
            sub = self.subs.get(name)
            if sub is None:
                continue
            with sub.handle:
                taken = sub.handle.take_message(sub.msg_type, sub.raw)
            if taken is not None:
                self.on_wire(name, taken[0])
        return not waiting

    def take_from(self, bus: LocalBus, names: Iterable[str]) -> None:
        """The answers of the in-process sources ``names`` come from ``bus``, not DDS."""
        for name in names:
            sub = self.subs.pop(name, None)
            if sub is None:
                continue
            self.node.destroy_subscription(sub)
            bus.subscribe(force_topic(name), lambda msg, name=name: self.on_force(name, msg))

    def gone(self) -> list[str]:
        """
        Check the writers of every watched topic; return the sources whose publisher left.

        Raises
        ------
        RunError
            A topic with a second writer (a force topic unless ``shared_source_topics``, an
            output topic of the plant), named by participant and host
            (:meth:`pentapod_sim.nodes.writers.WriterCheck.check`).
        """
        present = self.writers.check()
        return [name for name in self.sources if not present.get(force_topic(name))]

    def wait_for_publishers(self, executor, timeout: float) -> None:
        """Wait until every source topic has a publisher (RunError names the missing)."""
        def missing() -> list[str]:
            return [s for s in self.sources
                    if self.node.count_publishers(force_topic(s)) == 0]
        if not spin_until(executor, lambda: not missing() or shutdown.requested(), timeout):
            raise RunError(f'force source(s) {", ".join(missing())} did not appear within '
                           f'startup_timeout = {timeout} s')
        self.gone()
