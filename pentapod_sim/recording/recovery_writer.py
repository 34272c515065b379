"""
Writing of a recovered bag for :mod:`pentapod_sim.recording.recover`, with the mcap ``Writer``.

Each surveyed file becomes ``<name>_<k>.mcap``: its header (profile kept, library extended),
schemas and channels (metadata included, ids renumbered by the writer), then its intact pieces
in file order (messages with their bytes, log and publish times and sequence numbers; metadata
records; attachments), the :data:`RECOVERY_RECORD` and a new ``rosbag2`` record; the writer
adds chunk and message indexes, statistics and the summary. An old ``rosbag2`` record (the
writer's close had begun) is replaced, since it describes the bag before the loss.
"""
from __future__ import annotations

import datetime
from pathlib import Path
from types import SimpleNamespace
from typing import Any, Callable, Mapping, Optional, Sequence

from mcap.records import Attachment, Metadata
from mcap.writer import CompressionType, Writer
import yaml

from pentapod_sim import __version__
from pentapod_sim.errors import BagError
from pentapod_sim.recording.chunk_salvage import api, chunk_content, MESSAGE, RECORD
from pentapod_sim.recording.recovery_report import Recovery
from pentapod_sim.recording.rosbag2_metadata import (
    bagfile_information,
    FileEntry,
    record_text,
    ROSBAG2_RECORD,
    RUN_METADATA_NAME,
    TopicEntry,
    write_metadata_yaml,
)
from pentapod_sim.recording.salvage import FileSurvey

#: Name of the MCAP metadata record (and custom_data prefix) describing the recovery.
RECOVERY_RECORD = 'pentapod_recovery'
#: Folder inside a bag recovered in place that keeps the damaged originals.
ORIGINALS = 'before-recovery'
#: Chunk size of the output [bytes]: rosbag2's MCAP default.
CHUNK_SIZE = 768 * 1024
_COMPRESSION = {'': CompressionType.NONE, 'zstd': CompressionType.ZSTD,
                'lz4': CompressionType.LZ4}


def write_bag(folder: Path, name: str, surveys: Sequence[FileSurvey], recovery: Recovery,
              yaml_info: Mapping[str, Any],
              progress: Optional[Callable[[str, int, int], None]] = None) -> None:
    """Write the recovered files, the ``rosbag2`` record and metadata.yaml into ``folder``."""
    mcap = api()
    custom = {str(k): str(v) for k, v in (yaml_info.get('custom_data') or {}).items()}
    if not custom:
        found = (p.record for s in surveys for p in s.pieces if isinstance(p.record, Metadata))
        custom = next((dict(r.metadata) for r in found if r.name == RUN_METADATA_NAME), {})
    record = recovery.record()
    record.update(recovered_utc=datetime.datetime.now(datetime.timezone.utc).isoformat(
        timespec='seconds'), package_version=__version__)
    custom.update({f'{RECOVERY_RECORD}.{k}': v for k, v in record.items()})
    entries, written = _entries(surveys, name)
    topics = _topic_entries(surveys, recovery)
    info = bagfile_information(entries, topics, custom,
                               str(yaml_info.get('ros_distro') or 'jazzy'))
    for entry, survey in zip(entries, surveys):
        counts = _write_file(mcap, folder / entry.path, survey, record, record_text(info),
                             progress)
        if counts != written[entry.path]:
            raise BagError(f'{survey.path} changed while it was recovered ({counts} messages '
                           f'written, {written[entry.path]} surveyed)')
    write_metadata_yaml(folder, info)


def _entries(surveys: Sequence[FileSurvey],
             name: str) -> tuple[list[FileEntry], dict[str, dict[int, int]]]:
    """metadata.yaml ``files`` entries and, per file, messages per channel to be written."""
    entries: list[FileEntry] = []
    written: dict[str, dict[int, int]] = {}
    for k, survey in enumerate(surveys):
        path = f'{name}_{k}.mcap'
        kept = {c: n for c, n in survey.counts().items() if c in survey.channels and n}
        times = [survey.log_times(c) for c in kept]
        start = min((int(t.min()) for t in times), default=None)
        end = max((int(t.max()) for t in times), default=None)
        entries.append(FileEntry(path, sum(kept.values()), start, end))
        written[path] = kept
    return entries, written


