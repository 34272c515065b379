"""
Survey of one MCAP file for :mod:`pentapod_sim.recording.recover`: what is intact, what is not.

The file is walked record by record from the start (a file cut by a crash has no summary to
jump by). Every record length is checked against the file end before anything is read, every
record must parse to its exact length, and every chunk is verified as
:mod:`pentapod_sim.analysis.bag.mcap_chunks` describes (decompressed size, CRC-32 when the
writer set one). What fails is a :class:`DamagedRange` (byte range, reason, messages lost per
channel when the Message Index records that follow a chunk tell, log-time span of a chunk):

* a chunk whose content fails but whose framing holds (its record length equals its header
  plus its records length) is skipped, and the walk goes on after it;
* a record whose framing is broken (opcode 0 or reserved, a length past the file end, a record
  that does not parse to its length and is not followed by a plausible record) starts a
  search for the next chunk whose lengths agree and whose content verifies; the bytes in
  between are lost. ``mcap recover`` (Go) stops at such a record;
* a chunk cut by the end of the file keeps the records that are complete before the cut when
  its compression allows (none: every complete record; zstd, lz4: whole compressed blocks).
  The chunk's CRC covers all its records, so these messages cannot be CRC-checked: they are
  counted as *unverified*, and must also carry a known channel and a log time inside the
  chunk header's span.

The second pass (:func:`~.chunk_salvage.chunk_content` on the same bytes) hands the intact
records to the writer, so nothing but offsets and counts is held between the passes.
"""
from __future__ import annotations

import dataclasses
import mmap
import os
from pathlib import Path
import struct
from types import SimpleNamespace
from typing import Any, Callable, Optional, TYPE_CHECKING
import zlib

import numpy as np

from pentapod_sim.analysis.bag.mcap_chunks import Int64s, parse_record, RecordDamage
from pentapod_sim.errors import BagError
from pentapod_sim.recording.chunk_salvage import (
    api,
    chunk_content,
    CHUNK_FIXED,
    chunk_span,
    ChunkContent,
    framed,
    MESSAGE,
    OP,
    RECORD,
)

if TYPE_CHECKING:       # the classes come from api() at run time (InternalsChanged if changed)
    from mcap import records

MAGIC = b'\x89MCAP0\r\n'
_SUMMARY_OPS = {8, 10, 13, 14}             # chunk, attachment, metadata index; summary offset


@dataclasses.dataclass
class DamagedRange:
    """
    Bytes of a file that gave no intact record.

    ``lost`` is ``{channel id: messages}`` where the file tells (a damaged chunk's Message Index
    records), None where it does not; ``start_ns``, ``end_ns`` the log-time span of a chunk.
    """

    start: int
    end: int
    reason: str
    lost: Optional[dict[int, int]] = None
    start_ns: Optional[int] = None
    end_ns: Optional[int] = None


@dataclasses.dataclass
class Piece:
    """A part to copy: ``kind`` 'chunk', 'messages' (a run of them), 'metadata', 'attachment'."""

    kind: str
    offset: int
    end: int                   # end of the bytes used (the file end for a cut chunk)
    complete: bool = True      # False: a cut chunk, its complete records kept unverified
    count: int = 0             # messages of a chunk kept (a cut chunk: its first ``count``)
    record: records.Metadata | records.Attachment | None = None   # of those two kinds


@dataclasses.dataclass
class FileSurvey:
    """What :func:`survey_file` found in one file."""

    path: Path
    size: int
    header: Optional[records.Header] = None
    schemas: dict[int, records.Schema] = dataclasses.field(default_factory=dict)
    channels: dict[int, records.Channel] = dataclasses.field(default_factory=dict)
    pieces: list[Piece] = dataclasses.field(default_factory=list)
    damage: list[DamagedRange] = dataclasses.field(default_factory=list)
    times: dict[int, list[Int64s]] = dataclasses.field(default_factory=dict)  # log times [ns]
    loose: dict[int, list[int]] = dataclasses.field(default_factory=dict)     # same, unchunked
    unverified: dict[int, int] = dataclasses.field(default_factory=dict)   # channel -> messages
    payloads: dict[int, list[bytes]] = dataclasses.field(default_factory=dict)  # CDR bytes
    statistics: Optional[dict[int, int]] = None  # channel -> messages, from a CRC-checked summary
    footer: bool = False
    compression: Optional[str] = None   # of the first intact chunk

    def log_times(self, channel: int) -> Int64s:
        """(N,) int64 log times [ns] of the messages kept on ``channel``, in file order."""
        parts = self.times.get(channel, []) + [np.array(self.loose.get(channel, []), np.int64)]
        return np.concatenate(parts)

    def counts(self) -> dict[int, int]:
        """``{channel id: messages kept}``."""
        return {c: len(self.log_times(c)) for c in set(self.times) | set(self.loose)}


