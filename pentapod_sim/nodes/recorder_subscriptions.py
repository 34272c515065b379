"""
The recorder's readers: which topics it subscribes to, at which QoS level, and when.

Known topics (docs/architecture.md) are subscribed at start, before any publisher exists, so
that a recorder started before the plant misses no step; others are found by discovery. A
topic is first subscribed as :func:`~pentapod_sim.nodes.recorder_qos.level_for` says for the
publishers known then; a later publisher that offers less (volatile, best effort) cannot match
that reader, so the topic is subscribed again at that publisher's level, with a warning (its
messages before the new subscription matched are lost). The level never goes back up.

Fresh topics (recorder parameter ``fresh_topics``: the answers of a source that outlives runs,
recorded volatile, without its earlier runs' history) are subscribed first, and the known
topics only once every fresh topic's writer is matched: the plant, waiting for the recorder
on its own topics, cannot start before, so no answer is published before the recorder's
reader can take it (test/test_recorder_fresh.py). The per-step topics a run status
announces are subscribed when it comes (:meth:`Subscriptions.expect`), found or not.
"""
from __future__ import annotations

from typing import Any, Callable

from rclpy.clock import Clock, ClockType

from pentapod_sim import interface
from pentapod_sim.errors import BagError
from pentapod_sim.nodes.recorder_qos import BEST_EFFORT, level_for, LEVELS, subscription_qos

#: Wall time [s] between looks for the writers of ``fresh_topics`` while the known topics wait.
HOLD_BACK_PERIOD = 0.02


def _type_of(topic: str) -> str | None:
    """The message type of a testbed topic known by name (forces: any source's), else None."""
    msg_type = interface.TOPIC_TYPES.get(topic)
    if msg_type is None and topic.startswith(interface.FORCE_PREFIX):
        msg_type = interface.JOINT_STATE
    return msg_type


class Subscriptions:
    """
    The readers of one recorder node.

    Parameters
    ----------
    node : rclpy.node.Node
        The recorder (subscriptions, timers, graph queries and its logger).
    known : dict
        Topic -> message type subscribed at start (held back while fresh topics wait).
    selected : callable
        ``selected(topic)``: True for a topic the recorder records.
    callback_of : callable
        ``callback_of(topic, msg_type)``: the raw-message callback of a topic.
    message_class : callable
        ``message_class(msg_type)``: the rclpy message class of a type name.
    watch : callable
        ``watch(topic)``: a newly subscribed topic whose writers are checked.
    depth : int
        Queue depth of every reader.
    fresh : iterable of str
        Fresh topics (module docstring).
    """

    def __init__(self, node: Any, known: dict[str, str], selected: Callable[[str], bool],
                 callback_of: Callable[[str, str], Any], message_class: Callable[[str], Any],
                 watch: Callable[[str], None], depth: int, fresh: Any = ()) -> None:
        self.node, self.known, self.selected = node, known, selected
        self.callback_of, self.message_class, self.watch = callback_of, message_class, watch
        self.depth, self.fresh = depth, set(fresh)
        self.subs: dict[str, tuple[Any, str, int]] = {}   # topic -> (reader or None, type, level)
        self.held_back = [t for t in known if selected(t) or t == interface.RUN_STATUS]
        self._release_timer = None
        for topic in sorted(self.fresh):
            msg_type = _type_of(topic)
            if msg_type is not None and selected(topic):
                self.subscribe(topic, msg_type)
        if self.fresh:
            node.get_logger().info('waiting for the writer(s) of ' + ', '.join(sorted(self.fresh))
                                   + " (fresh_topics) before subscribing to the plant's topics")
        if not self.release_held_back():     # looked for often: the plant waits for it
            self._release_timer = node.create_timer(
                HOLD_BACK_PERIOD, self.release_held_back,
                clock=Clock(clock_type=ClockType.STEADY_TIME))

    def reader(self, topic: str) -> Any:
        """The subscription of ``topic`` (None: not subscribed or not recordable)."""
        return self.subs.get(topic, (None,))[0]

    def release_held_back(self) -> bool:
        """Subscribe the known topics once every fresh topic's writer is matched (True then)."""
        if not self.held_back:
            return True
        fresh = sorted(t for t in self.fresh if self.selected(t))
        if any(self.reader(t) is None or self.reader(t).get_publisher_count() == 0
               for t in fresh):
            return False
        if self._release_timer is not None:
            self.node.destroy_timer(self._release_timer)
            self._release_timer = None
        if fresh:
            self.node.get_logger().info('matched the writer(s) of ' + ', '.join(fresh))
        for topic in self.held_back:
            if topic not in self.subs:
                self.subscribe(topic, self.known[topic])
        self.held_back = []
        return True

    def expect(self, topics: Any) -> None:
        """
        Subscribe to the per-step topics a run status announces, before discovery finds them.

        The plant names the force topics it takes in its status; a recorder whose participant
        has not found a source's writer yet (DDS discovery can take an announcement period)
        would otherwise miss that source's steps of a short run. Its writers keep the run's
        steps for late readers, so the steps come once the writer is matched.
        """
        if self.held_back:
            return
        for topic in topics:
            msg_type = _type_of(topic)
            if topic not in self.subs and msg_type is not None and self.selected(topic):
                self.subscribe(topic, msg_type)

    def discover(self) -> None:
        """Subscribe to new selected topics with a publisher; follow what publishers offer."""
        node = self.node
        released = self.release_held_back()
        for topic, types in node.get_topic_names_and_types():
            if not self.selected(topic) or not (released or topic in self.fresh):
                continue
            known = self.subs.get(topic)
            if known is not None and (known[0] is None or known[2] == BEST_EFFORT):
                continue  # unrecordable, or already best effort (matches every publisher)
            publishers = node.get_publishers_info_by_topic(topic)
            if not publishers:
                continue
            level = level_for(topic, publishers, topic in self.fresh)
            if known is not None and level >= known[2]:
                continue
            if known is not None:  # the reader asks more than a publisher offers
                node.destroy_subscription(known[0])
                node.get_logger().warning(f'{topic}: a publisher offers only {LEVELS[level]}; '
                                          're-subscribed, messages may be lost')
            try:
                self.subscribe(topic, types[0], level)
            except (BagError, ImportError, AttributeError, ValueError) as err:
                node.get_logger().error(f'cannot record {topic} [{types[0]}]: {err}')
                self.subs[topic] = (None, types[0], BEST_EFFORT)  # do not retry every period

    def subscribe(self, topic: str, msg_type: str, level: int | None = None) -> None:
        """Subscribe at ``level`` (:func:`level_for`; None: the topic's own, no publisher)."""
        if level is None:
            level = level_for(topic, [], topic in self.fresh)
        # transient local (per-step streams, run status, excitation spec): a recorder that
        # matched a writer late gets what the writer still holds
        sub = self.node.create_subscription(self.message_class(msg_type), topic,
                                            self.callback_of(topic, msg_type),
                                            subscription_qos(level, self.depth), raw=True)
        if topic == interface.RUN_STATUS or interface.is_step_topic(topic):
            self.watch(topic)
        self.subs[topic] = (sub, msg_type, level)
        self.node.get_logger().info(f'subscribed {topic} [{msg_type}]'
                                    f'{" best effort" if level == BEST_EFFORT else ""}')
