"""
Compact storage of one topic's CDR messages as views into decompressed MCAP chunks.

Keeping one Python ``bytes`` object per message costs about 100 bytes of overhead each (and a
copy); here a message is (segment, start, length) into a shared uint8 array, and decoders
gather only the byte columns they need, segment by segment, with numpy.
"""
from typing import Optional, Sequence

import numpy as np

from pentapod_sim.errors import BagError


class MessageStore:
    """
    Append-only list of messages of one topic.

    Messages are added as segments: a uint8 array (e.g. one decompressed chunk) with the start
    offsets and lengths of the messages in it. Call :meth:`finish` (done implicitly on first
    read) before reading.
    """

    def __init__(self) -> None:
        self._segments: list = []  # (data uint8, starts int64, lengths int64)
        self._pending: list = []  # loose messages (unchunked files), merged on finish
        self._bounds: Optional[np.ndarray] = None
        self._lengths: Optional[np.ndarray] = None

    @classmethod
    def from_list(cls, payloads: Sequence[bytes]) -> 'MessageStore':
        """Build a store from a list of messages."""
        store = cls()
        for payload in payloads:
            store.append(payload)
        return store

    def add_segment(self, data: np.ndarray, starts: np.ndarray, lengths: np.ndarray) -> None:
        """Add the messages ``data[starts[i]:starts[i] + lengths[i]]``."""
        self._flush_pending()
        self._segments.append((data, np.asarray(starts, np.int64),
                               np.asarray(lengths, np.int64)))
        self._bounds = None

    def append(self, payload: bytes) -> None:
        """Add one message."""
        self._pending.append(bytes(payload))
        self._bounds = None

    def _flush_pending(self) -> None:
        if not self._pending:
            return
        lengths = np.fromiter((len(p) for p in self._pending), np.int64, len(self._pending))
        starts = np.concatenate([[0], np.cumsum(lengths)[:-1]])
        data = np.frombuffer(b''.join(self._pending), dtype=np.uint8)
        self._pending = []
        self._segments.append((data, starts, lengths))

    def finish(self) -> None:
        """Merge loose messages and index the segments."""
        self._flush_pending()
        counts = [len(s[1]) for s in self._segments]
        self._bounds = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
        self._lengths = (np.concatenate([s[2] for s in self._segments]) if self._segments
                         else np.zeros(0, np.int64))

    def _ready(self) -> None:
        if self._bounds is None or self._pending:
            self.finish()

    def __len__(self) -> int:
        self._ready()
        return int(self._bounds[-1])

    @property
    def lengths(self) -> np.ndarray:
        """(N,) message lengths [bytes]."""
        self._ready()
        return self._lengths

    def __getitem__(self, index: int) -> bytes:
        self._ready()
        index = int(index) % len(self)
        seg = int(np.searchsorted(self._bounds, index, side='right')) - 1
        data, starts, lengths = self._segments[seg]
        local = index - self._bounds[seg]
        return data[starts[local]:starts[local] + lengths[local]].tobytes()

    def __iter__(self):
        for data, starts, lengths in self._segments_ready():
            for start, length in zip(starts.tolist(), lengths.tolist()):
                yield data[start:start + length].tobytes()

    def _segments_ready(self) -> list:
        self._ready()
        return self._segments

    def gather(self, indices: np.ndarray, offset: int, width: int) -> np.ndarray:
        """
        Return bytes ``[offset, offset + width)`` of the messages ``indices`` (sorted).

        Returns
        -------
        (len(indices), width) uint8 ndarray

        Raises
        ------
        BagError
            If a message is shorter than ``offset + width`` bytes (it would read its neighbour).
        """
        self._ready()
        indices = np.asarray(indices, dtype=np.int64)
        short = np.flatnonzero(self._lengths[indices] < offset + width)
        if len(short):
            k = int(indices[short[0]])
            raise BagError(f'message {k} has {int(self._lengths[k])} bytes, too short for bytes '
                           f'{offset}..{offset + width} of its type ({len(short)} such messages)')
        out = np.empty((len(indices), width), dtype=np.uint8)
        cuts = np.searchsorted(indices, self._bounds)
        columns = np.arange(offset, offset + width, dtype=np.int64)
        for seg, (data, starts, _) in enumerate(self._segments):
            lo, hi = cuts[seg], cuts[seg + 1]
            if lo == hi:
                continue
            local = indices[lo:hi] - self._bounds[seg]
            out[lo:hi] = data[starts[local][:, None] + columns]
        return out
