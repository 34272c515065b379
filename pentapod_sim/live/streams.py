"""
One subscribed topic of the live view: raw CDR in, deduplicated samples and envelopes out.

The node's subscriptions are polled by the live view's worker thread, which hands every message
to :meth:`TopicStream.offer` (append the bytes, count the messages lost before it or a drop when
the backlog is full); once per pass the worker takes the backlog, decodes it in one
vectorised pass (:mod:`pentapod_sim.analysis.bag.cdr_arrays`), drops the copies of a step that a
lockstep plant re-sends while it waits, notices a new run (stamps going back) and feeds the
envelope downsampler. Supported types: sensor_msgs/JointState (columns: the joints' position,
then velocity, then effort values, for the fields the messages carry) and
geometry_msgs/WrenchStamped (force x, y, z, torque x, y, z).

A :class:`BatchStream` gets a state or force topic from the plant's display batches
(:mod:`pentapod_sim.nodes.display_batch`: M steps per JointState, joints ``<joint>@j``) and
unpacks them into the per-step samples the topic carries, stamps included, so the rest of the
view cannot tell the two apart.
"""
from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field
import struct

import numpy as np
import numpy.typing as npt

from pentapod_sim import interface
from pentapod_sim.analysis.bag.cdr_arrays import (
    joint_state_arrays,
    JOINT_STATE_FIELDS,
    joint_state_layout,
    stamps_ns,
    wrench_arrays,
)
from pentapod_sim.errors import BagError
from pentapod_sim.interface import step_of
from pentapod_sim.live.envelope import EnvelopeDownsampler, Sample
from pentapod_sim.topic_layout import split_batch_name

#: Message types the live view downsamples.
SUPPORTED_TYPES = (interface.JOINT_STATE, interface.WRENCH_STAMPED)
HEADER_FRAME_OFFSET = 12  # CDR header (4) + stamp (8): the frame_id string length
BATCH_STAMP = struct.Struct('<iI')  # header.stamp (sec, nanosec) after the CDR header


def frame_id(data: bytes) -> str:
    """The header.frame_id of a serialised message that starts with a std_msgs/Header."""
    (length,) = struct.unpack_from('<I', data, HEADER_FRAME_OFFSET)
    start = HEADER_FRAME_OFFSET + 4
    return bytes(data[start:start + max(length - 1, 0)]).decode('utf-8')


@dataclass
class Shape:
    """What a display message of the topic holds besides the values."""

    frame_id: str = ''
    names: list[str] = field(default_factory=list)         # JointState joints
    fields: list[tuple[str, int]] = field(default_factory=list)  # (field, count) in order

    def split(self, row: npt.NDArray[np.float64]) -> dict[str, list[float]]:
        """Cut a value row back into JointState fields (absent fields: empty lists)."""
        out: dict[str, list[float]] = {f: [] for f in JOINT_STATE_FIELDS}
        start = 0
        for name, count in self.fields:
            out[name] = row[start:start + count].tolist()
            start += count
        return out


@dataclass
class Batch:
    """What the worker made of one backlog."""

    samples: tuple[npt.NDArray[np.int64], npt.NDArray[np.float64]]  # new, deduplicated
    display: list[Sample]                                            # envelope samples
    new_run: bool = False


