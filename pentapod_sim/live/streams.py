"""
One subscribed topic of the live view: raw CDR in, deduplicated samples and envelopes out.

The node's subscriptions are polled by the live view's worker thread, which hands every message
to :meth:`TopicStream.offer` (append the bytes, count the messages lost before it or a drop when
the backlog is full); once per pass the worker takes the backlog, decodes it in one
vectorised pass (:mod:`pentapod_sim.analysis.cdr_arrays`), drops the copies of a step that a
lockstep plant re-sends while it waits, notices a new run (stamps going back) and feeds the
envelope downsampler. Supported types: sensor_msgs/JointState (columns: the joints' position,
then velocity, then effort values, for the fields the messages carry) and
geometry_msgs/WrenchStamped (force x, y, z, torque x, y, z).
"""
from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field
import struct

import numpy as np
import numpy.typing as npt

from pentapod_sim import interface
from pentapod_sim.analysis.cdr_arrays import (
    joint_state_arrays,
    JOINT_STATE_FIELDS,
    joint_state_layout,
    stamps_ns,
    wrench_arrays,
)
from pentapod_sim.errors import BagError
from pentapod_sim.live.envelope import EnvelopeDownsampler, Sample

#: Message types the live view downsamples.
SUPPORTED_TYPES = (interface.JOINT_STATE, interface.WRENCH_STAMPED)
HEADER_FRAME_OFFSET = 12  # CDR header (4) + stamp (8): the frame_id string length


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
        out = {f: [] for f in JOINT_STATE_FIELDS}
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