def survey_file(path: Path, payload_topics: frozenset[str] = frozenset(),
                keep_unverified: bool = True,
                progress: Optional[Callable[[int, int], None]] = None) -> FileSurvey:
    """
    Survey one MCAP file (see the module docstring).

    Parameters
    ----------
    path : Path
        The file.
    payload_topics : frozenset of str
        Topics whose message bytes are kept in ``payloads`` (the run status: a few messages).
    keep_unverified : bool
        Keep the complete records of a chunk cut by the file end (not CRC-checkable).
    progress : callable, optional
        Called as ``progress(bytes done, file size)`` after each record.

    Raises
    ------
    BagError
        If the file is empty or holds no MCAP record at all.
    InternalsChanged
        If the mcap record classes used here are missing or changed.
    """
    survey = FileSurvey(Path(path), 0)
    with open(path, 'rb') as stream:
        survey.size = os.fstat(stream.fileno()).st_size
        if survey.size == 0:
            raise BagError(f'{path} is empty')
        with mmap.mmap(stream.fileno(), 0, access=mmap.ACCESS_READ) as data:
            _Walker(api(), data, survey, payload_topics, keep_unverified).run(progress)
    if survey.header is None and not survey.pieces:
        raise BagError(f'{path} is not an MCAP file (no intact MCAP record in it)')
    return survey


@dataclasses.dataclass
class _Summary:
    """Records of the summary section, used once its CRC is checked."""

    schemas: dict[int, records.Schema] = dataclasses.field(default_factory=dict)
    channels: dict[int, records.Channel] = dataclasses.field(default_factory=dict)
    statistics: Optional[records.Statistics] = None


