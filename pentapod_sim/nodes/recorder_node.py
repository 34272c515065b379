"""
Recorder node: writes chosen topics (default every /pentapod/* topic and /clock) to a bag.

Subscriptions are raw (CDR bytes, no deserialisation) and reliable with a deep queue unless a
publisher only offers best effort; the bag is written by the ROS-free
:class:`pentapod_sim.recording.BagWriter`. The log time of a message is its header stamp (sim
time) when its type starts with a std_msgs/Header or a builtin Time (Clock), else the
receive time of the node clock. SIGINT/SIGTERM close the bag completely; after a SIGKILL the
bag is readable up to the last periodic flush. The node publishes nothing.

Parameters: :data:`pentapod_sim.nodes.parameter_tables.RECORDER` (docs/parameters.md).
"""
import datetime
import importlib
from pathlib import Path
import struct
import time

import rclpy
from rclpy.clock import Clock, ClockType
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
import yaml

from pentapod_sim import interface
from pentapod_sim.errors import BagError, ConfigError
from pentapod_sim.nodes.common import declare_table, node_args, run_node
from pentapod_sim.nodes.parameter_tables import RECORDER
from pentapod_sim.recording import BagWriter, qos_profile
from pentapod_sim.recording.msgdefs import has_header_stamp

# topics of docs/architecture.md: subscribed at start (before any publisher exists), so that a
# recorder started before the plant misses no step; others are found by discovery
KNOWN_TOPICS = {t: interface.TOPIC_TYPES[t] for t in (
    interface.CLOCK, interface.TCP_STATE, interface.STRUT_STATES, interface.EXCITATION,
    interface.PMA_STATE)}


def message_class(msg_type: str):
    """Import the rclpy message class of ``pkg/msg/Type``."""
    pkg, _, name = msg_type.split('/')
    return getattr(importlib.import_module(f'{pkg}.msg'), name)


