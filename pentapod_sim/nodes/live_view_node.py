"""
Live view node: serves the testbed topics to Foxglove over its WebSocket protocol.

A thin rclpy adapter around :class:`pentapod_sim.live.hub.LiveHub`. It subscribes to every
testbed topic of type JointState or WrenchStamped (found at start and by discovery) with raw
(CDR bytes) subscriptions whose callbacks only queue the bytes; decoding, downsampling and the
WebSocket work run on the hub's worker thread. The subscriptions are best effort by default:
the plant's reliable KEEP_LAST writers then neither keep, resend nor wait for acknowledgements
for the live view, so a slow or stalled live view cannot hold up the lockstep loop (it loses
display samples instead, counted in the run status). See docs/live_view.md.

Parameters: :data:`pentapod_sim.live.params.LIVE_VIEW`.
"""
from __future__ import annotations

import time

from geometry_msgs.msg import WrenchStamped
import rclpy
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.serialization import serialize_message
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray, MultiArrayDimension

from pentapod_sim import interface, shutdown
from pentapod_sim.live.hub import LiveHub, lower_priority
from pentapod_sim.live.params import LIVE_VIEW
from pentapod_sim.live.streams import SUPPORTED_TYPES
from pentapod_sim.nodes.common import declare_table, node_args, run_node, stamp_msg

MESSAGE_CLASSES = {interface.JOINT_STATE: JointState, interface.WRENCH_STAMPED: WrenchStamped}
#: Topics subscribed at start, before any publisher exists (others come by discovery).
KNOWN_TOPICS = (*interface.STATE_TOPICS, interface.EXCITATION, interface.PMA_STATE)


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


class LiveViewNode(Node):
    """Subscriptions and discovery of the live view (parameters: docs/parameters.md)."""

    def __init__(self, **kwargs):
        super().__init__('live_view', **kwargs)
        self.params = params = declare_table(self, LIVE_VIEW, node_args(kwargs.get('cli_args')))
        self.qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=params.queue_depth,
                              reliability=ReliabilityPolicy[params.reliability.upper()],
                              durability=DurabilityPolicy.VOLATILE)
        self.hub = LiveHub(params, RclpyEncoder())
        self.subs = {}
        for topic in KNOWN_TOPICS:
            if self._selected(topic):
                self._subscribe(topic, interface.TOPIC_TYPES[topic])
        self.discover()

    def _selected(self, topic: str) -> bool:
        if topic.startswith(interface.LIVE_PREFIX):
            return False
        if self.params.topics:
            return topic in self.params.topics
        return interface.is_testbed_topic(topic) and topic != interface.CLOCK

    def discover(self) -> None:
        """Subscribe to selected topics that appeared (JointState and WrenchStamped only)."""
        for topic, types in self.get_topic_names_and_types():
            if topic in self.subs or not self._selected(topic):
                continue
            if types[0] not in SUPPORTED_TYPES:
                self.subs[topic] = None     # not served; do not look again
                continue
            self._subscribe(topic, types[0])

    def _subscribe(self, topic: str, msg_type: str) -> None:
        stream = self.hub.add_topic(topic, msg_type)
        self.subs[topic] = self.create_subscription(MESSAGE_CLASSES[msg_type], topic,
                                                    stream.offer, self.qos, raw=True)
        self.get_logger().info(f'serving {topic} [{msg_type}]')


def serve(node: LiveViewNode, executor) -> None:
    """Start the WebSocket server, spin (discovering topics) until SIGINT/SIGTERM."""
    port = node.hub.start()
    threads = lower_priority(node.params.nice)
    node.get_logger().info(f'Foxglove WebSocket server on ws://{node.params.host}:{port} '
                           f'(niceness +{node.params.nice} on {threads} threads)')
    try:
        next_look = time.monotonic() + node.params.discovery_period
        while rclpy.ok() and not shutdown.requested():
            executor.spin_once(timeout_sec=0.1)
            if time.monotonic() > next_look:
                node.discover()
                next_look = time.monotonic() + node.params.discovery_period
    finally:
        node.hub.stop()


def main(argv=None) -> int:
    """Entry point of ``ros2 run pentapod_testbed live_view``."""
    return run_node(LiveViewNode, argv, serve, table=LIVE_VIEW)


if __name__ == '__main__':
    raise SystemExit(main())
