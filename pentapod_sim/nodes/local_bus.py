"""
In-process hand-off between the nodes of one composition (like rclcpp's intra-process comms).

In a composed run (:mod:`pentapod_sim.nodes.composed`) the plant and its in-process force
sources (:class:`pentapod_sim.nodes.lockstep_source.LockstepSource` nodes named in the plant's
``sources``) exchange their per-step messages without DDS: :func:`connect` replaces the
sources' state (or /clock) subscriptions and the plant's force subscriptions for them by
callbacks on a :class:`LocalBus`, and every such publisher becomes an :class:`Outlet`. An
outlet hands the message object itself to the in-process callbacks, synchronously inside
``publish``, and publishes it on DDS only while the topic has DDS subscribers (a recorder or
live view, in this process or another, ``ros2 topic echo``), so those get every message as
before. The message objects carry the values a DDS round trip would give (JointState arrays
are ``array('d')`` either way, stamps are integers), so the traces stay bit-identical to
separate processes and to the offline loop. Every callback of a topic gets the same object, as
rclcpp hands out const messages: a callback must not change it, nor keep it past the call
(the sources refill one message object every step).

A recorder in the composition (:class:`pentapod_sim.nodes.recorder_node.RecorderNode`) takes
the topics of these outlets from the bus too (:meth:`RecorderNode.take_from_bus`): it
serialises the message objects itself and ignores its DDS subscriptions of those topics, which
it keeps (the plant's ``wait_for_subscribers`` and acknowledgement waits see it as before). The
bus knows them as *served* (:meth:`LocalBus.subscribe` with ``node``), so an outlet publishes on
DDS only while a subscriber of another node exists (:meth:`LocalBus.outside`).

Answers thus arrive while the plant publishes, and the plant's loop no longer waits in the
executor. :class:`Drain` spins the executor from the loop every :data:`DRAIN_PERIOD` s of wall
time instead, so timers (run status), graph events and in-process DDS deliveries (a recorder's
raw subscriptions, the live view) keep flowing; their queues (``interface.QOS``, 40,000 messages
per per-step stream) hold many seconds of steps, far more than a period.

The sources' per-step diagnostics (excitation, PMA state: :meth:`LockstepSource.info_outlet`)
are outlets too: an in-process recorder takes them from the bus, DDS carries them only to
subscribers outside it.

What stays on DDS: the sources' force publishers (the plant's start-up and graph checks count
them; a force topic of an in-process source is served by the hand-off only), the controller
models, run status, and everything of nodes that are no lockstep source of the plant in this
process (an in-process recorder takes those over DDS). A composition on rclpy's own executors
(``PENTAPOD_EXECUTOR=single``) stays on DDS altogether (:func:`connect`).
"""
from __future__ import annotations

import os
import time
from typing import Callable

#: Wall time [s] between two drains of the executor by a composed plant's loop (a drain that
#: finds nothing to do costs about 60 us here).
DRAIN_PERIOD = 5e-3
#: Hidden topic (std_msgs/Empty) on which a composed plant marks the end of a drain.
DRAIN_TOPIC = '/_pentapod_drain_{pid}'
#: Longest wall time [s] one drain spins (a flood from outside cannot stall the loop).
DRAIN_LIMIT = 0.05
#: Wall time [s] between two checks of an outlet's DDS subscriber count (sources' outlets).
REFRESH_PERIOD = 0.25


class LocalBus:
    """The in-process subscribers of a composition: topic -> callbacks taking a message."""

    def __init__(self):
        self._callbacks: dict[str, list[Callable]] = {}
        self._served: dict[str, list] = {}

    def callbacks(self, topic: str) -> list[Callable]:
        """The (live) list of in-process callbacks of ``topic``."""
        return self._callbacks.setdefault(topic, [])

    def subscribe(self, topic: str, callback: Callable, node=None) -> None:
        """
        Deliver every message an outlet of ``topic`` publishes to ``callback``.

        ``node``: a node whose DDS subscriptions of ``topic`` this callback serves (they get
        nothing the callback does not get already; :meth:`outside` does not count them).
        """
        self.callbacks(topic).append(callback)
        if node is not None:
            self._served.setdefault(topic, []).append(node)

    def outside(self, topic: str) -> bool:
        """True if a DDS subscription of ``topic`` belongs to a node the bus does not serve."""
        served = self._served.get(topic)
        if not served:
            return True
        names = {(n.get_name(), n.get_namespace()) for n in served}
        return any((info.node_name, info.node_namespace) not in names
                   for info in served[0].get_subscriptions_info_by_topic(topic))


