"""
The plant node's per-step outputs: /clock, the state topics, the full-rate topic, display batches.

Each topic is published only while someone listens (publishing a state topic costs tens of
microseconds): :meth:`PlantOutputs.refresh` notes the subscribers, at the latest every
:data:`REFRESH_PERIOD` s of a run. In a composition the in-process sources get the messages
through the outlets directly (:mod:`pentapod_sim.nodes.local_bus`). Before a run the plant
waits here for the nodes of ``wait_for_subscribers``; after it, for every subscriber's
acknowledgement of every message.
"""
from __future__ import annotations

import array
import time

import numpy as np
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState

from pentapod_sim import shutdown
from pentapod_sim.errors import RunError
from pentapod_sim.interface import CLOCK, stamp_ns, state_layouts
from pentapod_sim.nodes.common import set_stamp, spin_until, STATE_QOS, subscribers_of
from pentapod_sim.nodes.fullrate import FullRateOutputs
from pentapod_sim.nodes.local_bus import LocalBus, Outlet
from pentapod_sim.topic_layout import TopicLayout

#: Wall time [s] between two looks at the output topics' subscribers during a run.
REFRESH_PERIOD = 0.25


class PlantOutputs:
    """
    The plant's output publishers and their pre-built messages.

    Parameters
    ----------
    node : rclpy.node.Node
        The plant node (creates the publishers, answers the graph queries).
    core : DiscretePlant or MultiRatePlant
        The plant core (output names, dt, substeps).
    mixer : ForceMixer
        The plant's force mixer (display batches of the forces).
    display_period : float
        Simulated time per display batch [s].
    """

    def __init__(self, node, core, mixer, display_period: float):
        self.node = node
        self.dt = core.dt
        self.clock = Outlet(node.create_publisher(Clock, CLOCK, STATE_QOS))
        self.layouts = state_layouts(core.output_names)
        self.states: list[tuple[Outlet, TopicLayout]] = [
            (Outlet(node.create_publisher(JointState, lay.topic, STATE_QOS)), lay)
            for lay in self.layouts]
        self.fullrate = FullRateOutputs(node, core, mixer, display_period)
        # one message per topic, refilled every step: building a JointState costs several us
        # (rosidl's checks of every joint name), refilling its arrays and stamp about 1 us;
        # publishing serialises it and in-process callbacks must not keep it (.local_bus)
        self.clock_msg = Clock()
        self.state_msgs = {lay.topic: JointState(name=lay.joints) for lay in self.layouts}
        self.active: list[tuple[Outlet, TopicLayout]] = []    # state topics with a listener
        self.clock_active = False
        self.next_refresh = 0.0
        # a composition's in-process sources' DDS publishers (force answers, diagnostics):
        # matched before step 0 and acknowledged at the end like the plant's own
        self.companions: list = []

    def outlets(self) -> list[Outlet]:
        """The per-step outlets with in-process hand-off (/clock, the state topics)."""
        return [self.clock] + [out for out, _ in self.states]

    def attach(self, bus: LocalBus, companions=()) -> None:
        """
        Hand every outlet's messages to the in-process callbacks of ``bus`` (composed).

        ``companions``: the outlets of the sources in the composition. Their DDS publishers
        write only while a subscriber outside is matched, so a subscriber that is not matched
        yet at step 0 would never get the first steps: :meth:`wait_for_subscribers` waits for
        those matches too, and the end of the run for their acknowledgements
        (:meth:`acknowledged_publishers`).
        """
        for outlet in self.outlets():
            outlet.attach(bus)
        self.companions = [outlet.pub for outlet in companions]

    def topics(self) -> list[str]:
        """Every topic published each step: /clock, the state topics, the full-rate one."""
        return [out.topic_name for out in self.outlets()] + self.fullrate.topics()

    def active_topics(self) -> list[str]:
        """The per-step topics published now (someone listens)."""
        return (([self.clock.topic_name] if self.clock_active else [])
                + [out.topic_name for out, _ in self.active] + self.fullrate.active_topics())

    def publishers(self) -> list:
        """Every output publisher (subscriber waits, acknowledgements)."""
        return [out.pub for out in self.outlets()] + self.fullrate.publishers()

    def acknowledged_publishers(self) -> list:
        """The publishers whose messages are acknowledged before the plant's process ends."""
        return self.publishers() + self.companions

    def due(self) -> bool:
        """True when the subscribers should be looked up again (every REFRESH_PERIOD s)."""
        return time.monotonic() > self.next_refresh

    def refresh(self) -> None:
        """Note which topics have subscribers (DDS or in-process)."""
        self.active = [(out, lay) for out, lay in self.states if out.refresh()]
        self.clock_active = self.clock.refresh()
        self.fullrate.refresh()
        self.next_refresh = time.monotonic() + REFRESH_PERIOD

    def publish(self, k: int, y: np.ndarray) -> None:
        """Publish /clock and the state topics of step k (those with subscribers)."""
        ns = stamp_ns(k, self.dt)
        if self.clock_active:
            set_stamp(self.clock_msg.clock, ns)
            self.clock.publish(self.clock_msg)
        for out, lay in self.active:
            pos, vel, eff = lay.values(y)
            msg = self.state_msgs[lay.topic]
            msg.position = array.array('d', pos.tobytes())
            msg.velocity = array.array('d', vel.tobytes())
            if lay.has_effort:      # else the empty array the message was built with
                msg.effort = array.array('d', eff.tobytes())
            set_stamp(msg.header.stamp, ns)
            out.publish(msg)

    def record(self, k: int, y: np.ndarray, u: np.ndarray, trace) -> None:
        """Step k to the trace, the full-rate topic and the display batches."""
        self.fullrate.record(k, y, u, trace)

    def flush(self) -> None:
        """Publish the open display batch (the run ended)."""
        self.fullrate.flush()

    def dds_published(self) -> dict[str, int]:
        """Topic -> messages that went out on DDS (the in-process hand-off not counted)."""
        return {out.topic_name: out.dds_published for out in self.outlets()}

    def display_batches(self) -> tuple[list, int]:
        """The display-batch publishers and the number of batches published."""
        return self.fullrate.display_batches()

    def wait_for_subscribers(self, executor, wanted: list[str], timeout: float,
                             settle: float) -> None:
        """
        Wait until each node of ``wanted`` subscribes to an output topic, all matched.

        Output topics are the plant's and, in a composition, its sources' (``companions``).

        Then spin ``settle`` seconds more, so that the node's other subscriptions (to this
        plant and to the sources) are matched too: a recorder started with the run thus
        receives step 0. RunError names a node that did not appear within ``timeout`` s. A
        stop signal ends the wait at once.
        """
        if not wanted:
            return
        pubs = self.publishers()

        def missing() -> list[str]:
            seen, unmatched = set(), []
            for pub in pubs + self.companions:
                names, matched = subscribers_of(self.node, pub)
                seen |= names
                if not matched:
                    unmatched.append(pub.topic_name)
            return [n for n in wanted if n not in seen] + [f'match on {t}' for t in unmatched]
        self.node.get_logger().info(f'waiting for subscriber node(s) {", ".join(wanted)} '
                                    f'(startup_timeout = {timeout} s)')
        if not spin_until(executor, lambda: not missing() or shutdown.requested(), timeout):
            raise RunError(f'subscriber node(s) {", ".join(missing())} did not appear within '
                           f'startup_timeout = {timeout} s')
        spin_until(executor, shutdown.requested, settle)