class _Walker:
    """One walk through the records of a file (see the module docstring)."""

    def __init__(self, mcap: SimpleNamespace, data: mmap.mmap, survey: FileSurvey,
                 payload_topics: frozenset[str], keep_unverified: bool) -> None:
        self.mcap, self.data, self.survey, self.size = mcap, data, survey, len(data)
        self.payload_topics, self.keep_unverified = payload_topics, keep_unverified
        self.skipped: Optional[DamagedRange] = None   # a damaged chunk: its indexes follow
        self.summary = _Summary()
        self.ended = False        # past the data section (a Data End or summary record seen)

    def damage(self, start: int, end: int, reason: str, lost: Optional[dict[int, int]] = None,
               start_ns: Optional[int] = None, end_ns: Optional[int] = None) -> DamagedRange:
        lost = {} if lost is None and self.ended else lost   # past the data: nothing lost
        entry = DamagedRange(int(start), int(end), reason, lost, start_ns, end_ns)
        self.survey.damage.append(entry)
        return entry

    def run(self, progress: Optional[Callable[[int, int], None]] = None) -> None:
        pos: Optional[int] = len(MAGIC)
        if self.data[:len(MAGIC)] != MAGIC:
            self.damage(0, min(len(MAGIC), self.size), 'file magic damaged', lost={})
        while pos is not None and pos < self.size:
            pos = self.step(pos)
            if progress is not None and pos is not None:
                progress(pos, self.size)
        if pos == self.size and not self.survey.footer:
            self.damage(self.size, self.size, f'the file ends at byte {self.size} without a '
                        'footer (cut short)')

    def plausible(self, pos: int) -> bool:
        """True if a record can start at ``pos`` (or the file ends there)."""
        if pos == self.size:
            return True
        if self.size - pos < 9:
            return False
        opcode, length = RECORD.unpack_from(self.data, pos)
        return (0 < opcode < 0x10 or opcode >= 0x80) and length <= self.size - pos - 9

    def step(self, pos: int) -> Optional[int]:
        """Take the record at ``pos``; return where the walk goes on (None: it ends)."""
        if self.size - pos < 9:
            self.damage(pos, self.size, f'the file ends at byte {self.size} inside a record '
                        'header (cut short)')
            return None
        opcode, length = RECORD.unpack_from(self.data, pos)
        if opcode == 0 or 0x10 <= opcode < 0x80:
            return self.resync(pos, f'opcode {opcode} is no record')
        end = pos + 9 + length
        if length > self.size - pos - 9:
            if opcode == OP.CHUNK and self.cut_chunk(pos, length):
                return None
            return self.resync(pos, f'record of {length} bytes (opcode {opcode}) runs past '
                               f'the file end at byte {self.size}: cut short, or its length '
                               'is damaged')
        body = self.data[pos + 9:end]
        if opcode != OP.MESSAGE_INDEX:
            self.skipped = None
        try:
            self.take(opcode, pos, end, body)
        except RecordDamage as err:
            if opcode == OP.CHUNK and framed(body):
                self.skipped = self.damage(pos, end, f'damaged chunk skipped: {err}',
                                           **chunk_span(body))
                return end
            if self.plausible(end):
                self.damage(pos, end, f'damaged record (opcode {opcode}) skipped: {err}')
                return end
            return self.resync(pos, f'record (opcode {opcode}) does not parse: {err}')
        return None if opcode == OP.FOOTER else end

    def take(self, opcode: int, pos: int, end: int, body: bytes) -> None:
        """Use one record whose bytes are all present; RecordDamage if it does not parse."""
        survey, mcap = self.survey, self.mcap
        if opcode == OP.CHUNK:
            self.add_chunk(pos, end, chunk_content(mcap, body, complete=True))
        elif opcode == OP.MESSAGE:
            if len(body) < MESSAGE.size or survey.compression is not None:
                raise RecordDamage('a message record outside the chunks of a chunked file')
            channel, _, log_time, _ = MESSAGE.unpack_from(body)
            if channel not in survey.channels:
                raise RecordDamage(f'a message on channel {channel} without Channel record')
            last = survey.pieces[-1] if survey.pieces else None
            if last is not None and last.kind == 'messages' and last.end == pos:
                last.end = end                 # a run of message records: one piece
            else:
                survey.pieces.append(Piece('messages', pos, end))
            survey.loose.setdefault(channel, []).append(log_time)
            self.keep_payload(channel, body[MESSAGE.size:])
        elif opcode in (OP.SCHEMA, OP.CHANNEL):
            record = parse_record(mcap, 'Schema' if opcode == OP.SCHEMA else 'Channel', body)
            self.add_other(record, self.summary if self.ended else None)
        elif opcode == OP.MESSAGE_INDEX:
            index: records.MessageIndex = parse_record(mcap, 'MessageIndex', body)
            if self.skipped is not None:
                lost = self.skipped.lost if self.skipped.lost is not None else {}
                lost[index.channel_id] = lost.get(index.channel_id, 0) + len(index.records)
                self.skipped.lost = lost
        elif opcode == OP.METADATA:
            survey.pieces.append(Piece('metadata', pos, end, record=parse_record(
                mcap, 'Metadata', body)))
        elif opcode == OP.ATTACHMENT:
            record = parse_record(mcap, 'Attachment', body)
            (crc,) = struct.unpack_from('<I', body, len(body) - 4)
            if crc and zlib.crc32(body[:-4]) != crc:
                raise RecordDamage('attachment CRC mismatch')
            survey.pieces.append(Piece('attachment', pos, end, record=record))
        elif opcode == OP.HEADER:
            survey.header = parse_record(mcap, 'Header', body)
        elif opcode == OP.STATISTICS:
            self.summary.statistics = parse_record(mcap, 'Statistics', body)
        elif opcode == OP.DATA_END:
            self.ended = True
        elif opcode == OP.FOOTER:
            self.footer(pos, parse_record(mcap, 'Footer', body))
        elif opcode in _SUMMARY_OPS:
            self.ended = True      # indexes are rebuilt by the writer

    def add_other(self, record: records.Schema | records.Channel,
                  summary: Optional[_Summary]) -> None:
        """A Schema or Channel record; one of the summary waits for the summary's CRC."""
        kind = 'channels' if hasattr(record, 'topic') else 'schemas'
        known: dict[int, Any] = getattr(self.survey, kind)
        if summary is not None and record.id not in known:
            getattr(summary, kind)[record.id] = record
        else:
            known.setdefault(record.id, record)

    def add_chunk(self, pos: int, end: int, content: ChunkContent) -> int:
        """Register a chunk's records; return its messages kept."""
        survey = self.survey
        for record in content.others:
            self.add_other(record, None)
        rows = content.messages
        if content.cut:                    # unverified: known channels, times in the span
            ok = np.isin(rows[:, 0], list(survey.channels)) & (rows[:, 2] >= content.start_ns)
            ok &= rows[:, 2] <= content.end_ns
            bad = np.flatnonzero(~ok)
            rows = rows[:bad[0]] if len(bad) else rows
        if content.cut and not len(rows):
            return 0
        if survey.compression is None:
            survey.compression = content.compression
        survey.pieces.append(Piece('chunk', pos, end, complete=not content.cut, count=len(rows)))
        for channel in np.unique(rows[:, 0]).tolist():
            mine = rows[:, 0] == channel
            survey.times.setdefault(channel, []).append(rows[mine, 2])
            if content.cut:
                survey.unverified[channel] = survey.unverified.get(channel, 0) + int(mine.sum())
            channel_record = survey.channels.get(channel)
            if channel_record is not None and channel_record.topic in self.payload_topics:
                for start, size in rows[mine][:, 4:6].tolist():
                    self.keep_payload(channel, content.data[start:start + size])
        return len(rows)

    def keep_payload(self, channel: int, payload: bytes) -> None:
        record = self.survey.channels.get(channel)
        if record is not None and record.topic in self.payload_topics:
            self.survey.payloads.setdefault(channel, []).append(bytes(payload))

    def cut_chunk(self, pos: int, length: int) -> bool:
        """A chunk cut by the file end: keep its complete records; False if not framed so."""
        body = self.data[pos + 9:self.size]
        if len(body) >= CHUNK_FIXED.size + 8 and not framed(body, length):
            return False
        span = chunk_span(body)
        try:
            content = chunk_content(self.mcap, body, complete=False)
        except RecordDamage as err:
            self.damage(pos, self.size, f'the file ends inside a chunk ({err}); nothing of it '
                        'is decodable', **span)
            return True
        kept = self.add_chunk(pos, self.size, content) if self.keep_unverified else 0
        n = kept if self.keep_unverified else len(content.messages)
        what = 'no message record is complete before the cut'
        if n:
            verb = 'kept' if self.keep_unverified else 'dropped (keep_unverified off)'
            what = (f'{verb} the {n} messages whose records are complete before the cut (not '
                    'CRC-checkable: the CRC covers the whole chunk)')
        self.damage(pos, self.size, f'the file ends inside a chunk of {length} bytes (cut '
                    f'short): {what}', **span)
        return True

    def resync(self, pos: int, reason: str) -> Optional[int]:
        """Find the next chunk after ``pos`` that verifies; the bytes before it are lost."""
        found = pos + 1
        while True:
            found = self.data.find(bytes([OP.CHUNK]), found)
            if found < 0:
                tail = self.data[pos:self.size]
                zeros = ' (all zero bytes)' if not tail.strip(b'\x00') else ''
                self.damage(pos, self.size, f'{reason}; no intact chunk after it: bytes '
                            f'{pos}..{self.size}{zeros} unread')
                return None
            if self.is_chunk_at(found):
                self.damage(pos, found, f'{reason}; bytes {pos}..{found} skipped up to the '
                            'next intact chunk')
                return found
            found += 1

    def is_chunk_at(self, pos: int) -> bool:
        """True if an intact chunk (or a framed chunk cut by the file end) starts at ``pos``."""
        if self.size - pos < 9 + CHUNK_FIXED.size + 8:
            return False
        length = RECORD.unpack_from(self.data, pos)[1]
        head = self.data[pos + 9:pos + 9 + CHUNK_FIXED.size + 24]
        if not framed(head, length):
            return False
        if length > self.size - pos - 9:
            return True                    # cut by the file end: step() takes what it can
        body = self.data[pos + 9:pos + 9 + length]
        try:
            content = chunk_content(self.mcap, body, complete=True)
        except RecordDamage:
            return False
        if CHUNK_FIXED.unpack_from(body)[3]:
            return True                    # CRC checked
        known = set(self.survey.channels) | {r.id for r in content.others if hasattr(r, 'topic')}
        rows = content.messages            # no CRC: every message must make sense
        return bool(len(rows)) and bool(np.isin(rows[:, 0], list(known)).all()) and bool(
            ((rows[:, 2] >= content.start_ns) & (rows[:, 2] <= content.end_ns)).all())

    def footer(self, pos: int, footer: records.Footer) -> None:
        """Check the summary's CRC; a good summary adds its channels and statistics."""
        self.survey.footer = True
        summary, start = self.summary, footer.summary_start
        if start and footer.summary_crc:
            crc = zlib.crc32(self.data[start:pos + 9 + 16]) if start <= pos else None
            if crc != footer.summary_crc:
                self.damage(start, pos, 'summary section damaged (CRC mismatch): ignored and '
                            'rebuilt', lost={})
                return
        for key, schema in summary.schemas.items():
            self.survey.schemas.setdefault(key, schema)
        for key, channel in summary.channels.items():
            self.survey.channels.setdefault(key, channel)
        if summary.statistics is not None:
            self.survey.statistics = dict(summary.statistics.channel_message_counts)
