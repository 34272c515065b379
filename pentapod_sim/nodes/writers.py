"""
One writer per topic: the publishers of the topics a node reads, identified by DDS, not by name.

A node name is whatever a participant chooses to call itself; the GUID of a DDS endpoint is
assigned by DDS. Its first 12 bytes (the GUID prefix) name the participant, which in ROS 2 is
one per process (one per rclpy context); for Fast DDS (vendor 01.0f) bytes 2-3 are the host id
(derived from the host's addresses) and bytes 4-5 the low 16 bits of the process id. rclpy's
graph gives the GUID of each publisher as ``TopicEndpointInfo.endpoint_gid``
(:meth:`rclpy.node.Node.get_publishers_info_by_topic`).

:class:`WriterCheck` keeps the rule for the topics a node reads, in two ways:

* **per message**: the subscription's count of *matched* publishers
  (``Subscription.get_publisher_count``, kept by the DDS reader) must be at most one. DDS
  delivers no sample of a writer the reader has not matched, so a message taken while the count
  is one comes from the one writer matched; while it is more, every message of the topic is
  refused (:meth:`WriterCheck.message_ok`). This is the per-message writer check rclpy allows:
  its ``MessageInfo`` (Jazzy, rclpy 7.1.6) carries no publisher GID, though rmw has it, and the
  EventsExecutor fails on callbacks that ask for the message info at all.
* **periodically** (every :data:`CHECK_PERIOD` s of wall time, and before a node's first step):
  the graph's publishers of each topic. A second writer stops the run with a RunError naming
  every writer by participant, host and claimed node name (:meth:`WriterCheck.check`); the
  writer first seen is pinned, so one that replaced it between two checks is refused too. A
  writer that left unpins its topic (a new plant run by a new process is a new writer).

So a foreign message is refused from the moment DDS matched its writer; what could pass is a
sample that arrives between the reader's match of the writer and the update of its matched
count (microseconds), or the samples of a writer that replaced the pinned one in the same
instant, for at most one check period.
"""
from __future__ import annotations

from dataclasses import dataclass
import time
from typing import Iterable

from pentapod_sim.errors import RunError

#: Wall time [s] between two graph checks of the publishers.
CHECK_PERIOD = 0.25
#: Wall time [s] a second writer matched by DDS may stay absent from the graph (no name yet)
#: before the run is stopped anyway, naming the writers the graph does show.
GRAPH_LAG = 1.0
#: DDS vendor ids (the first two bytes of a GUID prefix) of the common RMW implementations.
VENDORS = {b'\x01\x0f': 'Fast DDS', b'\x01\x10': 'Cyclone DDS', b'\x01\x01': 'Connext DDS'}
_UNKNOWN = '_NODE_NAME_UNKNOWN_'


@dataclass(frozen=True)
class Writer:
    """
    One publisher endpoint of the ROS graph.

    Attributes
    ----------
    gid : bytes
        The endpoint's GUID as rmw gives it (16 bytes in Jazzy: prefix + entity id).
    node : str
        The node name it claims ('' while undiscovered); anyone can claim any name.
    """

    gid: bytes
    node: str = ''

    @classmethod
    def of(cls, info) -> Writer:
        """The writer of a ``TopicEndpointInfo``."""
        name = '' if info.node_name == _UNKNOWN else (
            f'{info.node_namespace.rstrip("/")}/{info.node_name}')
        return cls(bytes(info.endpoint_gid), name)

    @property
    def participant(self) -> bytes:
        """The 12-byte GUID prefix: the DDS participant (in ROS 2, the process)."""
        return self.gid[:12]

    def host(self) -> str:
        """What the GUID tells about the host and process (Fast DDS), else the vendor only."""
        vendor = VENDORS.get(self.gid[:2])
        if vendor == 'Fast DDS' and len(self.gid) >= 6:
            return (f'Fast DDS host id {self.gid[2:4].hex()}, process id '
                    f'{int.from_bytes(self.gid[4:6], "little")} (low 16 bits)')
        return vendor or f'vendor {self.gid[:2].hex(".")}'

    def describe(self) -> str:
        """``participant 01.0f.78... (Fast DDS host id 78fd, process id 29691 ...; node /x)``."""
        return (f'participant {self.participant.hex(".")} ({self.host()}; '
                f'{"node " + self.node if self.node else "node name not yet discovered"})')


def participant_of(info) -> bytes:
    """The DDS participant (12-byte GUID prefix) of a graph endpoint (``TopicEndpointInfo``)."""
    return bytes(info.endpoint_gid[:12])


def writers_text(writers: Iterable[Writer]) -> str:
    """Every writer described, separated by '; '."""
    return '; '.join(w.describe() for w in writers)


