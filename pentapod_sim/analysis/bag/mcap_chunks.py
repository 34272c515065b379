"""
Verified, fast split of MCAP Chunk records into message tuples.

Hand-written because ``mcap.stream_reader.breakup_chunk`` builds each Message through several
small reads (about 8 us per message); this loop reads the fixed message prefix with one
``struct.unpack_from`` (about 1 us) and leaves the payloads in the decompressed chunk (no
per-message copy), which makes 1e6-sample bags load in seconds. Record layout (MCAP spec):
opcode u8, record length u64, then for a Message: channel id u16, sequence u32, log time u64,
publish time u64, data (rest of the record).

Integrity: every length is checked against the bytes that hold it before anything is
allocated or sliced, compressed chunks are decompressed only to the size that both the chunk
header and the compression frame announce (at most :data:`MAX_CHUNK_BYTES`), and the
records' CRC-32 (``uncompressed_crc``, when non-zero) must match. Any failure raises
:class:`RecordDamage`, so the caller skips the chunk and reports it.

Schema and Channel records are parsed with the mcap package's record classes, which are not
its public API (``mcap.records``, ``mcap.data_stream``, ``mcap.opcode``). :func:`internals`
loads them; if they are missing or changed, :class:`InternalsChanged` tells the bag reader to
use the public ``mcap.reader`` API instead (:mod:`pentapod_sim.analysis.bag.mcap_public`).
"""
import dataclasses
import importlib
import io
import struct
from types import SimpleNamespace
from typing import Any
import zlib

import numpy as np
import numpy.typing as npt

try:
    import zstandard
except ImportError:  # pragma: no cover - mcap depends on it
    zstandard = None  # type: ignore[assignment]  # its chunks are then reported unsupported
try:
    import lz4.frame as lz4_frame
except ImportError:  # pragma: no cover - mcap depends on it
    lz4_frame = None

#: Largest decompressed chunk accepted [bytes] (rosbag2's default chunk is 768 KiB).
MAX_CHUNK_BYTES = 1 << 30
_PREFIX = struct.Struct('<BQHIQQ')  # opcode, length, channel, sequence, log, publish
_RECORD = struct.Struct('<BQ')
_CHUNK_HEAD = struct.Struct('<QQQII')  # start, end, uncompressed size, crc, compression length
_MESSAGE_MIN = 22  # channel u16 + sequence u32 + two u64 times
Body = bytes | memoryview
Int64s = npt.NDArray[np.int64]
#: header, decompressed records (uint8), per message: channel, log time [ns], payload start,
#: payload length; the Schema and Channel records
SplitChunk = tuple['ChunkHeader', npt.NDArray[np.uint8], Int64s, Int64s, Int64s, Int64s,
                   list[Any]]
#: The mcap names the fast reader uses: module -> attributes.
INTERNAL_NAMES = {
    'mcap.data_stream': ('ReadDataStream',),
    'mcap.opcode': ('Opcode',),
    'mcap.records': ('Channel', 'ChunkIndex', 'MessageIndex', 'Metadata', 'MetadataIndex',
                     'Schema', 'Statistics'),
}


class RecordDamage(ValueError):
    """A record is damaged (bad CRC, a length past its end, undecodable content)."""


class InternalsChanged(RuntimeError):
    """The mcap internals this reader uses are missing or behave differently."""


def internals() -> SimpleNamespace:
    """
    Load the mcap internals of :data:`INTERNAL_NAMES`.

    Raises
    ------
    InternalsChanged
        If a module or a name is missing.
    """
    names = {}
    for module_name, attributes in INTERNAL_NAMES.items():
        try:
            module = importlib.import_module(module_name)
            for attribute in attributes:
                names[attribute] = getattr(module, attribute)
        except (ImportError, AttributeError) as err:
            raise InternalsChanged(f'{module_name}: {err}') from err
    return SimpleNamespace(**names)


class _ExactReader(io.BytesIO):
    """A byte stream whose reads fail instead of returning fewer bytes than asked for."""

    def read(self, size: int | None = -1) -> bytes:
        data = super().read(size)
        if size is not None and size >= 0 and len(data) != size:
            raise RecordDamage(f'a field of {size} bytes runs past the record end')
        return data


