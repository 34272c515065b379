"""
Fast, verifying reader of one MCAP file into a :class:`~.bag_file.FileContent`.

Two ways through a file, chosen by what is intact:

* **indexed** (footer and summary intact, summary CRC matching): every chunk is read where its
  Chunk Index says, so a damaged record anywhere cannot shift the others. A damaged chunk is
  skipped and reported with the index's time span and, from its Message Index records, the
  messages lost per topic.
* **sequential** (no footer: a file cut by a crash; or a damaged footer or summary): records
  are read one after the other from the start. Every record length is checked against the
  file end and every record must parse to its exact length; a file cut inside a record, or a
  record whose framing is broken, ends the read there, and the loss is reported (counts from
  metadata.yaml, see :func:`~.bag_file.reconcile`).

Every chunk is verified as :mod:`~.mcap_chunks` describes. Nothing is allocated from a length
before it is checked against the bytes that exist. Layout constants are the MCAP spec's.
"""
import dataclasses
import os
from pathlib import Path
import struct
from types import SimpleNamespace
from typing import Any, BinaryIO, Iterator, Optional
import zlib

from pentapod_sim.analysis.bag.file_content import Damage, FileContent, UnreadableBagError
from pentapod_sim.analysis.bag.mcap_chunks import (
    Body,
    chunk_header,
    internals,
    InternalsChanged,
    parse_record,
    RecordDamage,
    split_chunk,
)

MAGIC = b'\x89MCAP0\r\n'
_FOOTER = struct.Struct('<BQQQI')  # opcode, length (20), summary start, offsets start, crc
_TAIL = _FOOTER.size + len(MAGIC)
_RECORD = struct.Struct('<BQ')


@dataclasses.dataclass
class _Summary:
    """What the summary section indexes (mcap record objects, typed Any: see parse_record)."""

    end: int                                    # start of the summary section
    chunks: list[Any] = dataclasses.field(default_factory=list)     # ChunkIndex, by offset
    statistics: Any = None                      # the Statistics record, if any
    metadata: list[Any] = dataclasses.field(default_factory=list)   # MetadataIndex records


def read_file(path: Path, content: FileContent) -> None:
    """
    Read one MCAP file into ``content`` (see the module docstring).

    Raises
    ------
    UnreadableBagError
        If the file is not MCAP at all (neither its start nor its end is).
    InternalsChanged
        If the mcap internals used for parsing are missing or changed.
    """
    mcap = internals()
    with open(path, 'rb') as stream:
        size = os.fstat(stream.fileno()).st_size
        head = stream.read(len(MAGIC))
        try:
            footer_ok, summary = _summary(mcap, stream, size, content)
            if head != MAGIC:
                if not footer_ok:
                    raise UnreadableBagError(f'{path} is not an MCAP file (bad magic '
                                             f'{head[:8]!r}, no MCAP footer)')
                content.report(0, 'file magic damaged', lost={})
            if summary is not None and summary.chunks:
                _read_indexed(mcap, stream, size, summary, content)
            else:
                _read_sequential(mcap, stream, size, content, footer_ok)
        except (AttributeError, TypeError) as err:  # a record class changed its fields
            raise InternalsChanged(f'{type(err).__name__}: {err}') from err
    content.finish()


def _read_at(stream: BinaryIO, offset: int, length: int) -> bytes:
    stream.seek(offset)
    return stream.read(length)


def _summary(mcap: SimpleNamespace, stream: BinaryIO, size: int, content: FileContent
             ) -> tuple[bool, Optional[_Summary]]:
    """
    Read footer and summary section.

    Returns
    -------
    footer_ok : bool
        Whether the file ends with an intact-looking footer and magic.
    summary : _Summary or None
        None (the reason reported) if unusable.
    """
    if size < len(MAGIC) + _TAIL:
        return False, None
    tail = _read_at(stream, size - _TAIL, _TAIL)
    opcode, length, start, _, crc = _FOOTER.unpack_from(tail)
    if tail[_FOOTER.size:] != MAGIC or opcode != int(mcap.Opcode.FOOTER) or length != 20:
        return False, None  # cut short, or the footer is damaged: the sequential read tells
    if start == 0:
        return True, None  # a complete file without summary section
    if not len(MAGIC) <= start <= size - _TAIL:
        content.report(size - _TAIL, f'footer damaged (summary start {start})', lost={})
        return True, None
    section = _read_at(stream, start, size - _TAIL - start)
    if crc and zlib.crc32(tail[:_FOOTER.size - 4], zlib.crc32(section)) != crc:
        content.report(start, 'summary section or footer damaged (CRC mismatch); read the '
                       'data section record by record', lost={})
        return True, None
    out = _Summary(start)
    kinds = {int(mcap.Opcode.SCHEMA): 'Schema', int(mcap.Opcode.CHANNEL): 'Channel',
             int(mcap.Opcode.CHUNK_INDEX): 'ChunkIndex',
             int(mcap.Opcode.STATISTICS): 'Statistics',
             int(mcap.Opcode.METADATA_INDEX): 'MetadataIndex'}
    records: list[tuple[str, Any]] = []
    try:
        for opcode, body, _ in _records(section, 0):
            if opcode in kinds:
                records.append((kinds[opcode], parse_record(mcap, kinds[opcode], body)))
    except RecordDamage as err:
        content.report(start, f'summary section damaged ({err}); read the data section '
                       'record by record', lost={})
        return True, None
    for kind, record in records:
        if kind == 'Schema':
            content.schemas[record.id] = record
        elif kind == 'Channel':
            _add_channel(content, record)
        elif kind == 'ChunkIndex':
            out.chunks.append(record)
        elif kind == 'Statistics':
            out.statistics = record
        else:
            out.metadata.append(record)
    out.chunks.sort(key=lambda index: index.chunk_start_offset)
    return True, out