class Outlet:
    """
    A publisher whose in-process subscribers get each message object directly.

    Parameters
    ----------
    pub : rclpy.publisher.Publisher
        The DDS publisher of the topic.
    bus : LocalBus, optional
        The composition's bus; without one the outlet is the plain publisher. DDS
        subscriptions the bus serves (a recorder in the composition) do not count.
    always_remote : bool
        Without a bus: publish on DDS every time (True) or only while :meth:`refresh` saw a
        DDS subscriber (False, the plant's outputs). With a bus the outlet refreshes itself
        every :data:`REFRESH_PERIOD` s if nobody calls :meth:`refresh`.
    """

    __slots__ = ('pub', 'topic_name', 'local', 'bus', 'remote', 'dds_published', '_auto',
                 '_next')

    def __init__(self, pub, bus: LocalBus | None = None, always_remote: bool = False):
        self.pub = pub
        self.topic_name = pub.topic_name
        self.local = bus.callbacks(pub.topic_name) if bus is not None else []
        self.bus = bus
        self.remote = always_remote and bus is None
        self._auto = always_remote and bus is not None
        self._next = 0.0
        self.dds_published = 0          # messages that went out on DDS

    def attach(self, bus: LocalBus) -> None:
        """Hand this outlet's messages to the in-process callbacks of ``bus`` from now on."""
        self.local = bus.callbacks(self.topic_name)
        self.bus = bus
        if self.remote and not self._auto:      # was a plain publisher: now refreshed itself
            self._auto, self.remote = True, False

    def refresh(self) -> bool:
        """Note whether DDS has subscribers; True if anyone (DDS or in-process) listens."""
        self.remote = self.pub.get_subscription_count() > 0 and (
            self.bus is None or self.bus.outside(self.topic_name))
        self._next = time.monotonic() + REFRESH_PERIOD
        return self.remote or bool(self.local)

    def publish(self, msg) -> None:
        """Publish on DDS if subscribed there, then call each in-process callback with msg."""
        if self._auto and time.monotonic() > self._next:
            self.refresh()
        if self.remote:
            self.pub.publish(msg)
            self.dds_published += 1
        for callback in self.local:
            callback(msg)


class Drain:
    """
    Spins the executor from a loop that no longer waits in it, every ``period`` s.

    rclpy's EventsExecutor runs one event per ``spin_once`` and has no "nothing left" answer
    (an idle ``spin_once`` costs 50-80 us here), nor guard conditions; a one-shot timer as
    the end mark starved the node's other timers. So a drain publishes an empty message to
    itself on a hidden topic of this process (:data:`DRAIN_TOPIC`) and spins until it came
    back: the events queued before it ran first (a round costs about 60 us here); events DDS
    posts later are taken by the next drain (only the EventsExecutor is used so:
    :func:`connect`).
    """

    def __init__(self, node, period: float = DRAIN_PERIOD):
        from rclpy.qos import QoSProfile, ReliabilityPolicy
        from std_msgs.msg import Empty
        self.period = period
        self.drains = 0
        self._back = True
        self._next = 0.0
        self._mark = Empty()
        mark_qos = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE)
        topic = DRAIN_TOPIC.format(pid=os.getpid())
        self.pub = node.create_publisher(Empty, topic, mark_qos)
        self.sub = node.create_subscription(Empty, topic, self._came_back, mark_qos)

    def _came_back(self, _msg) -> None:
        self._back = True

    def ready(self) -> bool:
        """True once the mark's subscription is matched (a drain then runs every queued event)."""
        return self.pub.get_subscription_count() > 0

    def tick(self, executor) -> None:
        """Drain now if ``period`` s passed since the last drain."""
        now = time.monotonic()
        if now >= self._next:
            self._next = now + self.period
            self.drain(executor, now + DRAIN_LIMIT)

    def drain(self, executor, end: float) -> int:
        """
        Run what is queued in the executor now, until the mark is back or ``end`` [s].

        Returns the number of other events run (0: the executor had nothing queued).
        """
        self.drains += 1
        if not self.ready():                                  # not matched (yet): one event
            executor.spin_once(timeout_sec=0.0)
            return 1
        self._back = False
        self.pub.publish(self._mark)
        spins = 0
        while not self._back and time.monotonic() < end:
            executor.spin_once(timeout_sec=max(end - time.monotonic(), 0.0))
            spins += 1
        return spins - 1

    def flush(self, executor, limit: float) -> None:
        """Drain until a drain finds nothing queued, for at most ``limit`` [s]."""
        end = time.monotonic() + limit
        while self.drain(executor, end) > 0 and time.monotonic() < end:
            pass


def connect(plant, nodes, executor) -> LocalBus | None:
    """
    Hand the plant's outputs to its in-process sources and their answers to the plant.

    ``nodes`` are the nodes of the composition; those with ``use_bus`` whose ``source_name``
    is one of the plant's ``sources`` are connected, and those with ``take_from_bus`` (a
    recorder) take the topics of the outlets from the bus. Call before the nodes spin.
    Returns the bus, or None if no source is in-process or ``executor`` is one of rclpy's own
    executors (``PENTAPOD_EXECUTOR=single``): those take one message per subscription per
    wait, so a drain could not keep up with a recorder; such a composition stays on DDS.
    """
    candidates = [n for n in nodes if n is not plant and hasattr(n, 'use_bus')]
    names = plant.own_sources([n.source_name for n in candidates])
    sources = [n for n in candidates if n.source_name in names]
    if not sources or hasattr(executor, 'wait_for_ready_callbacks'):
        return None
    bus = LocalBus()
    plant.join_bus(bus, names, [o for s in sources for o in s.outlets()])
    for source in sources:
        source.use_bus(bus)
    topics = {o.topic_name: o.pub.msg_type
              for o in plant.outlets() + [o for s in sources for o in s.outlets()]}
    for node in nodes:
        if hasattr(node, 'take_from_bus'):
            node.take_from_bus(bus, topics)
    return bus
