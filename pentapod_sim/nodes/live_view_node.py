"""
Live view node: serves the testbed topics to Foxglove over its WebSocket protocol.

A thin rclpy adapter around :class:`pentapod_sim.live.hub.LiveHub`. It serves every testbed
topic of type JointState or WrenchStamped (found at start and by discovery); the plant's state
topics and the sources' force topics it takes from the plant's display batches
(:mod:`pentapod_sim.nodes.display_batch`, one message per ``display_batch_period`` carrying
every step), never per step, so the plant publishes no per-step message for the view and the
sources send it nothing (the full-rate TCP topic of a multi-rate plant is served only if named
in ``topics``: subscribing would make the plant compute and publish it every exchange). Like
foxglove_bridge it subscribes to a topic only while a WebSocket client watches its channel
(or the run figures or spectrum made from it): with no client, it takes nothing from the run.
The subscriptions are raw (CDR bytes) and no executor serves them: they sit in a callback group the
executor never waits on (:class:`PolledGroup`), and the hub's worker thread takes what they
hold once every ``tick_period`` (:meth:`LiveViewNode.take`). So the process does no work per
message in Python and wakes at its own pace, not the plant's; decoding, downsampling and the
WebSocket work run on the same worker thread, and every thread of the process runs at a lower
priority (``nice``). The subscriptions are best effort by default: the plant's reliable KEEP_LAST
writers then neither keep, resend nor wait for acknowledgements for the live view, so a slow or
stalled live view cannot hold up the lockstep loop (it loses display samples instead, counted
in the run status from the gaps in the publishers' sequence numbers). The plant's run status
(/pentapod/run_status) comes through an ordinary subscription and is passed through.
See docs/live_view.md.

Parameters: :class:`pentapod_sim.live.params.LiveViewParams`.
"""
from __future__ import annotations

import threading
import time

from diagnostic_msgs.msg import DiagnosticStatus
from geometry_msgs.msg import WrenchStamped
import rclpy
from rclpy.callback_groups import CallbackGroup
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray, MultiArrayDimension

from pentapod_sim import interface, shutdown
from pentapod_sim.live.hub import LiveHub, lower_priority
from pentapod_sim.live.params import LiveViewParams
from pentapod_sim.live.streams import SUPPORTED_TYPES
from pentapod_sim.nodes.common import qos, run_node, stamp_msg
from pentapod_sim.nodes.testbed_node import TestbedNode

MESSAGE_CLASSES = {interface.JOINT_STATE: JointState, interface.WRENCH_STAMPED: WrenchStamped}
#: Topics subscribed at start, before any publisher exists (others come by discovery).
KNOWN_TOPICS = (*interface.STATE_TOPICS, interface.EXCITATION, interface.PMA_STATE)
#: Testbed topics served only when named in ``topics``: /clock (no values), the full-rate TCP
#: samples (a multi-rate plant computes and publishes them every exchange while subscribed).
NOT_BY_DEFAULT = (interface.CLOCK, interface.TCP_STATE_FULLRATE)
#: Wall time [s] between two looks at what the connected clients watch.
CLIENT_PERIOD = 0.1


class RclpyEncoder:
    """The hub's message serialiser: rclpy messages and ``serialize_message``."""

    def joint_state(self, stamp_ns, frame_id, names, fields) -> bytes:
        """sensor_msgs/JointState as CDR."""
        msg = JointState(name=list(names), **fields)
        msg.header.stamp, msg.header.frame_id = stamp_msg(stamp_ns), frame_id
        return serialize_message(msg)

    def wrench(self, stamp_ns, frame_id, values) -> bytes:
        """geometry_msgs/WrenchStamped as CDR."""
        msg = WrenchStamped()
        msg.header.stamp, msg.header.frame_id = stamp_msg(stamp_ns), frame_id
        force, torque = msg.wrench.force, msg.wrench.torque
        force.x, force.y, force.z, torque.x, torque.y, torque.z = map(float, values)
        return serialize_message(msg)

    def float_array(self, label, values) -> bytes:
        """std_msgs/Float64MultiArray with one labelled dimension, as CDR."""
        msg = Float64MultiArray(data=list(values))
        msg.layout.dim = [MultiArrayDimension(label=label, size=len(values),
                                              stride=len(values))]
        return serialize_message(msg)


class PolledGroup(CallbackGroup):
    """Subscriptions no executor waits on or takes from: the live view's worker takes them."""

    def can_execute(self, entity) -> bool:
        """Never: the executor leaves these subscriptions alone."""
        return False

    def beginning_execution(self, entity) -> bool:
        """Never."""
        return False

    def ending_execution(self, entity) -> None:
        """Nothing to end."""


