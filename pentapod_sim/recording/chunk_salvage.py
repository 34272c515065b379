"""
Records of one MCAP chunk for :mod:`pentapod_sim.recording.salvage`, also of a chunk cut short.

A whole chunk is verified as :mod:`pentapod_sim.analysis.bag.mcap_chunks` describes
(decompressed size, CRC-32 when set) and must split into records exactly. A chunk cut by the
end of the file yields the records that are complete before the cut: an uncompressed chunk all
of them, a zstd or lz4 chunk those of its whole compressed blocks (the streaming decoders stop
at the last complete block). Decompression never produces more than the chunk header
announces, nor more than :data:`~pentapod_sim.analysis.bag.mcap_chunks.MAX_CHUNK_BYTES`.
"""
from __future__ import annotations

import dataclasses
import struct
from types import SimpleNamespace
from typing import Optional, TYPE_CHECKING, TypedDict

import numpy as np
import numpy.typing as npt

from pentapod_sim.analysis.bag.mcap_chunks import (
    chunk_bytes,
    chunk_header,
    internals,
    InternalsChanged,
    parse_record,
    prefix_bytes,
    RecordDamage,
)

if TYPE_CHECKING:       # the classes come from api() at run time (InternalsChanged if changed)
    from mcap.records import Channel, Schema

RECORD = struct.Struct('<BQ')
MESSAGE = struct.Struct('<HIQQ')           # channel, sequence, log time, publish time
CHUNK_FIXED = struct.Struct('<QQQII')      # start, end, uncompressed size, crc, name length
OP = SimpleNamespace(HEADER=1, FOOTER=2, SCHEMA=3, CHANNEL=4, MESSAGE=5, CHUNK=6,
                     MESSAGE_INDEX=7, ATTACHMENT=9, STATISTICS=11, METADATA=12, DATA_END=15)
_EXTRA_RECORDS = ('Header', 'Attachment', 'Footer')


def api() -> SimpleNamespace:
    """The mcap record classes used here (:func:`~.mcap_chunks.internals` and a few more)."""
    names = internals()
    try:
        from mcap import records
        for name in _EXTRA_RECORDS:
            setattr(names, name, getattr(records, name))
    except (ImportError, AttributeError) as err:
        raise InternalsChanged(f'mcap.records: {err}') from err
    return names


@dataclasses.dataclass
class ChunkContent:
    """Records of one chunk; ``messages`` rows: channel, sequence, log, publish, start, size."""

    start_ns: int
    end_ns: int
    compression: str
    data: bytes
    messages: npt.NDArray[np.int64]
    others: list[Schema | Channel]
    cut: bool


class ChunkSpan(TypedDict, total=False):
    """The log-time span [ns] of a chunk, as its header announces it."""

    start_ns: int
    end_ns: int


def chunk_content(mcap: SimpleNamespace, body: bytes, complete: bool) -> ChunkContent:
    """
    Split a Chunk record body (after opcode and length) into its records.

    ``complete``: the body is whole; it must verify, else RecordDamage. Otherwise the body is
    cut by the file end: the records complete before the cut are returned (``cut``), each
    message with a channel id and a log time that are checked later.
    """
    if complete:
        header = chunk_header(body)
        data = bytes(chunk_bytes(body, header))
        start, end, compression = header.start_ns, header.end_ns, header.compression
    else:
        start, end, compression, data = _cut_chunk_bytes(body)
    messages: list[tuple[int, ...]] = []
    others: list[Schema | Channel] = []
    off = 0
    kinds = {OP.SCHEMA: 'Schema', OP.CHANNEL: 'Channel'}
    while off < len(data):
        if len(data) - off < 9:
            if complete:
                raise RecordDamage(f'chunk ends inside a record header at byte {off}')
            break
        opcode, length = RECORD.unpack_from(data, off)
        if length > len(data) - off - 9:
            if complete:
                raise RecordDamage(f'record length {length} at chunk byte {off} runs past '
                                   'the chunk end')
            break
        if opcode == OP.MESSAGE:
            if length < MESSAGE.size:
                if complete:
                    raise RecordDamage(f'message record of {length} bytes')
                break
            messages.append((*MESSAGE.unpack_from(data, off + 9), off + 9 + MESSAGE.size,
                             length - MESSAGE.size))
        elif opcode in kinds:
            try:
                others.append(parse_record(mcap, kinds[opcode], data[off + 9:off + 9 + length]))
            except RecordDamage:
                if complete:
                    raise
                break
        off += 9 + length
    table = np.array(messages, dtype=np.uint64).reshape(-1, 6).astype(np.int64, copy=False)
    return ChunkContent(start, end, compression, data, table, others, not complete)


def _cut_chunk_bytes(body: bytes) -> tuple[int, int, str, bytes]:
    """Header fields and the records decodable from a chunk cut by the file end."""
    if len(body) < CHUNK_FIXED.size:
        raise RecordDamage('the file ends inside the chunk header')
    start, end, size, _, name_length = CHUNK_FIXED.unpack_from(body)
    at = CHUNK_FIXED.size + name_length
    if name_length > 16 or len(body) < at + 8:
        raise RecordDamage('the file ends inside the chunk header')
    compression = body[CHUNK_FIXED.size:at].decode('ascii', 'replace')
    return start, end, compression, prefix_bytes(compression, body[at + 8:], size)


def framed(body: bytes, length: Optional[int] = None) -> bool:
    """True if a chunk body's header and records length agree with its record length."""
    if len(body) < CHUNK_FIXED.size + 8:
        return False
    name_length = CHUNK_FIXED.unpack_from(body)[4]
    if name_length > 16 or len(body) < CHUNK_FIXED.size + name_length + 8:
        return False
    (records,) = struct.unpack_from('<Q', body, CHUNK_FIXED.size + name_length)
    return (len(body) if length is None else length) == CHUNK_FIXED.size + name_length + 8 + \
        records


def chunk_span(body: bytes) -> ChunkSpan:
    """The log-time span a chunk header announces (empty if the header is cut)."""
    if len(body) < 16:
        return {}
    start, end = struct.unpack_from('<QQ', body)
    return {'start_ns': start, 'end_ns': end}