class TopicStream:
    """
    Backlog, decoder and envelope of one topic.

    Parameters
    ----------
    topic, msg_type : str
        Topic name and type (one of :data:`SUPPORTED_TYPES`).
    period_ns : int
        Envelope window [ns of simulated time].
    backlog : int
        Messages held for the worker at most; more are dropped and counted.
    """

    def __init__(self, topic: str, msg_type: str, period_ns: int, backlog: int):
        if msg_type not in SUPPORTED_TYPES:
            raise ValueError(f'live view cannot downsample {topic} [{msg_type}]')
        self.topic, self.msg_type = topic, msg_type
        self.queue: deque[bytes] = deque()
        self.backlog = backlog
        self.dropped = 0          # lost: backlog full or never delivered (sequence gaps)
        self.rejected = 0         # could not be decoded
        self.sequence: int | None = None
        self.shape: Shape | None = None
        self.last_stamp = -1
        self.envelope = EnvelopeDownsampler(period_ns)

    def offer(self, data: bytes, sequence: int | None = None) -> None:
        """
        Queue one message (constant time, never blocks).

        ``sequence`` is the publisher's sequence number of the message (1, 2, ...), if known:
        a gap counts the messages that never arrived in ``dropped`` (one publisher per topic;
        a number that does not grow means a new publisher).
        """
        if sequence is not None:
            if self.sequence is not None and sequence > self.sequence + 1:
                self.dropped += sequence - self.sequence - 1
            self.sequence = sequence
        if len(self.queue) >= self.backlog:
            self.dropped += 1
            return
        self.queue.append(data)

    def take(self) -> list[bytes]:
        """Everything queued so far (worker thread)."""
        return [self.queue.popleft() for _ in range(len(self.queue))]

    def _shape_of(self, data: bytes) -> Shape:
        if self.msg_type == interface.WRENCH_STAMPED:
            return Shape(frame_id(data))
        layout = joint_state_layout(data)
        fields = [(f, count) for f, (_, count) in layout.arrays.items() if count]
        return Shape(frame_id(data), list(layout.names), fields)

    def decode(self, batch: list[bytes]) -> tuple[npt.NDArray[np.int64],
                                                  npt.NDArray[np.float64]]:
        """Stamps [ns] and value rows of a batch; messages of another layout are rejected."""
        if self.shape is None:
            self.shape = self._shape_of(batch[0])
        stamps = stamps_ns(batch)
        if self.msg_type == interface.WRENCH_STAMPED:
            return stamps, wrench_arrays(batch)
        names, values = joint_state_arrays(batch)
        missing = [n for n in self.shape.names if n not in names]
        if missing:
            raise BagError(f'{self.topic}: joints {missing} missing')
        cols = [names.index(n) for n in self.shape.names]
        parts = [values[f][:, cols] for f, _ in self.shape.fields]
        return stamps, (np.hstack(parts) if parts else np.zeros((len(batch), 0)))

    def process(self, batch: list[bytes]) -> list[Batch]:
        """
        Decode a backlog and run it through the envelope.

        Returns one :class:`Batch` per run the backlog touches: when the stamps go back (the
        plant started a new run) the old run's open window is emitted and a new run begins.
        A backlog that cannot be decoded is counted in ``rejected`` and skipped.
        """
        if not batch:
            return []
        try:
            stamps, rows = self.decode(batch)
        except (BagError, struct.error, UnicodeDecodeError):
            self.rejected += len(batch)
            return []
        out, new_run = [], False
        while len(stamps):
            before = np.maximum.accumulate(np.concatenate([[self.last_stamp], stamps]))[:-1]
            back = np.flatnonzero(stamps < before)
            end = int(back[0]) if len(back) else len(stamps)
            if end == 0:                           # stamps went back: a new run
                out.append(Batch((stamps[:0], rows[:0]), self.envelope.flush()))
                self.reset()
                new_run = True
                continue
            fresh = stamps[:end] > before[:end]    # drop re-sent copies of a step
            t, v = stamps[:end][fresh], rows[:end][fresh]
            if len(t):
                self.last_stamp = int(t[-1])
            out.append(Batch((t, v), self.envelope.add(t, v), new_run))
            new_run = False
            stamps, rows = stamps[end:], rows[end:]
        return out

    def flush(self) -> list[Sample]:
        """Emit the open envelope window (the topic went quiet)."""
        return self.envelope.flush()

    def reset(self) -> None:
        """Forget the run: envelope window and newest stamp."""
        self.envelope.reset()
        self.last_stamp = -1


@dataclass
class BatchLayout:
    """One layout of display-batch messages: where their values are and what they mean."""

    length: int                          # message bytes
    structure: npt.NDArray[np.intp]      # bytes that define the layout
    reference: npt.NDArray[np.uint8]     # their values
    dt: float                            # step [s] (header.frame_id)
    joints: list[str]                    # per-step joints
    samples: int                         # steps per message
    fields: list[tuple[str, int]]        # (field, byte offset), fields present