class LiveViewNode(TestbedNode):
    """Subscriptions and discovery of the live view (parameters: docs/parameters.md)."""

    Params = LiveViewParams

    def __init__(self, **kwargs):
        super().__init__('live_view', **kwargs)
        params = self.params
        self.qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=params.queue_depth,
                              reliability=ReliabilityPolicy[params.reliability.upper()],
                              durability=DurabilityPolicy.VOLATILE)
        self.hub = LiveHub(params, RclpyEncoder(), poll=self.take)
        self.subs = {}            # topic -> its subscription; None: not now (or not served)
        self.served = {}          # topic -> (stream, message class, topic subscribed to)
        self.polled = []          # (stream, subscription), taken by the hub's worker
        self._lock = threading.Lock()     # polled: the worker's take against changes
        self.group = PolledGroup()
        for topic in KNOWN_TOPICS:
            if self._selected(topic):
                self._subscribe(topic, interface.TOPIC_TYPES[topic])
        self.subs[interface.RUN_STATUS] = self.create_subscription(
            DiagnosticStatus, interface.RUN_STATUS, self._run_status,
            qos(interface.qos_class(interface.RUN_STATUS)), raw=True)
        self.discover()

    def _run_status(self, data: bytes) -> None:
        msg = deserialize_message(data, DiagnosticStatus)
        self.hub.add_run_status(data, {kv.key: kv.value for kv in msg.values})

    def _selected(self, topic: str) -> bool:
        if topic.startswith(interface.LIVE_PREFIX):
            return False
        if self.params.topics:
            return topic in self.params.topics
        return interface.is_testbed_topic(topic) and topic not in NOT_BY_DEFAULT

    def discover(self) -> None:
        """Serve selected topics that appeared (JointState and WrenchStamped only)."""
        for topic, types in self.get_topic_names_and_types():
            topic = interface.batched_topic(topic) or topic     # a display batch: its topic
            if topic in self.subs or not self._selected(topic):
                continue
            if interface.has_display_batch(topic):
                self._subscribe(topic, interface.JOINT_STATE)
                continue
            if types[0] not in SUPPORTED_TYPES:
                self.subs[topic] = None     # not served; do not look again
                continue
            self._subscribe(topic, types[0])

    def _subscribe(self, topic: str, msg_type: str) -> None:
        """
        Serve ``topic``: its channel now, its subscription while a client watches it.

        The subscription is to the topic's display batches if the plant makes them, else to
        the topic itself (:meth:`follow_clients`).
        """
        batched = interface.has_display_batch(topic)
        source = interface.display_batch_topic(topic) if batched else topic
        stream = self.hub.add_topic(topic, msg_type, batched=batched)
        self.served[topic] = (stream, MESSAGE_CLASSES[msg_type], source)
        self.subs[topic] = None
        self.get_logger().info(f'serving {topic} [{msg_type}]' + (
            f' from {source}' if batched else ''))

    def follow_clients(self) -> None:
        """
        Subscribe to what a connected client watches; unsubscribe from what nobody watches.

        Like foxglove_bridge: with no client the view subscribes to no data topic, so the
        plant publishes nothing for it and nothing is received. Called from the executor's
        thread (:func:`serve`, a timer in a composition).
        """
        for topic, (stream, msg_class, source) in list(self.served.items()):
            wanted, sub = self.hub.wanted(topic), self.subs[topic]
            if wanted and sub is None:
                stream.sequence = None     # a new start: the numbers skipped are no loss
                sub = self.create_subscription(msg_class, source, stream.offer, self.qos,
                                               raw=True, callback_group=self.group)
                with self._lock:
                    self.subs[topic] = sub
                    self.polled.append((stream, sub))
            elif not wanted and sub is not None:
                with self._lock:
                    self.polled.remove((stream, sub))
                    self.subs[topic] = None
                self.destroy_subscription(sub)

    def take(self) -> None:
        """Move every message the subscriptions hold into the streams (the hub's worker)."""
        with self._lock:
            for stream, sub in self.polled:
                with sub.handle:
                    while (got := sub.handle.take_message(sub.msg_type, True)) is not None:
                        data, info = got
                        stream.offer(data, info.get('publication_sequence_number'))


    def start(self, nice: int) -> None:
        """Start the WebSocket server; add ``nice`` to this process's threads' niceness."""
        port = self.hub.start()
        threads = lower_priority(nice)
        self.get_logger().info(f'Foxglove WebSocket server on ws://{self.params.host}:{port} '
                               f'(niceness +{nice} on {threads} threads)')

    def start_component(self) -> None:
        """
        Start inside a composed run (:mod:`pentapod_sim.nodes.composed`).

        The server starts without renicing (the plant shares the process) and timers on the
        composition's executor look for new topics and follow the clients; ``close`` stops
        the server.
        """
        self.start(0)
        self.create_timer(self.params.discovery_period, self.discover)
        self.create_timer(CLIENT_PERIOD, self.follow_clients)

    def close(self) -> None:
        """Stop the worker and the WebSocket server."""
        self.hub.stop()


def serve(node: LiveViewNode, executor) -> None:
    """Start the WebSocket server, spin (discovering topics) until SIGINT/SIGTERM."""
    node.start(node.params.nice)
    try:
        next_look = time.monotonic() + node.params.discovery_period
        while rclpy.ok() and not shutdown.requested():
            executor.spin_once(timeout_sec=CLIENT_PERIOD)
            node.follow_clients()
            if time.monotonic() > next_look:
                node.discover()
                next_look = time.monotonic() + node.params.discovery_period
    finally:
        node.hub.stop()


def main(argv=None) -> int:
    """Entry point of ``ros2 run pentapod_testbed live_view``."""
    return run_node(LiveViewNode, argv, serve, executor=SingleThreadedExecutor)


if __name__ == '__main__':
    raise SystemExit(main())
