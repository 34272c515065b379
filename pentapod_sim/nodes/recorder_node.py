"""
Recorder node: writes chosen topics (default every /pentapod/* topic and /clock) to a bag.

Subscriptions are raw (CDR bytes, no deserialisation) and reliable with a deep queue unless a
publisher only offers best effort; the ROS-free :class:`pentapod_sim.recording.BagWriter` writes
the bag. A message's log time is its header stamp (sim time) when its type starts with a
std_msgs/Header or a builtin Time (Clock), else the receive time of the node clock. With
``stop_at_run_end`` the recorder closes the bag once the plant announced the end of the run
(:data:`pentapod_sim.interface.RUN_STATUS`) and every per-step topic holds the last step, or
after the announcement once no step message came for ``drain_timeout`` s; it logs unique vs
expected steps per topic and stores them in the bag (:mod:`pentapod_sim.recording.run_end`,
docs/recording.md); missing steps, a conflicting copy of a step or a second writer on a recorded
topic (:mod:`pentapod_sim.nodes.writers`) fail the recording: exit code 3 after the bag is
closed. SIGINT/SIGTERM close the bag completely; after a SIGKILL it is readable up to the last
flush. Where the plant started (status ``initial_state``) goes into the metadata. It publishes
nothing.

In a composed run the recorder takes the plant's and the in-process sources' per-step topics
from the composition's bus as message objects (:meth:`RecorderNode.take_from_bus`,
:mod:`pentapod_sim.nodes.local_bus`) and serialises them to the bytes DDS delivers
(:mod:`pentapod_sim.nodes.wire_cdr`), written as the DDS messages are (same channels, log
times, duplicate skipping, counts); its DDS subscriptions of those topics record nothing.

Which topics it subscribes to, at which QoS and when:
:mod:`pentapod_sim.nodes.recorder_subscriptions`.
Parameters: :class:`pentapod_sim.nodes.parameter_tables.RecorderParams` (docs/parameters.md).
"""
import datetime
import importlib
from pathlib import Path
import struct
import time

import rclpy
from rclpy.clock import Clock, ClockType
from rclpy.executors import SingleThreadedExecutor
from rclpy.serialization import deserialize_message
import yaml

from pentapod_sim import interface, shutdown
from pentapod_sim.errors import BagError, ConfigError, RecordingError
from pentapod_sim.nodes.common import run_node
from pentapod_sim.nodes.parameter_tables import RecorderParams
from pentapod_sim.nodes.recorder_qos import LATE_JOINER, offered_qos
from pentapod_sim.nodes.recorder_subscriptions import Subscriptions
from pentapod_sim.nodes.testbed_node import TestbedNode
from pentapod_sim.nodes.wire_cdr import serializer, type_name
from pentapod_sim.nodes.writers import WriterCheck, writers_text
from pentapod_sim.recording import BagWriter, run_end
from pentapod_sim.recording.msgdefs import has_header_stamp
from pentapod_sim.recording.run_end import failures, report_record, RunStatus, StepLedger

#: A recorder stops waiting for topics whose publishers all left once it took no message for
#: this long [s]: what their publishers sent before leaving is taken first.
ORPHAN_QUIET = 0.5
#: After the end of the run a recorder waits up to this long [s, wall time] for the message of
#: each latched topic it found with a publisher (an exciter's signal, a controller's model):
#: one discovered only at the end of a short run is subscribed then, and its writer's kept
#: message takes a moment to arrive.
LATCHED_WAIT = 2.0
#: Wall time [s] a recorder of a stopped run keeps looking for a foreign writer at its end.
FOREIGN_WAIT = 2.0
#: Name of the MCAP metadata record (and custom_data key) with expected vs recorded counts.
RECORDING_RECORD = 'pentapod_recording'

# topics of docs/architecture.md: subscribed at start (before any publisher exists), so that a
# recorder started before the plant misses no step; others are found by discovery
KNOWN_TOPICS = {t: interface.TOPIC_TYPES[t] for t in (
    interface.CLOCK, interface.TCP_STATE, interface.STRUT_STATES, interface.PMA_MOUNT_STATE,
    interface.TCP_STATE_FULLRATE, interface.EXCITATION, interface.PMA_STATE,
    interface.CUTTING_STATE)}
KNOWN_TOPICS[interface.RUN_STATUS] = interface.DIAGNOSTIC_STATUS


def message_class(msg_type: str):
    """Import the rclpy message class of ``pkg/msg/Type``."""
    pkg, _, name = msg_type.split('/')
    return getattr(importlib.import_module(f'{pkg}.msg'), name)