class RecorderNode(Node):
    """Record topics to a rosbag2-compatible MCAP bag."""

    def __init__(self, **kwargs):
        super().__init__('recorder', **kwargs)
        self.params = params = declare_table(self, RECORDER, node_args(kwargs.get('cli_args')))
        self.stop_when_idle = params.stop_when_idle
        self.last_message = None
        self.duplicates = {}
        self.wanted = params.topics
        name = params.bag_name or datetime.datetime.now(
            datetime.timezone.utc).strftime('run_%Y%m%d_%H%M%S')
        try:
            run_info = yaml.safe_load(params.run_info or '{}') or {}
        except yaml.YAMLError as err:
            raise ConfigError(f'parameter run_info is not YAML: {err}') from None
        if not isinstance(run_info, dict):
            raise ConfigError(f'parameter run_info must be a YAML mapping, got {run_info!r}')
        self.depth = params.queue_depth
        self.writer = BagWriter(Path(params.output_dir) / name, run_info=run_info,
                                flush_period_s=0.0)
        self.subs = {}  # topic -> (subscription or None, msg_type, best_effort)
        for topic, msg_type in KNOWN_TOPICS.items():
            if self._selected(topic):
                self._subscribe(topic, msg_type, [])
        steady = Clock(clock_type=ClockType.STEADY_TIME)
        self.create_timer(params.discovery_period, self.discover, clock=steady)
        self.create_timer(params.flush_period, self.flush, clock=steady)
        self.discover()
        self.get_logger().info(f'recording to {self.writer.path}')

    def _selected(self, topic: str) -> bool:
        if self.wanted:
            return topic in self.wanted
        return interface.is_testbed_topic(topic)

    def discover(self) -> None:
        """Subscribe to new selected topics with a publisher; follow best-effort publishers."""
        for topic, types in self.get_topic_names_and_types():
            if not self._selected(topic):
                continue
            known = self.subs.get(topic)
            if known is not None and (known[0] is None or known[2]):
                continue  # unrecordable, or already best effort (matches every publisher)
            publishers = self.get_publishers_info_by_topic(topic)
            if not publishers or (known is not None and not _any_best_effort(publishers)):
                continue
            if known is not None:  # a best-effort publisher cannot match a reliable reader
                self.destroy_subscription(known[0])
                self.get_logger().warning(f'{topic}: best-effort publisher, messages may be lost')
            try:
                self._subscribe(topic, types[0], publishers)
            except (BagError, ImportError, AttributeError, ValueError) as err:
                self.get_logger().error(f'cannot record {topic} [{types[0]}]: {err}')
                self.subs[topic] = (None, types[0], False)  # do not retry every period

    def _subscribe(self, topic: str, msg_type: str, publishers) -> None:
        best_effort = _any_best_effort(publishers)
        qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=self.depth,
                         reliability=(ReliabilityPolicy.BEST_EFFORT if best_effort
                                      else ReliabilityPolicy.RELIABLE),
                         durability=DurabilityPolicy.VOLATILE)
        stamped = has_header_stamp(msg_type)
        sub = self.create_subscription(message_class(msg_type), topic,
                                       self._callback(topic, msg_type, stamped), qos, raw=True)
        self.subs[topic] = (sub, msg_type, best_effort)
        self.get_logger().info(f'subscribed {topic} [{msg_type}]'
                               f'{" best effort" if best_effort else ""}')

    def _register(self, topic: str, msg_type: str) -> None:
        """Add the topic to the bag at its first message, with the publishers' offered QoS."""
        offered = [qos_profile(p.qos_profile.reliability.name.lower(), self.depth,
                               p.qos_profile.durability.name.lower())
                   for p in self.get_publishers_info_by_topic(topic)]
        self.writer.add_topic(topic, msg_type, offered or None)

    def _callback(self, topic: str, msg_type: str, stamped: bool):
        clock, write = self.get_clock(), self.writer.write
        registered = []

        def on_message(data: bytes) -> None:
            received = clock.now().nanoseconds
            if not registered:
                self._register(topic, msg_type)
                registered.append(True)
            self.last_message = time.monotonic()
            if stamped:
                sec, nanosec = struct.unpack_from('<iI', data, 4)
                stamp = sec * 1_000_000_000 + nanosec
                if last_stamp and last_stamp[0] == stamp and last_data[0] == data:
                    self.duplicates[topic] = self.duplicates.get(topic, 0) + 1
                    return  # a lockstep plant re-sends a step while it waits: keep one copy
                last_stamp[:], last_data[:] = [stamp], [data]
                write(topic, data, stamp, received)
            else:
                write(topic, data, received, received)
        last_stamp, last_data = [], []
        return on_message

    def flush(self) -> None:
        """Push the open chunk to disk and rewrite metadata.yaml."""
        self.writer.flush()

    def idle(self) -> bool:
        """True once messages came and none arrived for ``stop_when_idle`` seconds."""
        return (self.stop_when_idle > 0 and self.last_message is not None
                and time.monotonic() - self.last_message > self.stop_when_idle)

    def close(self) -> None:
        """Finish the bag (summary, footer, metadata.yaml)."""
        self.writer.close()
        if self.duplicates:
            self.get_logger().info(f'skipped re-sent copies of a step: {self.duplicates}')
        if self.context.ok():  # after a signal the rosout publisher is gone
            self.get_logger().info(f'closed {self.writer.path}: {self.writer.topic_counts()}')


def _any_best_effort(publishers) -> bool:
    return any(p.qos_profile.reliability == ReliabilityPolicy.BEST_EFFORT for p in publishers)


def record(node: RecorderNode, executor) -> None:
    """Spin until SIGINT/SIGTERM or ``stop_when_idle``; the bag is closed on the way out."""
    try:
        while rclpy.ok() and not node.idle():
            executor.spin_once(timeout_sec=0.05)
    finally:
        node.close()


def main(argv=None) -> int:
    """Entry point of ``ros2 run pentapod_testbed recorder``."""
    # the default executor: rclpy's EventsExecutor did not fire the steady-clock discovery and
    # flush timers here
    return run_node(RecorderNode, argv, record, table=RECORDER,
                    executor=SingleThreadedExecutor)


if __name__ == '__main__':
    raise SystemExit(main())