def _records(data: Body, offset: int) -> Iterator[tuple[int, memoryview, int]]:
    """Yield (opcode, body, offset) of the records in ``data``; RecordDamage on bad framing."""
    end = len(data)
    while offset < end:
        if end - offset < 9:
            raise RecordDamage(f'a record header at byte {offset} is cut')
        opcode, length = _RECORD.unpack_from(data, offset)
        if length > end - offset - 9:
            raise RecordDamage(f'record length {length} at byte {offset} runs past the end')
        yield opcode, memoryview(data)[offset + 9:offset + 9 + length], offset
        offset += 9 + length


def _add_channel(content: FileContent, channel: Any) -> None:
    content.add_channel(channel.id, channel.topic, channel.schema_id)


def _take_chunk(mcap: SimpleNamespace, body: Body, content: FileContent) -> None:
    """Split a chunk (RecordDamage if it fails a check) and add its records."""
    _, data, channel_ids, times, starts, lengths, others = split_chunk(mcap, body)
    for record in others:
        if hasattr(record, 'topic'):
            _add_channel(content, record)
        else:
            content.schemas[record.id] = record
    content.add_chunk(data, channel_ids, times, starts, lengths)


def _read_indexed(mcap: SimpleNamespace, stream: BinaryIO, size: int, summary: _Summary,
                  content: FileContent) -> None:
    data_end = summary.end
    for index in summary.chunks:
        offset, length = index.chunk_start_offset, index.chunk_length
        topics = tuple(sorted({content.topic_of(c) for c in index.message_index_offsets}))
        try:
            if not (len(MAGIC) <= offset and 9 <= length <= data_end - offset):
                raise RecordDamage(f'chunk index points outside the data section ({offset})')
            record = _read_at(stream, offset, length)
            opcode, record_length = _RECORD.unpack_from(record)
            if opcode != int(mcap.Opcode.CHUNK) or record_length != length - 9:
                raise RecordDamage(f'no chunk record of {length} bytes where the index says')
            _take_chunk(mcap, memoryview(record)[9:], content)
        except RecordDamage as err:
            lost = _index_counts(mcap, stream, index, data_end, content)
            content.report(offset, f'damaged chunk skipped: {err}',
                           start_ns=index.message_start_time, end_ns=index.message_end_time,
                           lost=lost, topics=topics)
    for index in summary.metadata:
        try:
            if not (len(MAGIC) <= index.offset and 9 <= index.length <= data_end - index.offset):
                raise RecordDamage('metadata index points outside the data section')
            record = _read_at(stream, index.offset, index.length)
            if record[0] != int(mcap.Opcode.METADATA):
                raise RecordDamage('no metadata record where the index says')
            _take_metadata(mcap, memoryview(record)[9:], content)
        except RecordDamage as err:
            content.report(index.offset, f'metadata record {index.name!r} damaged ({err})',
                           lost={})
    if summary.statistics is not None:
        expected: dict[str, int] = {}
        for channel_id, count in summary.statistics.channel_message_counts.items():
            topic = content.topic_of(channel_id)
            expected[topic] = expected.get(topic, 0) + count
        content.expected = expected


def _index_counts(mcap: SimpleNamespace, stream: BinaryIO, index: Any, data_end: int,
                  content: FileContent) -> Optional[dict[str, int]]:
    """Messages per topic of one chunk from its Message Index records (None if unreadable)."""
    start = index.chunk_start_offset + index.chunk_length
    if not index.message_index_offsets or index.message_index_length > data_end - start:
        return None
    counts: dict[str, int] = {}
    try:
        section = _read_at(stream, start, index.message_index_length)
        for opcode, body, _ in _records(section, 0):
            if opcode == int(mcap.Opcode.MESSAGE_INDEX):
                entry = parse_record(mcap, 'MessageIndex', body)
                topic = content.topic_of(entry.channel_id)
                counts[topic] = counts.get(topic, 0) + len(entry.records)
    except RecordDamage:
        return None
    return counts


