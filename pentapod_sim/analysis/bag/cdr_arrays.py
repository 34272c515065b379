"""
Vectorised decoding of recorded CDR messages (JointState, WrenchStamped, Clock) into arrays.

Hand-written because the generic decoders (mcap_ros2, rosbags) build one Python object per
message, about 20-50 us each, too slow for 1e6 samples. Runs of messages with the same byte
length and the same layout (names, sequence lengths) are stacked into a 2-D uint8 array and
the float64 columns are read with numpy views; messages of other layouts form their own
groups. Offsets count from the end of the 4-byte encapsulation header (Fast-CDR alignment).
"""
import dataclasses
import struct
from typing import Optional, Sequence

import numpy as np
import numpy.typing as npt

from pentapod_sim.analysis.bag.message_store import MessageStore
from pentapod_sim.errors import BagError

JOINT_STATE_FIELDS = ('position', 'velocity', 'effort')
HEADER = 4  # CDR encapsulation header bytes
BATCH = 200_000  # messages per gather when checking layouts
#: CDR messages of one topic: a store, or a list of their bytes
Messages = MessageStore | Sequence[bytes]
Indices = npt.NDArray[np.intp]
Floats = npt.NDArray[np.float64]


@dataclasses.dataclass
class JointStateLayout:
    """Byte layout of one JointState message: names, array offsets, structural byte indices."""

    names: list[str]
    arrays: dict[str, tuple[int, int]]  # field -> (absolute byte offset, element count)
    structure: Indices  # absolute indices of bytes that define the layout


def _align(offset: int, size: int) -> int:
    return offset + (-offset) % size


def _read_string(body: bytes | memoryview, off: int, structure: list[int]) -> tuple[str, int]:
    off = _align(off, 4)
    (length,) = struct.unpack_from('<I', body, off)
    structure.extend(range(off, off + 4 + max(length - 1, 0)))
    text = bytes(body[off + 4:off + 4 + length - 1]).decode('utf-8')
    return text, off + 4 + length


def joint_state_layout(data: bytes) -> JointStateLayout:
    """
    Parse the layout of one serialised sensor_msgs/msg/JointState.

    Raises
    ------
    BagError
        If the bytes are too short for the layout they announce.
    """
    body = memoryview(data)[HEADER:]
    structure: list[int] = []
    try:
        _, off = _read_string(body, 8, structure)
        off = _align(off, 4)
        (n_names,) = struct.unpack_from('<I', body, off)
        structure.extend(range(off, off + 4))
        off += 4
        names = []
        for _ in range(n_names):
            name, off = _read_string(body, off, structure)
            names.append(name)
        arrays = {}
        for field in JOINT_STATE_FIELDS:
            off = _align(off, 4)
            (count,) = struct.unpack_from('<I', body, off)
            structure.extend(range(off, off + 4))
            off += 4
            if count:
                off = _align(off, 8)
            arrays[field] = (off + HEADER, count)
            off += 8 * count
        if off > len(body):
            raise struct.error('message shorter than its sequences')
    except (struct.error, UnicodeDecodeError) as err:
        raise BagError(f'malformed JointState message ({len(data)} bytes): {err}') from None
    return JointStateLayout(names, arrays, np.asarray(structure, dtype=np.intp) + HEADER)


def _store(messages: Messages) -> MessageStore:
    return messages if isinstance(messages, MessageStore) else MessageStore.from_list(messages)


def stamps_ns(messages: Messages) -> npt.NDArray[np.int64]:
    """
    Header stamps [ns] of messages whose first field is a std_msgs/Header or builtin Time.

    Parameters
    ----------
    messages : MessageStore or list of bytes
        CDR messages.

    Returns
    -------
    (N,) int64 ndarray
    """
    store = _store(messages)
    head = store.gather(np.arange(len(store)), HEADER, 8)
    sec = head[:, :4].copy().view('<i4')[:, 0].astype(np.int64)
    nanosec = head[:, 4:].copy().view('<u4')[:, 0].astype(np.int64)
    return sec * 1_000_000_000 + nanosec


def _groups_by_length(store: MessageStore) -> dict[int, Indices]:
    lengths = store.lengths
    return {int(length): np.flatnonzero(lengths == length) for length in np.unique(lengths)}


