"""
Compact storage of one topic's CDR messages as views into decompressed MCAP chunks.

Keeping one Python ``bytes`` object per message costs about 100 bytes of overhead each (and a
copy); here a message is (segment, start, length) into a shared uint8 array, and decoders
gather only the byte columns they need, segment by segment, with numpy.
"""
from typing import Iterator, Sequence

import numpy as np
import numpy.typing as npt

from pentapod_sim.errors import BagError

Bytes = npt.NDArray[np.uint8]
Int64s = npt.NDArray[np.int64]


class MessageStore:
    """
    Append-only list of messages of one topic.

    Messages are added as segments: a uint8 array (e.g. one decompressed chunk) with the start
    offsets and lengths of the messages in it. Call :meth:`finish` (done implicitly on first
    read) before reading.
    """

    def __init__(self) -> None:
        self._segments: list[tuple[Bytes, Int64s, Int64s]] = []   # (data, starts, lengths)
        self._pending: list[bytes] = []  # loose messages (unchunked files), merged on finish
        # (first message of each segment and the total count, all message lengths); None
        # until the next read after a change
        self._index: tuple[Int64s, Int64s] | None = None

    @classmethod
    def from_list(cls, payloads: Sequence[bytes]) -> 'MessageStore':
        """Build a store from a list of messages."""
        store = cls()
        for payload in payloads:
            store.append(payload)
        return store

    def add_segment(self, data: Bytes, starts: npt.ArrayLike, lengths: npt.ArrayLike) -> None:
        """Add the messages ``data[starts[i]:starts[i] + lengths[i]]``."""
        self._flush_pending()
        self._segments.append((data, np.asarray(starts, np.int64),
                               np.asarray(lengths, np.int64)))
        self._index = None

    def append(self, payload: bytes) -> None:
        """Add one message."""
        self._pending.append(bytes(payload))
        self._index = None

    def _flush_pending(self) -> None:
        if not self._pending:
            return
        lengths = np.fromiter((len(p) for p in self._pending), np.int64, len(self._pending))
        starts = np.concatenate([[0], np.cumsum(lengths)[:-1]]).astype(np.int64)
        data = np.frombuffer(b''.join(self._pending), dtype=np.uint8)
        self._pending = []
        self._segments.append((data, starts, lengths))

    def finish(self) -> None:
        """Merge loose messages and index the segments."""
        self._ready()

    def _ready(self) -> tuple[Int64s, Int64s]:
        """(segment bounds, message lengths), indexing the segments first if they changed."""
        if self._index is not None and not self._pending:
            return self._index
        self._flush_pending()
        counts = [len(s[1]) for s in self._segments]
        bounds = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
        lengths = (np.concatenate([s[2] for s in self._segments]) if self._segments
                   else np.zeros(0, np.int64))
        self._index = bounds, lengths
        return self._index

    def __len__(self) -> int:
        return int(self._ready()[0][-1])

    @property
    def lengths(self) -> Int64s:
        """(N,) message lengths [bytes]."""
        return self._ready()[1]

    def __getitem__(self, index: int) -> bytes:
        bounds, _ = self._ready()
        index = int(index) % len(self)
        seg = int(np.searchsorted(bounds, index, side='right')) - 1
        data, starts, lengths = self._segments[seg]
        local = index - bounds[seg]
        return data[starts[local]:starts[local] + lengths[local]].tobytes()

    def __iter__(self) -> Iterator[bytes]:
        self._ready()
        for data, starts, lengths in self._segments:
            for start, length in zip(starts.tolist(), lengths.tolist()):
                yield data[start:start + length].tobytes()

    def gather(self, indices: npt.ArrayLike, offset: int, width: int) -> Bytes:
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
        bounds, msg_lengths = self._ready()
        indices = np.asarray(indices, dtype=np.int64)
        short = np.flatnonzero(msg_lengths[indices] < offset + width)
        if len(short):
            k = int(indices[short[0]])
            raise BagError(f'message {k} has {int(msg_lengths[k])} bytes, too short for bytes '
                           f'{offset}..{offset + width} of its type ({len(short)} such messages)')
        out = np.empty((len(indices), width), dtype=np.uint8)
        cuts = np.searchsorted(indices, bounds)
        columns = np.arange(offset, offset + width, dtype=np.int64)
        for seg, (data, starts, _) in enumerate(self._segments):
            lo, hi = cuts[seg], cuts[seg + 1]
            if lo == hi:
                continue
            local = indices[lo:hi] - bounds[seg]
            out[lo:hi] = data[starts[local][:, None] + columns]
        return out