class RecorderNode(TestbedNode):
    """Record topics to a rosbag2-compatible MCAP bag."""

    Params = RecorderParams

    def __init__(self, **kwargs):
        super().__init__('recorder', **kwargs)
        params = self.params
        self.duplicates = {}
        self.wanted = params.topics
        utc = datetime.datetime.now(datetime.timezone.utc).strftime('%Y%m%dT%H%M%SZ')
        name = (params.bag_name or 'run-{utc}').replace('{utc}', utc)
        self.ledger = StepLedger(self._selected)
        self.end = None           # RunStatus once the plant announced the end of the run
        self.end_seen = None      # monotonic time of that announcement
        self.report = None        # expected vs unique counts, set by close()
        self.failed: list[str] = []    # why the recording is not trustworthy (store_report)
        # one writer per recorded per-step topic (pentapod_sim.nodes.writers): a second one is
        # named at once and fails the recording; it is still recorded (the evidence)
        self.writers = WriterCheck(self)
        self.foreign: dict[str, str] = {}   # topic -> the refusal of its writers
        self.conflicts: set[str] = set()      # topics with a conflicting copy of a step
        self.announced = False               # a run status came (the plant's run exists)
        try:
            run_info = yaml.safe_load(params.run_info or '{}') or {}
        except yaml.YAMLError as err:
            raise ConfigError(f'parameter run_info is not YAML: {err}') from None
        if not isinstance(run_info, dict):
            raise ConfigError(f'parameter run_info must be a YAML mapping, got {run_info!r}')
        self.writer = BagWriter(Path(params.output_dir) / name, run_info=run_info,
                                flush_period_s=0.0)
        self.from_bus = set()    # topics taken from a composition's bus (take_from_bus)
        self._records = {}       # topic -> callback writing one message's CDR bytes
        self.readers = Subscriptions(self, KNOWN_TOPICS, self._selected, self._callback_of,
                                     message_class, self.writers.watch, params.queue_depth,
                                     params.fresh_topics)
        steady = Clock(clock_type=ClockType.STEADY_TIME)
        self.create_timer(params.discovery_period, self.discover, clock=steady)
        self.create_timer(params.flush_period, self.flush, clock=steady)
        self.discover()
        self.get_logger().info(f'recording to {self.writer.path}')

    def _selected(self, topic: str) -> bool:
        if self.wanted:
            return topic in self.wanted
        return interface.is_testbed_topic(topic) and not topic.startswith(interface.LIVE_PREFIX)

    def discover(self) -> None:
        """Look for foreign writers and new topics (:meth:`Subscriptions.discover`)."""
        self.note_foreign()
        self.readers.discover()

    def note_foreign(self, final: bool = False) -> None:
        """Check the watched topics' writers now (:meth:`WriterCheck.check_each`); log refusals."""
        if final:      # what DDS matched, whether or not the graph shows it yet
            for topic in self.writers.topics:
                sub = self.readers.reader(topic)
                if sub is not None:
                    self.writers.note_matched(topic, sub)
        for topic, refusal in self.writers.check_each(final).items():
            if topic not in self.foreign:
                self.foreign[topic] = refusal
                self.get_logger().error(f'foreign writer: {refusal}; the recording will fail')

    def _callback_of(self, topic: str, msg_type: str):
        """The raw callback of a subscribed topic: the run status's, or the DDS one."""
        record = self._record(topic, msg_type)
        if topic == interface.RUN_STATUS:
            return self._status_callback(record)
        return self._from_dds(topic, record)

    def _register(self, topic: str, msg_type: str) -> None:
        """Add the topic to the bag at its first message, with the publishers' offered QoS."""
        offered = [offered_qos(topic, p.qos_profile)
                   for p in self.get_publishers_info_by_topic(topic)]
        self.writer.add_topic(topic, msg_type, offered or None)

    def _record(self, topic: str, msg_type: str):
        """The one callback that writes the CDR bytes of ``topic`` (DDS and bus share it)."""
        if topic not in self._records:
            self._records[topic] = self._callback(topic, msg_type, has_header_stamp(msg_type),
                                                  self._selected(topic))
        return self._records[topic]

    def _from_dds(self, topic: str, record):
        """DDS callback of ``topic``: records unless the topic comes from the bus."""
        from_bus = self.from_bus

        def on_dds(data: bytes) -> None:
            if topic not in from_bus:
                record(data)
        return on_dds

    def take_from_bus(self, bus, topics: dict) -> list[str]:
        """
        Record the selected ones of ``topics`` (name -> message class) from ``bus``.

        Called by :func:`pentapod_sim.nodes.local_bus.connect` before the composition spins.
        The DDS subscriptions of these topics stay (the plant's subscriber waits see them) but
        record nothing; the bus does not count them as DDS subscribers. Returns the topics
        taken.
        """
        taken = []
        for topic, cls in topics.items():
            if not self._selected(topic) or topic == interface.RUN_STATUS:
                continue
            cdr = serializer(cls)
            if cdr is None:
                continue    # no direct serialiser for this type: it stays on DDS
            record = self._record(topic, type_name(cls))
            self.from_bus.add(topic)
            bus.subscribe(topic, lambda msg, record=record, cdr=cdr: record(cdr(msg)),
                          node=self)
            taken.append(topic)
        if taken:
            self.get_logger().info(f'in-process: {", ".join(taken)}')
        return taken

    def _status_callback(self, record):
        """Callback of the run status: record it, then note the end of the run."""
        def on_status(data: bytes) -> None:
            record(data)
            msg = deserialize_message(data, message_class(interface.DIAGNOSTIC_STATUS))
            try:
                status = RunStatus.from_values({kv.key: kv.value for kv in msg.values})
            except BagError as err:
                self.get_logger().error(f'{interface.RUN_STATUS}: {err}')
                return
            self.announced = True
            run_end.note_start(self.writer, status)       # a start not at rest is noted
            self.readers.expect(status.step_topics)       # found by discovery or not
            if status.ended:
                self.end, self.end_seen = status, time.monotonic()
                self.get_logger().info(f'run {status.state} after {status.steps} steps; '
                                       'draining')
                self.discover()      # what appeared since the last look is recorded too
        return on_status

    def _callback(self, topic: str, msg_type: str, stamped: bool, selected: bool = True):
        clock, write, note = self.get_clock(), self.writer.write, self.ledger.note
        # the node's clock is the system clock unless use_sim_time: time.time_ns reads that
        # in 0.04 us, rclpy's Clock.now in 1.9 us (per message, several per step)
        now_ns = (time.time_ns if not self.get_parameter('use_sim_time').value
                  else lambda: clock.now().nanoseconds)
        registered = []
        conflicts = self.conflicts

        def on_message(data: bytes) -> None:
            if not selected:
                return
            received = now_ns()
            if not registered:
                self._register(topic, msg_type)
                registered.append(True)
            if stamped:
                sec, nanosec = struct.unpack_from('<iI', data, 4)
                stamp = sec * 1_000_000_000 + nanosec
                if last_stamp and last_stamp[0] == stamp and last_data[0] == data:
                    self.duplicates[topic] = self.duplicates.get(topic, 0) + 1
                    return  # a lockstep plant re-sends a step while it waits: keep one copy
                last_stamp[:], last_data[:] = [stamp], [data]
                write(topic, data, stamp, received)    # a conflicting copy too: evidence
                if not note(topic, stamp) and topic not in conflicts:
                    conflicts.add(topic)
                    self.get_logger().error(f'{topic}: a second, different message for stamp '
                                            f'{stamp} ns; the recording will fail')
            else:
                write(topic, data, received, received)
        last_stamp, last_data = [], []
        return on_message

    def flush(self) -> None:
        """Push the open chunk to disk and rewrite metadata.yaml."""
        self.writer.flush()

    def expected_topics(self) -> list:
        """Per-step topics that must hold every step of the announced run."""
        present = set(self.writer.topic_counts()) | {
            t for t, (sub, _, _) in self.readers.subs.items()
            if sub is not None and self.count_publishers(t) > 0}
        return self.ledger.expected_topics(self.end, present)

    def done(self) -> bool:
        """
        True once the run ended and every per-step topic holds its last step.

        Also once every topic still short of it has no publisher left (nothing more can come:
        after a stop signal a source may end without answering the last step), and once no
        step message came for ``drain_timeout`` s of wall time after the end announcement;
        never without ``stop_at_run_end``. Each latched topic with a publisher must hold its
        message too, or :data:`LATCHED_WAIT` s have passed since the end announcement.
        """
        if not self.params.stop_at_run_end or self.end is None:
            return False
        waiting = self.ledger.pending(self.end, self.expected_topics())
        if not waiting or (time.monotonic() - self.ledger.noted > ORPHAN_QUIET
                           and not any(self.count_publishers(t) for t in waiting)):
            unheard = self.unheard_latched()
            if not unheard:
                return True
            wait = min(LATCHED_WAIT, self.params.drain_timeout)
            if time.monotonic() - self.end_seen > wait:
                self.get_logger().warning(f'no message on {", ".join(unheard)} within '
                                          f'{wait} s after the end of the run')
                return True
            return False
        # counted from the last step message taken, not from the announcement: a recorder
        # behind the run (a loaded machine) still takes the steps its readers hold, which
        # are lost once it closes (a 3000-step composed run with three busy loops on two
        # cores: the recorder took steps for 35 s after the end, and closed at 30 s)
        if time.monotonic() - max(self.end_seen, self.ledger.noted) > self.params.drain_timeout:
            self.get_logger().warning(f'drain_timeout = {self.params.drain_timeout} s without '
                                      'a new step after the end of the run; closing with steps '
                                      'missing')
            return True
        return False

    def unheard_latched(self) -> list[str]:
        """Recorded latched topics, subscribed as such, with a publisher and no message yet."""
        counts = self.writer.topic_counts()
        return [t for t, (sub, _, level) in self.readers.subs.items()
                if sub is not None and level == LATE_JOINER and t not in counts
                and self._selected(t) and self.count_publishers(t)]

    def store_report(self) -> None:
        """Log unique vs expected steps per topic and why it failed; store them in the bag."""
        # a last look at the graph: a run stopped by a foreign writer may end before this
        # recorder's next periodic check, and the bag must still name the writer; a run that
        # was stopped (by a node's error) gets up to FOREIGN_WAIT s more, since this recorder's
        # participant may discover the writer that made another node stop it only later
        # (seconds on a loaded host)
        self.note_foreign(final=True)
        if self.end is not None and self.end.state == interface.RUN_STOPPED:
            until = time.monotonic() + FOREIGN_WAIT
            while not self.foreign and time.monotonic() < until:
                time.sleep(0.1)
                self.note_foreign(final=True)
        if not self.announced:
            self.note_unannounced()
        if self.end is None:       # the bag still says what it holds is not the plant's
            self.failed = [f'{t}: {text}' for t, text in self.foreign.items()]
            self.writer.add_record(RECORDING_RECORD, report_record(None, {}, self.foreign))
            return
        self.report = report = self.ledger.report(
            self.end, self.expected_topics(), self.writer.topic_counts())
        self.failed = failures(report, self.foreign)
        self.writer.add_record(RECORDING_RECORD, report_record(self.end, report, self.foreign))
        text = ', '.join(f'{t} {c["unique"]}/{c["expected"]}' for t, c in report.items())
        if self.failed:
            self.get_logger().error(f'unique/expected steps: {text}; FAILED: '
                                    + '; '.join(self.failed))
        else:
            self.get_logger().info(f'unique/expected steps: {text}; none missing, no '
                                   'conflicting copy, no foreign writer')

    def note_unannounced(self) -> None:
        """
        Name the writers of the plant's state topics that hold messages though no run came.

        The plant announces its run before its first step, so such messages are not a run's;
        a forger whose run was stopped before this recorder saw the real plant is named so.
        """
        counts = self.writer.topic_counts()
        for topic in (interface.CLOCK, *interface.STATE_TOPICS):
            if counts.get(topic) and topic not in self.foreign:
                writers = writers_text(self.writers.seen.get(topic, {}).values())
                self.foreign[topic] = (f'{topic}: {counts[topic]} message(s) but no run '
                                       f'announced, from {writers or "a writer now gone"}')
                self.get_logger().error(f'foreign writer: {self.foreign[topic]}')

    def close(self) -> None:
        """Store the counts, finish the bag (summary, footer, metadata.yaml)."""
        if self.context.ok():  # after a signal the graph and rosout are gone
            self.store_report()
        self.writer.close()
        if self.duplicates:
            self.get_logger().info(f'skipped re-sent copies of a step: {self.duplicates}')
        if self.context.ok():
            self.get_logger().info(f'closed {self.writer.path}: {self.writer.topic_counts()}')


