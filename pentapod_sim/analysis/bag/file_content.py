"""
What one MCAP file of a bag yielded: channels, message segments, metadata and damage.

Both MCAP readers (the fast one in :mod:`pentapod_sim.analysis.bag.mcap_scan`, the fallback on the
public ``mcap.reader`` API in :mod:`pentapod_sim.analysis.bag.mcap_public`) fill a
:class:`FileContent`; the bag merges it only when the file was read to its end, so a reader
that gives up half-way leaves nothing behind. A damaged or missing part of a file is a
:class:`Damage` entry (where, why, which topics, which log-time span, how many messages lost),
never an exception: only a file with nothing readable raises :class:`UnreadableBagError`.
"""
from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any, Optional, TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from pentapod_sim.errors import BagError

if TYPE_CHECKING:       # the fast reader gets the class at run time (mcap_chunks.internals)
    from mcap.records import Schema

Bytes = npt.NDArray[np.uint8]
Int64s = npt.NDArray[np.int64]
#: messages data[starts[i]:starts[i] + lengths[i]] of one chunk
Segment = tuple[Bytes, Int64s, Int64s]


class UnreadableBagError(BagError):
    """Nothing of a bag (or of one of its files) could be read."""


class BagDamageWarning(UserWarning):
    """A bag is damaged or truncated; its readable part was loaded (see ``Bag.damage``)."""


class McapInternalsWarning(UserWarning):
    """The fast reader's mcap internals are missing or changed: reading with ``mcap.reader``."""


@dataclasses.dataclass
class Damage:
    """
    One damaged or missing part of an MCAP file.

    Attributes
    ----------
    file : str
        File name.
    offset : int
        Byte offset of the damaged record (or of the cut) in the file.
    reason : str
        What is wrong, e.g. ``'chunk CRC mismatch'``.
    start_ns, end_ns : int or None
        Log-time span [ns] of the lost messages (chunk index or chunk header), if known.
    lost : dict or None
        ``{topic: messages lost}``; ``{}`` when no message was lost (e.g. a damaged summary
        section whose data section was read in full), None when unknown.
    topics : tuple of str
        Topics with messages in the damaged part (known even when ``lost`` is not).
    """

    file: str
    offset: int
    reason: str
    start_ns: Optional[int] = None
    end_ns: Optional[int] = None
    lost: Optional[dict[str, int]] = None
    topics: tuple[str, ...] = ()

    @property
    def messages_lost(self) -> Optional[int]:
        """Messages lost in this part (None: unknown)."""
        return None if self.lost is None else sum(self.lost.values())

    def describe(self) -> str:
        """One line for people: where, why, what was lost."""
        if self.lost is None:
            loss = 'an unknown number of messages lost'
        elif not self.lost:
            loss = 'no message lost'
        else:
            per_topic = ', '.join(f'{t}: {n}' for t, n in sorted(self.lost.items()))
            loss = f'{self.messages_lost} messages lost ({per_topic})'
        topics = sorted(set(self.topics) | set(self.lost or {}))
        if self.lost is None and topics:
            loss += f' on {", ".join(topics)}'
        span = ''
        if self.start_ns is not None and self.end_ns is not None:
            span = f'; log time {self.start_ns * 1e-9:.6f} .. {self.end_ns * 1e-9:.6f} s'
        return f'{self.file} at byte {self.offset}: {self.reason}; {loss}{span}'


@dataclasses.dataclass
class ChannelInfo:
    """Topic and schema (an mcap Schema record, or None) of one MCAP channel."""

    topic: str
    schema: Optional[Schema] = None

    @property
    def msg_type(self) -> str:
        """Message type, e.g. ``'sensor_msgs/msg/JointState'`` (``''`` without schema)."""
        return self.schema.name if self.schema is not None else ''

    @property
    def schema_text(self) -> str:
        """Message definition (``''`` without schema)."""
        return self.schema.data.decode('utf-8', 'replace') if self.schema is not None else ''