def _take_metadata(mcap: SimpleNamespace, body: Body, content: FileContent) -> None:
    record = parse_record(mcap, 'Metadata', body)
    content.metadata[record.name] = dict(record.metadata)


def _read_sequential(mcap: SimpleNamespace, stream: BinaryIO, size: int, content: FileContent,
                     footer_seen: bool) -> None:
    """Read records from the start; stop at the data end, a cut or broken framing."""
    ops = SimpleNamespace(**{name: int(getattr(mcap.Opcode, name)) for name in (
        'CHUNK', 'MESSAGE_INDEX', 'SCHEMA', 'CHANNEL', 'MESSAGE', 'METADATA', 'DATA_END',
        'FOOTER')})
    kinds = {ops.SCHEMA: 'Schema', ops.CHANNEL: 'Channel', ops.METADATA: 'Metadata',
             ops.MESSAGE_INDEX: 'MessageIndex'}
    offset, chunked = len(MAGIC), False
    damaged_chunk: Optional[Damage] = None
    while True:
        stream.seek(offset)
        prefix = stream.read(9)
        if len(prefix) < 9:
            content.truncated = True
            where = ' inside a record header' if prefix else ''
            content.report(offset, f'the file ends at byte {size}{where} (no summary or '
                           'footer): cut short')
            return
        opcode, length = _RECORD.unpack_from(prefix)
        if length > size - offset - 9:
            _cut_record(content, stream, offset, opcode == ops.CHUNK, size, length)
            return
        body = stream.read(length)
        try:
            if opcode == 0:  # reserved by the spec: zeros or garbage, not a record
                raise RecordDamage('opcode 0')
            if chunked and opcode in (ops.MESSAGE, ops.SCHEMA, ops.CHANNEL):
                raise RecordDamage(f'opcode {opcode} outside the chunks of a chunked file')
            if opcode == ops.CHUNK:
                chunked, damaged_chunk = True, _chunk_in_sequence(mcap, body, offset, content)
            elif opcode in kinds:
                _take_simple(kinds[opcode], parse_record(mcap, kinds[opcode], body), content,
                             damaged_chunk)
            elif opcode == ops.MESSAGE:
                if length < 22:
                    raise RecordDamage(f'message record of {length} bytes')
                channel_id, _, log_time, _ = struct.unpack_from('<HIQQ', body)
                content.add_message(channel_id, body[22:], log_time)
            elif opcode in (ops.DATA_END, ops.FOOTER):
                if not footer_seen:
                    content.truncated = True
                    content.report(offset, 'no intact footer after the complete data section '
                                   '(cut short in the summary, or footer damaged)', lost={})
                return
        except RecordDamage as err:
            content.report(offset, f'record framing broken ({err}); the remaining '
                           f'{size - offset} bytes are unread')
            return
        offset += 9 + length


def _chunk_in_sequence(mcap: SimpleNamespace, body: Body, offset: int, content: FileContent
                       ) -> Optional[Damage]:
    """Take a chunk met in a sequential read; return its damage entry if it is damaged."""
    header = chunk_header(body)  # RecordDamage here: its framing is broken, stop reading
    try:
        _take_chunk(mcap, body, content)
    except RecordDamage as err:
        return content.report(offset, f'damaged chunk skipped: {err}', start_ns=header.start_ns,
                              end_ns=header.end_ns)
    return None


def _take_simple(kind: str, record: Any, content: FileContent,
                 damaged_chunk: Optional[Damage]) -> None:
    if kind == 'Schema':
        content.schemas[record.id] = record
    elif kind == 'Channel':
        _add_channel(content, record)
    elif kind == 'Metadata':
        content.metadata[record.name] = dict(record.metadata)
    elif damaged_chunk is not None:  # the Message Index records that follow a chunk
        lost = damaged_chunk.lost if damaged_chunk.lost is not None else {}
        topic = content.topic_of(record.channel_id)
        lost[topic] = lost.get(topic, 0) + len(record.records)
        damaged_chunk.lost = lost
        damaged_chunk.topics = tuple(sorted(lost))


def _cut_record(content: FileContent, stream: BinaryIO, offset: int, is_chunk: bool, size: int,
                length: int) -> None:
    content.truncated = True
    fields: dict[str, int] = {}
    if is_chunk and size - offset - 9 >= 16:
        start_ns, end_ns = struct.unpack('<QQ', _read_at(stream, offset + 9, 16))
        fields = {'start_ns': start_ns, 'end_ns': end_ns}
    kind = 'chunk' if is_chunk else 'record'
    content.report(offset, f'the file ends at byte {size}, inside a {kind} of {length} bytes '
                   '(cut short, or its length is damaged)', **fields)
