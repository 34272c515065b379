"""
Vectorised decoding of recorded CDR messages (JointState, WrenchStamped, Clock) into arrays.

Hand-written because the generic decoders (mcap_ros2, rosbags) build one Python object per
message, about 20-50 us each, too slow for 1e6 samples. Runs of messages with the same byte
length and the same layout (names, sequence lengths) are stacked into a 2-D uint8 array and
the float64 columns are read with numpy views; any other message goes through a per-message
parser. Offsets count from the end of the 4-byte encapsulation header (Fast-CDR alignment).
"""
import dataclasses
import struct

import numpy as np

from pentapod_sim.exceptions import BagError

JOINT_STATE_FIELDS = ('position', 'velocity', 'effort')
HEADER = 4  # CDR encapsulation header bytes


@dataclasses.dataclass
class JointStateLayout:
    """Byte layout of one JointState message: names, array offsets, structural byte indices."""

    names: list
    arrays: dict  # field -> (absolute byte offset, element count)
    structure: np.ndarray  # absolute indices of bytes that define the layout


def _align(offset: int, size: int) -> int:
    return offset + (-offset) % size


def _read_string(body: bytes, off: int, structure: list) -> tuple:
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
    structure: list = []
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


def stamps_ns(payloads: list) -> np.ndarray:
    """
    Header stamps [ns] of messages whose first field is a std_msgs/Header or builtin Time.

    Parameters
    ----------
    payloads : list of bytes
        CDR messages.

    Returns
    -------
    (N,) int64 ndarray
    """
    head = np.frombuffer(b''.join(bytes(p[HEADER:HEADER + 8]) for p in payloads), dtype='<i4')
    head = head.reshape(-1, 2).astype(np.int64)
    sec, nanosec = head[:, 0], head[:, 1] & 0xFFFFFFFF
    return sec * 1_000_000_000 + nanosec


def _groups_by_length(payloads: list) -> dict:
    lengths = np.fromiter((len(p) for p in payloads), dtype=np.int64, count=len(payloads))
    groups = {}
    for length in np.unique(lengths):
        groups[int(length)] = np.flatnonzero(lengths == length)
    return groups


def joint_state_arrays(payloads: list) -> tuple:
    """
    Decode JointState messages into per-field arrays.

    Parameters
    ----------
    payloads : list of bytes
        CDR JointState messages of one topic.

    Returns
    -------
    names : list of str
        Joint names (union over all messages, in order of appearance).
    values : dict
        ``{field: (N, len(names)) float64 ndarray}`` for position/velocity/effort; NaN where a
        message lacks the name or the field.
    """
    n_msgs = len(payloads)
    names: list = []
    blocks = []  # (indices, layout, rows)
    for length, indices in _groups_by_length(payloads).items():
        rows = np.frombuffer(b''.join(payloads[i] for i in indices), dtype=np.uint8)
        rows = rows.reshape(len(indices), length)
        layout = joint_state_layout(payloads[indices[0]])
        same = np.all(rows[:, layout.structure] == rows[0, layout.structure], axis=1)
        if not same.all():
            odd = indices[~same]
            indices, rows = indices[same], rows[same]
            for i in odd:  # layouts differing at equal length: decode one by one
                single = np.frombuffer(payloads[i], dtype=np.uint8)[None, :]
                blocks.append((np.array([i]), joint_state_layout(payloads[i]), single))
        blocks.append((indices, layout, rows))
    for _, layout, _ in blocks:
        names.extend(n for n in layout.names if n not in names)
    column = {name: k for k, name in enumerate(names)}
    values = {f: np.full((n_msgs, len(names)), np.nan) for f in JOINT_STATE_FIELDS}
    for indices, layout, rows in blocks:
        cols = [column[n] for n in layout.names]
        for field, (offset, count) in layout.arrays.items():
            if count == 0 or len(indices) == 0:
                continue
            if count != len(layout.names):
                raise BagError(f'JointState {field} has {count} values for '
                               f'{len(layout.names)} names')
            block = np.ascontiguousarray(rows[:, offset:offset + 8 * count]).view('<f8')
            values[field][np.ix_(indices, cols)] = block
    return names, values


def wrench_arrays(payloads: list) -> np.ndarray:
    """
    Decode WrenchStamped messages.

    Returns
    -------
    (N, 6) float64 ndarray
        force x, y, z [N], torque x, y, z [N m].
    """
    out = np.empty((len(payloads), 6))
    for length, indices in _groups_by_length(payloads).items():
        (frame_len,) = struct.unpack_from('<I', payloads[indices[0]], HEADER + 8)
        offset = HEADER + _align(12 + frame_len, 8)
        if offset + 48 > length:
            raise BagError(f'malformed WrenchStamped message ({length} bytes)')
        rows = np.frombuffer(b''.join(payloads[i] for i in indices), dtype=np.uint8)
        rows = rows.reshape(len(indices), length)
        frame_lens = np.ascontiguousarray(rows[:, HEADER + 8:HEADER + 12]).view('<u4')[:, 0]
        if np.any(frame_lens != frame_len):  # rare: different frame ids of equal total length
            for i in indices[frame_lens != frame_len]:
                out[i] = wrench_arrays([payloads[i]])[0]
            indices, rows = indices[frame_lens == frame_len], rows[frame_lens == frame_len]
        out[indices] = np.ascontiguousarray(rows[:, offset:offset + 48]).view('<f8')
    return out