class FileContent:
    """
    Collects what a reader found in one file.

    Parameters
    ----------
    path : Path
        The file.
    wanted : set of str or None
        Topics whose messages are kept (None: all); the others are listed without messages.
    """

    def __init__(self, path: Path, wanted: Optional[set[str]]) -> None:
        self.path = Path(path)
        self.wanted = wanted
        self.schemas: dict[int, Schema] = {}          # schema id -> mcap Schema record
        self.channels: dict[int, ChannelInfo] = {}    # channel id -> ChannelInfo
        #: topic -> [(data, starts, lengths, log times)]
        self.segments: dict[str, list[tuple[Bytes, Int64s, Int64s, Int64s]]] = {}
        #: topic -> ([payload], [log time])
        self.loose: dict[str, tuple[list[bytes], list[int]]] = {}
        #: channel id without a Channel record -> messages seen
        self.orphans: dict[int, int] = {}
        self.metadata: dict[str, dict[str, str]] = {}
        self.damage: list[Damage] = []
        self.truncated = False
        self.reader = 'fast'
        #: {topic: messages} the file says it holds (summary statistics), if trustworthy
        self.expected: Optional[dict[str, int]] = None

    def add_channel(self, channel_id: int, topic: str, schema_id: int) -> None:
        """Register a channel (a repeated registration keeps the first)."""
        self.channels.setdefault(int(channel_id), ChannelInfo(topic, self.schemas.get(schema_id)))

    def _keeps(self, channel_id: int) -> bool:
        info = self.channels.get(channel_id)
        return info is not None and (self.wanted is None or info.topic in self.wanted)

    def add_chunk(self, data: Bytes, channel_ids: Int64s, times: Int64s, starts: Int64s,
                  lengths: Int64s) -> None:
        """Add the messages of one verified chunk (views into ``data``)."""
        for channel_id in np.unique(channel_ids).tolist():
            mine = channel_ids == channel_id
            if channel_id not in self.channels:
                self.orphans[channel_id] = self.orphans.get(channel_id, 0) + int(mine.sum())
                continue
            if not self._keeps(channel_id):
                continue
            segment = (data, starts[mine], lengths[mine])
            if self.wanted is not None:
                segment = compact(*segment)  # do not keep the whole chunk alive
            topic = self.channels[channel_id].topic
            self.segments.setdefault(topic, []).append((*segment, times[mine]))

    def add_message(self, channel_id: int, payload: bytes, log_time_ns: int) -> None:
        """Add one message read on its own (unchunked file or the fallback reader)."""
        if channel_id not in self.channels:
            self.orphans[channel_id] = self.orphans.get(channel_id, 0) + 1
        elif self._keeps(channel_id):
            payloads, times = self.loose.setdefault(self.channels[channel_id].topic, ([], []))
            payloads.append(payload)
            times.append(log_time_ns)

    def topic_of(self, channel_id: int) -> str:
        """Topic of a channel id, or ``'channel N'`` if its Channel record was lost."""
        info = self.channels.get(int(channel_id))
        return info.topic if info else f'channel {int(channel_id)}'

    def counts(self) -> dict[str, int]:
        """``{topic: messages read}`` (kept topics only)."""
        out = {topic: sum(len(s[1]) for s in segments)
               for topic, segments in self.segments.items()}
        for topic, (payloads, _) in self.loose.items():
            out[topic] = out.get(topic, 0) + len(payloads)
        return out

    @property
    def message_count(self) -> int:
        """Messages read (kept topics only)."""
        return sum(self.counts().values())

    def report(self, offset: int, reason: str, **fields: Any) -> Damage:
        """Record one damaged part; return it (its loss may be filled in later)."""
        damage = Damage(self.path.name, int(offset), reason, **fields)
        self.damage.append(damage)
        return damage

    def finish(self) -> None:
        """Report messages on channels without a Channel record (it was in a lost chunk)."""
        if self.orphans:
            lost = {f'channel {k}': n for k, n in self.orphans.items()}
            self.report(0, 'messages on channels whose Channel record was in a damaged part',
                        lost=lost)
        if self.expected is not None:
            reconcile(self.damage, self.expected, self.counts(), self.wanted,
                      self.path.name, 'the summary statistics')


def reconcile(damage: list[Damage], expected: dict[str, int], read: dict[str, int],
              wanted: Optional[set[str]], file: str, source: str) -> None:
    """
    Explain every message that ``expected`` lists and the readers did not return.

    Per topic, missing = expected - read - losses already attributed. The missing messages go
    to the one damage entry of unknown loss if there is exactly one (a cut chunk, a cut file),
    else to a new entry naming ``source``.
    """
    missing = {}
    for topic, count in expected.items():
        if wanted is not None and topic not in wanted:
            continue
        attributed = sum((d.lost or {}).get(topic, 0) for d in damage)
        if count - read.get(topic, 0) - attributed > 0:
            missing[topic] = count - read.get(topic, 0) - attributed
    unknown = [d for d in damage if d.lost is None]
    if len(unknown) == 1:
        unknown[0].lost = missing
    elif missing:
        damage.append(Damage(file, 0, f'{source} list messages that no intact part holds',
                             lost=missing))


def compact(data: Bytes, starts: Int64s, lengths: Int64s) -> Segment:
    """Copy the given messages of a chunk into a new contiguous array; return a segment."""
    ends = np.cumsum(lengths)
    new_starts = ends - lengths
    positions = np.arange(int(ends[-1]) if len(ends) else 0) + np.repeat(starts - new_starts,
                                                                          lengths)
    return data[positions], new_starts, lengths