def _topic_entries(surveys: Sequence[FileSurvey], recovery: Recovery) -> list[TopicEntry]:
    """metadata.yaml topics with the QoS text of their MCAP channel (rosbags compares them)."""
    found: dict[str, TopicEntry] = {}
    for survey in surveys:
        for record in survey.channels.values():
            if record.topic in found:
                continue
            text = record.metadata.get('offered_qos_profiles', '')
            try:
                qos = yaml.safe_load(text) if text else []
            except yaml.YAMLError:
                qos = text
            found[record.topic] = TopicEntry(
                record.topic, recovery.topics[record.topic].msg_type,
                qos if isinstance(qos, list) else text, recovery.topics[record.topic].kept,
                record.message_encoding, record.metadata.get('topic_type_hash', ''))
    return list(found.values())


def _write_file(mcap: SimpleNamespace, path: Path, survey: FileSurvey, record: dict[str, str],
                rosbag2: str,
                progress: Optional[Callable[[str, int, int], None]]) -> dict[int, int]:
    """Write one recovered MCAP file; return messages written per (source) channel."""
    header = survey.header
    counts: dict[int, int] = {}
    with open(path, 'wb') as stream, open(survey.path, 'rb') as source:
        writer = Writer(stream, chunk_size=CHUNK_SIZE,
                        compression=_COMPRESSION.get(survey.compression or '',
                                                     CompressionType.NONE))
        library = f'{header.library}; ' if header is not None and header.library else ''
        writer.start(profile=header.profile if header is not None else 'ros2',
                     library=f'{library}recovered by pentapod_testbed {__version__}')
        schemas = {0: 0}
        for key, schema in sorted(survey.schemas.items()):
            schemas[key] = writer.register_schema(schema.name, schema.encoding, schema.data)
        channels = {key: writer.register_channel(c.topic, c.message_encoding,
                                                 schemas.get(c.schema_id, 0), dict(c.metadata))
                    for key, c in sorted(survey.channels.items())}
        for piece in survey.pieces:
            if progress is not None:
                progress(f'write {path.name}', piece.offset, survey.size)
            source.seek(piece.offset)
            raw = source.read(piece.end - piece.offset)
            parsed = piece.record
            if isinstance(parsed, Metadata):
                if parsed.name != ROSBAG2_RECORD:
                    writer.add_metadata(parsed.name, dict(parsed.metadata))
            elif isinstance(parsed, Attachment):
                writer.add_attachment(parsed.create_time, parsed.log_time, parsed.name,
                                      parsed.media_type, parsed.data)
            elif piece.kind == 'chunk':
                content = chunk_content(mcap, raw[9:], piece.complete)
                rows = content.messages if piece.complete else content.messages[:piece.count]
                data = content.data
                for channel, sequence, log, publish, start, size in rows.tolist():
                    if channel in channels:
                        writer.add_message(channels[channel], log, data[start:start + size],
                                           publish, sequence)
                        counts[channel] = counts.get(channel, 0) + 1
            elif piece.kind == 'messages':
                _copy_messages(writer, raw, channels, counts)
        writer.add_metadata(RECOVERY_RECORD, record)
        writer.add_metadata(ROSBAG2_RECORD, {'serialized_metadata': rosbag2})
        writer.finish()
    return counts


def _copy_messages(writer: Writer, raw: bytes, channels: Mapping[int, int],
                   counts: dict[int, int]) -> None:
    """Copy a run of Message records (an unchunked file)."""
    off = 0
    while off < len(raw):
        _, length = RECORD.unpack_from(raw, off)
        channel, sequence, log, publish = MESSAGE.unpack_from(raw, off + 9)
        if channel in channels:
            start = off + 9 + MESSAGE.size
            writer.add_message(channels[channel], log, raw[start:off + 9 + length], publish,
                               sequence)
            counts[channel] = counts.get(channel, 0) + 1
        off += 9 + length