def parse_record(mcap: SimpleNamespace, kind: str, body: Body) -> Any:
    """
    Parse one record body with mcap's record class ``kind``; it must use every byte.

    The record is an instance of ``mcap.records.<kind>`` (loaded at run time by
    :func:`internals`, hence typed Any).

    Raises
    ------
    RecordDamage
        If the body is too short, too long or undecodable.
    InternalsChanged
        If the record class no longer reads this way.
    """
    stream = _ExactReader(bytes(body))
    try:
        record = getattr(mcap, kind).read(mcap.ReadDataStream(stream))
    except (AttributeError, TypeError) as err:
        raise InternalsChanged(f'mcap.records.{kind}.read: {err}') from err
    except (EOFError, struct.error, UnicodeDecodeError, ValueError) as err:
        raise RecordDamage(f'{kind} record undecodable ({err})') from None
    except Exception as err:  # mcap's own errors (EndOfFile, ...) for short fields
        if type(err).__module__.startswith('mcap'):
            raise RecordDamage(f'{kind} record undecodable ({type(err).__name__})') from None
        raise
    if stream.tell() != len(stream.getbuffer()):
        raise RecordDamage(f'{kind} record has {len(stream.getbuffer()) - stream.tell()} '
                           'bytes after its last field')
    return record


@dataclasses.dataclass
class ChunkHeader:
    """Fields of a Chunk record before its records (MCAP spec)."""

    start_ns: int
    end_ns: int
    uncompressed_size: int
    crc: int
    compression: str
    records_at: int  # offset of the records in the record body


def chunk_header(body: Body) -> ChunkHeader:
    """
    Parse and check the header of a Chunk record body (without opcode and length).

    Raises
    ------
    RecordDamage
        If the lengths disagree with the body's size or the compression name is garbled.
    """
    if len(body) < _CHUNK_HEAD.size + 8:
        raise RecordDamage(f'chunk record of {len(body)} bytes is shorter than its header')
    start, end, size, crc, name_length = _CHUNK_HEAD.unpack_from(body, 0)
    if name_length > len(body) - _CHUNK_HEAD.size - 8:
        raise RecordDamage(f'chunk compression name length {name_length} runs past the record')
    at = _CHUNK_HEAD.size + name_length
    try:
        compression = bytes(body[_CHUNK_HEAD.size:at]).decode('ascii')
    except UnicodeDecodeError:
        raise RecordDamage('chunk compression name is not ASCII') from None
    (records_length,) = struct.unpack_from('<Q', body, at)
    if records_length != len(body) - at - 8:
        raise RecordDamage(f'chunk records length {records_length} disagrees with the record '
                           f'length ({len(body) - at - 8} bytes of records)')
    return ChunkHeader(start, end, size, crc, compression, at + 8)


def chunk_bytes(body: Body, header: ChunkHeader) -> Body:
    """
    Return the decompressed, CRC-checked records of a Chunk record body.

    Raises
    ------
    RecordDamage
        If sizes disagree, decompression fails or the CRC does not match.
    """
    data = memoryview(body)[header.records_at:]
    size = header.uncompressed_size
    records: Body
    if header.compression and size > MAX_CHUNK_BYTES:
        raise RecordDamage(f'chunk uncompressed size {size} bytes exceeds {MAX_CHUNK_BYTES}')
    try:
        if header.compression == '':
            records = data
        elif header.compression == 'zstd' and zstandard is not None:
            announced = zstandard.frame_content_size(data)
            if announced not in (-1, size):
                raise RecordDamage(f'chunk size {size} disagrees with its zstd frame '
                                   f'({announced})')
            records = zstandard.decompress(data, max_output_size=max(size, 1))
        elif header.compression == 'lz4' and lz4_frame is not None:
            announced = lz4_frame.get_frame_info(data)['content_size']
            if announced not in (0, size):
                raise RecordDamage(f'chunk size {size} disagrees with its lz4 frame '
                                   f'({announced})')
            records = lz4_frame.decompress(data)
        else:
            raise RecordDamage(f'chunk compression {header.compression!r} is not supported')
    except RecordDamage:
        raise
    except Exception as err:  # zstandard.ZstdError, lz4's RuntimeError: a damaged frame
        raise RecordDamage(f'{header.compression} decompression failed ({err})') from None
    if len(records) != size:
        raise RecordDamage(f'chunk holds {len(records)} bytes of records, its header says '
                           f'{size}')
    if header.crc and zlib.crc32(records) != header.crc:
        raise RecordDamage('chunk CRC mismatch')
    return records