#: After a stop signal the recorder waits this long [s, wall time] for the plant's end
#: announcement (a plant stopped by the same signal ends its step and announces it), then
#: drains up to ``drain_timeout``; without an announcement it closes with what it has.
SIGNAL_GRACE = 2.0


def record(node: RecorderNode, executor) -> None:
    """
    Spin until the drained end of the run or a signal; the bag is closed on the way out.

    A stop signal sent to every node at once (Ctrl-C of a launch, the scenario runner) reaches
    the recorder while the plant's last steps are still on their way: the recorder then keeps
    taking messages until the plant's end announcement is drained, for at most
    :data:`SIGNAL_GRACE` s without an announcement.
    """
    try:
        while rclpy.ok() and not node.done() and not shutdown.requested():
            executor.spin_once(timeout_sec=0.05)
        if shutdown.requested() and rclpy.ok() and node.params.stop_at_run_end:
            give_up = time.monotonic() + SIGNAL_GRACE
            while rclpy.ok() and not node.done() and (node.end is not None
                                                       or time.monotonic() < give_up):
                executor.spin_once(timeout_sec=0.05)
    finally:
        node.close()
    if node.failed:
        raise RecordingError(f'recording {node.writer.path} is incomplete or not trustworthy: '
                             + '; '.join(node.failed))


def main(argv=None) -> int:
    """Entry point of ``ros2 run pentapod_testbed recorder``."""
    # the default executor: rclpy's EventsExecutor did not fire the steady-clock discovery and
    # flush timers here
    return run_node(RecorderNode, argv, record, executor=SingleThreadedExecutor)


if __name__ == '__main__':
    raise SystemExit(main())