def _same_layout(store: MessageStore, indices: Indices, layout: JointStateLayout
                 ) -> tuple[Indices, Indices]:
    """Split ``indices`` into those whose structural bytes equal the layout's and the rest."""
    if len(layout.structure) == 0:
        return indices, indices[:0]
    lo, hi = int(layout.structure.min()), int(layout.structure.max()) + 1
    cols = layout.structure - lo
    reference = np.frombuffer(store[indices[0]], dtype=np.uint8)[layout.structure]
    same = np.ones(len(indices), dtype=bool)
    for start in range(0, len(indices), BATCH):  # bounded temporary memory
        part = store.gather(indices[start:start + BATCH], lo, hi - lo)
        same[start:start + BATCH] = np.all(part[:, cols] == reference, axis=1)
    return indices[same], indices[~same]


def _layouts(store: MessageStore) -> list[tuple[Indices, JointStateLayout]]:
    """Group message indices by identical JointState layout: [(indices, layout)]."""
    groups = []
    for _, indices in _groups_by_length(store).items():
        while len(indices):
            layout = joint_state_layout(store[indices[0]])
            same, indices = _same_layout(store, indices, layout)
            groups.append((same, layout))
    return groups


def joint_state_arrays(messages: Messages) -> tuple[list[str], dict[str, Floats]]:
    """
    Decode JointState messages into per-field arrays.

    Parameters
    ----------
    messages : MessageStore or list of bytes
        CDR JointState messages of one topic.

    Returns
    -------
    names : list of str
        Joint names (union over all messages, in order of appearance).
    values : dict
        ``{field: (N, len(names)) float64 ndarray}`` for position/velocity/effort; NaN where a
        message lacks the name or the field.
    """
    store = _store(messages)
    groups = _layouts(store)
    names: list[str] = []
    for _, layout in groups:
        names.extend(n for n in layout.names if n not in names)
    column = {name: k for k, name in enumerate(names)}
    values = {f: np.full((len(store), len(names)), np.nan) for f in JOINT_STATE_FIELDS}
    for indices, layout in groups:
        cols = np.array([column[n] for n in layout.names], dtype=np.intp)
        for field, (offset, count) in layout.arrays.items():
            if count == 0:
                continue
            if count != len(layout.names):
                raise BagError(f'JointState {field} has {count} values for '
                               f'{len(layout.names)} names')
            block = store.gather(indices, offset, 8 * count).view('<f8')
            values[field][np.ix_(indices, cols)] = block
    return names, values


def joint_state_column(messages: Messages, field: str, name: str) -> tuple[Floats, list[str]]:
    """
    Decode one value (``field`` of joint ``name``) of every JointState message.

    Reads only those 8 bytes per message, unlike :func:`joint_state_arrays`.

    Parameters
    ----------
    messages : MessageStore or list of bytes
        CDR JointState messages of one topic.
    field : str
        ``'position'``, ``'velocity'`` or ``'effort'``.
    name : str
        Joint name.

    Returns
    -------
    values : (N,) float64 ndarray
        NaN where a message lacks the name or the field.
    names : list of str
        All joint names seen (for error messages).
    """
    store = _store(messages)
    values = np.full(len(store), np.nan)
    names: list[str] = []
    for indices, layout in _layouts(store):
        names.extend(n for n in layout.names if n not in names)
        offset, count = layout.arrays[field]
        if name in layout.names and count == len(layout.names):
            where = offset + 8 * layout.names.index(name)
            values[indices] = store.gather(indices, where, 8).view('<f8')[:, 0]
    return values, names


def wrench_arrays(messages: Messages, component: Optional[int] = None) -> Floats:
    """
    Decode WrenchStamped messages.

    Parameters
    ----------
    messages : MessageStore or list of bytes
        CDR WrenchStamped messages of one topic.
    component : int, optional
        Decode only this column (0-2 force x, y, z; 3-5 torque x, y, z).

    Returns
    -------
    (N, 6) or (N,) float64 ndarray
        force x, y, z [N], torque x, y, z [N m] (or the one requested column).
    """
    store = _store(messages)
    first, width = (0, 6) if component is None else (int(component), 1)
    out = np.empty((len(store), width))
    lengths = store.lengths
    frame_lens = store.gather(np.arange(len(store)), HEADER + 8, 4).view('<u4')[:, 0]
    for length in np.unique(lengths):
        for frame_len in np.unique(frame_lens[lengths == length]):
            indices = np.flatnonzero((lengths == length) & (frame_lens == frame_len))
            offset = HEADER + _align(12 + int(frame_len), 8)
            if offset + 48 > length:
                raise BagError(f'malformed WrenchStamped message ({length} bytes)')
            out[indices] = store.gather(indices, offset + 8 * first, 8 * width).view('<f8')
    return out if component is None else out[:, 0]