def prefix_bytes(compression: str, present: bytes, size: int) -> bytes:
    """
    Return the records decodable from the bytes present of a Chunk cut by the end of its file.

    ``present`` are the compressed records up to the cut, ``size`` the uncompressed size the
    chunk header announces. Uncompressed, every byte present is returned; zstd and lz4 give
    their whole compressed blocks (the streaming decoders stop at the last complete one). At
    most ``size`` and :data:`MAX_CHUNK_BYTES` bytes are produced; nothing is CRC-checked.

    Raises
    ------
    RecordDamage
        If the bytes do not decode or the compression is not supported.
    """
    limit = min(size, MAX_CHUNK_BYTES)
    try:
        if compression == '':
            return present[:limit]
        if compression == 'zstd' and zstandard is not None:
            reader = zstandard.ZstdDecompressor().stream_reader(io.BytesIO(present))
            return reader.read(limit)
        if compression == 'lz4' and lz4_frame is not None:
            return lz4_frame.LZ4FrameDecompressor().decompress(present, max_length=limit)
    except Exception as err:  # zstandard.ZstdError, lz4's RuntimeError: undecodable prefix
        raise RecordDamage(f'{compression} prefix undecodable ({err})') from None
    raise RecordDamage(f'chunk compression {compression!r} is not supported')


def split_chunk(mcap: SimpleNamespace, body: Body) -> SplitChunk:
    """
    Verify one Chunk record body and split it into its records.

    Parameters
    ----------
    mcap : SimpleNamespace
        From :func:`internals`.
    body : bytes-like
        The Chunk record after its opcode and length.

    Returns
    -------
    header : ChunkHeader
    data : (B,) uint8 ndarray
        Decompressed chunk records.
    channel_ids, log_times_ns, starts, lengths : (M,) int64 ndarrays
        Per message: channel, log time [ns], offset of its payload in ``data``, payload length.
    others : list
        Schema and Channel records found in the chunk.

    Raises
    ------
    RecordDamage
        If anything in the chunk fails a check (see the module docstring).
    """
    header = chunk_header(body)
    data = chunk_bytes(body, header)
    # channel, log time, payload start, payload length of one message after the other
    messages: list[int] = []
    others: list[Any] = []
    off, end = 0, len(data)
    message_op = int(mcap.Opcode.MESSAGE)
    kinds = {int(mcap.Opcode.SCHEMA): 'Schema', int(mcap.Opcode.CHANNEL): 'Channel'}
    unpack_message, add = _PREFIX.unpack_from, messages.extend
    while off < end:
        if end - off >= _PREFIX.size:  # one unpack per message (the common case)
            opcode, length, channel, _, log_time, _ = unpack_message(data, off)
        elif end - off >= 9:
            (opcode, length), channel, log_time = _RECORD.unpack_from(data, off), 0, 0
        else:
            raise RecordDamage(f'chunk ends inside a record header at byte {off}')
        if length > end - off - 9:
            raise RecordDamage(f'record length {length} at chunk byte {off} runs past the '
                               'chunk end')
        if opcode == message_op:
            if length < _MESSAGE_MIN:
                raise RecordDamage(f'message record of {length} bytes at chunk byte {off}')
            add((channel, log_time, off + _PREFIX.size, length - _MESSAGE_MIN))
        elif opcode in kinds:
            others.append(parse_record(mcap, kinds[opcode], data[off + 9:off + 9 + length]))
        off += 9 + length
    # uint64 holds any u64 log time; a time past 2**63 ns (year 2262) wraps instead of raising
    table = np.fromiter(messages, np.uint64, len(messages)).reshape(-1, 4).view(np.int64)
    return (header, np.frombuffer(data, dtype=np.uint8), table[:, 0].copy(), table[:, 1].copy(),
            table[:, 2].copy(), table[:, 3].copy(), others)