class BatchStream(TopicStream):
    """
    A per-step topic served from the plant's display batches of it.

    ``topic`` is the per-step topic (the channel name); the node subscribes to its display
    batch topic (:func:`pentapod_sim.interface.display_batch_topic`) and offers those
    messages. Decoding yields the per-step stamps and values; a lost batch counts its samples
    in ``dropped``. Served messages have an empty frame_id, as the plant's state messages and
    the sources' force messages have.
    """

    def __init__(self, topic: str, msg_type: str, period_ns: int, backlog: int):
        super().__init__(topic, msg_type, period_ns, backlog)
        self.samples = 1                  # steps per message, as last decoded
        self._layout: BatchLayout | None = None

    def offer(self, data: bytes, sequence: int | None = None) -> None:
        """Queue one batch; lost or dropped batches count their steps in ``dropped``."""
        if sequence is not None:
            if self.sequence is not None and sequence > self.sequence + 1:
                self.dropped += (sequence - self.sequence - 1) * self.samples
            self.sequence = sequence
        if len(self.queue) >= self.backlog:
            self.dropped += self.samples
            return
        self.queue.append(data)

    def _parse(self, data: bytes) -> BatchLayout:
        """The layout of one batch (BagError if it is none)."""
        lay = self._layout
        if (lay is not None and len(data) == lay.length and np.array_equal(
                np.frombuffer(data, dtype=np.uint8)[lay.structure], lay.reference)):
            return lay
        parsed = joint_state_layout(data)
        names = parsed.names
        try:
            dt = float(frame_id(data))
            split = [split_batch_name(n) for n in names]
        except ValueError as err:
            raise BagError(f'{self.topic}: not a display batch: {err}') from None
        joints = [j for j, sample in split if sample == 0]
        samples = len(names) // max(len(joints), 1)
        if not joints or names != [f'{j}@{s}' for s in range(samples) for j in joints]:
            raise BagError(f'{self.topic}: joints {names[:4]}... are no display batch')
        fields = [(f, offset) for f, (offset, count) in parsed.arrays.items() if count]
        if any(parsed.arrays[f][1] != len(names) for f, _ in fields) or not dt > 0:
            raise BagError(f'{self.topic}: malformed display batch')
        structure = parsed.structure
        lay = self._layout = BatchLayout(len(data), structure,
                                         np.frombuffer(data, dtype=np.uint8)[structure].copy(),
                                         dt, joints, samples, fields)
        return lay

    def decode(self, batch: list[bytes]) -> tuple[npt.NDArray[np.int64],
                                                  npt.NDArray[np.float64]]:
        """Per-step stamps [ns] and value rows of a backlog of batches."""
        all_stamps, all_rows = [], []
        for data in batch:
            sec, nanosec = BATCH_STAMP.unpack_from(data, 4)
            lay = self._parse(data)
            if self.shape is None:
                self.shape = Shape('', list(lay.joints),
                                   [(f, len(lay.joints)) for f, _ in lay.fields])
            elif lay.joints != self.shape.names or [f for f, _ in lay.fields] != [
                    f for f, _ in self.shape.fields]:
                raise BagError(f'{self.topic}: batch joints {lay.joints} differ from '
                               f'{self.shape.names}')
            self.samples = lay.samples
            k0 = step_of(sec * 1_000_000_000 + nanosec, lay.dt)
            # stamp_ns(k, dt) = round(k dt 1e9) for every k at once (both round half to even)
            steps = np.arange(k0, k0 + lay.samples, dtype=np.int64)
            all_stamps.append(np.rint(steps * lay.dt * 1e9).astype(np.int64))
            count = lay.samples * len(lay.joints)
            parts = [np.frombuffer(data, dtype='<f8', count=count, offset=offset).reshape(
                lay.samples, len(lay.joints)) for _, offset in lay.fields]
            all_rows.append(np.hstack(parts))
        return np.concatenate(all_stamps), np.vstack(all_rows)