def second_writer(topic: str, writers: list[Writer]) -> str:
    """The refusal of a topic with several writers, naming each by participant and host."""
    return (f'{topic} has {len(writers)} writers, one is allowed: {writers_text(writers)}; '
            'a second participant is publishing on it (docs/interface.md, "One writer per '
            'topic")')


class WriterCheck:
    """
    One writer per topic for the topics a node reads (see the module docstring).

    Parameters
    ----------
    node : rclpy.node.Node
        Answers the graph queries.
    period : float
        Wall time [s] between graph checks (:meth:`due`).
    """

    def __init__(self, node, period: float = CHECK_PERIOD):
        self.node, self.period = node, period
        self.topics: list[str] = []
        self.shared: set[str] = set()            # topics where several writers are allowed
        self.pinned: dict[str, Writer] = {}
        self.suspect: dict[str, float] = {}      # topic -> when DDS matched a second writer
        self.seen: dict[str, dict[bytes, Writer]] = {}   # every writer seen, per topic
        self.refused: dict[str, int] = {}        # topic -> messages refused per message check
        self.next_check = 0.0

    def watch(self, topic: str, shared: bool = False) -> None:
        """Check the writers of ``topic`` (``shared``: several allowed, only recorded)."""
        if topic not in self.topics:
            self.topics.append(topic)
        if shared:
            self.shared.add(topic)

    def message_ok(self, topic: str, sub) -> bool:
        """
        True if a message of ``topic`` just taken from ``sub`` may be used.

        False (the message is refused, counted) while the subscription has more than one
        matched publisher on a topic that allows one; :meth:`check` then stops the run.
        """
        if topic in self.shared or sub.get_publisher_count() <= 1:
            if self.suspect:
                self.suspect.pop(topic, None)   # a second writer that left again
            return True
        self.suspect.setdefault(topic, time.monotonic())
        self.refused[topic] = self.refused.get(topic, 0) + 1
        return False

    def note_matched(self, topic: str, sub) -> None:
        """Suspect ``topic`` if ``sub`` matched more than one writer (no message taken)."""
        if topic not in self.shared and sub.get_publisher_count() > 1:
            self.suspect.setdefault(topic, time.monotonic())

    def due(self) -> bool:
        """True when the graph should be checked again (every ``period`` s, or suspected)."""
        return bool(self.suspect) or time.monotonic() >= self.next_check

    def check(self) -> dict[str, list[Writer]]:
        """
        Check every watched topic's publishers in the graph; return them, per topic.

        Raises
        ------
        RunError
            A topic that allows one writer has two or more, or its writer changed, or DDS
            matched a second writer that the graph has not shown for :data:`GRAPH_LAG` s.
        """
        self.next_check = time.monotonic() + self.period
        return {topic: self._check(topic) for topic in self.topics}

    def check_each(self, final: bool = False) -> dict[str, str]:
        """
        Like :meth:`check`, but every topic: topic -> the refusal, for those refused.

        ``final``: the last check (nothing comes after it), so a second writer DDS matched is
        refused at once, without waiting :data:`GRAPH_LAG` s for the graph to show it.
        """
        self.next_check = time.monotonic() + self.period
        refused = {}
        for topic in self.topics:
            try:
                self._check(topic, lag=0.0 if final else GRAPH_LAG)
            except RunError as err:
                refused[topic] = str(err)
        return refused

    def _check(self, topic: str, lag: float = GRAPH_LAG) -> list[Writer]:
        """The writers of one topic in the graph (RunError: see :meth:`check`)."""
        now = time.monotonic()
        writers = [Writer.of(i) for i in self.node.get_publishers_info_by_topic(topic)]
        seen = self.seen.setdefault(topic, {})
        for w in writers:
            if w.gid not in seen or (w.node and not seen[w.gid].node):
                seen[w.gid] = w
        if topic in self.shared:
            return writers
        if len(writers) > 1:
            raise RunError(second_writer(topic, writers))
        since = self.suspect.get(topic)
        if since is not None and now - since >= lag:
            raise RunError(f'{topic}: DDS matched a second writer ({self.refused.get(topic, 0)} '
                           'message(s) refused) that has not appeared in the ROS graph '
                           f'within {now - since:.2g} s; known writer: '
                           f'{writers_text(writers) or "none"}')
        if not writers:
            self.pinned.pop(topic, None)      # it left: a new writer may take its place
            return writers
        pinned = self.pinned.setdefault(topic, writers[0])
        if pinned.gid != writers[0].gid:
            raise RunError(f'{topic}: its writer changed between two checks, from '
                           f'{pinned.describe()} to {writers[0].describe()}; one writer '
                           'per topic')
        return writers

    def foreign(self) -> dict[str, list[Writer]]:
        """Topics (allowing one writer) on which more than one writer was seen, with them all."""
        return {t: list(w.values()) for t, w in self.seen.items()
                if t not in self.shared and len(w) > 1}
