"""
Read one MCAP file with the mcap package's public API (``mcap.reader.make_reader``).

The fallback of the fast reader (:mod:`pentapod_sim.analysis.bag.mcap_scan`) for when the mcap
internals it uses are missing or changed; it fills the same
:class:`~pentapod_sim.analysis.bag.file_content.FileContent`, so the same CDR decoders
(:mod:`pentapod_sim.analysis.bag.cdr_arrays`) read the result. It is slower (one Python object
per message) and coarser on damage: messages come in file order with chunk CRCs checked, and
the first damaged or missing record ends the read of the file (reported; the loss counted from
the summary statistics or metadata.yaml). Reads from the file are clamped to its size, so a
damaged record length cannot make it allocate more than the file holds.
"""
import os
from pathlib import Path
from typing import BinaryIO, cast, IO

from mcap.reader import make_reader, McapReader

from pentapod_sim.analysis.bag.file_content import FileContent, UnreadableBagError


class _FileWindow:
    """A read-only file stream whose reads never ask for more than the file holds."""

    def __init__(self, raw: BinaryIO, seekable: bool) -> None:
        self._raw = raw
        self._size = os.fstat(raw.fileno()).st_size
        self._seekable = seekable

    def read(self, size: int | None = -1) -> bytes:
        left = max(self._size - self._raw.tell(), 0)
        return self._raw.read(left if size is None or size < 0 else min(size, left))

    def seekable(self) -> bool:
        return self._seekable

    def seek(self, offset: int, whence: int = 0) -> int:
        return self._raw.seek(offset, whence)

    def tell(self) -> int:
        return self._raw.tell()


def _reader(raw: BinaryIO, seekable: bool, validate_crcs: bool = False) -> McapReader:
    """``make_reader`` on a :class:`_FileWindow` of ``raw``."""
    # make_reader is typed for IO[bytes]; it calls read, seek, tell and seekable only
    window = cast(IO[bytes], _FileWindow(raw, seekable))
    return make_reader(window, validate_crcs=validate_crcs)


def read_file(path: Path, content: FileContent) -> None:
    """
    Read one MCAP file into ``content`` with ``mcap.reader`` (see the module docstring).

    Raises
    ------
    UnreadableBagError
        If not even the file's start is MCAP.
    """
    content.reader = 'mcap.reader'
    with open(path, 'rb') as raw:
        _summary_counts(raw, content)
        raw.seek(0)
        reader = _reader(raw, seekable=False, validate_crcs=True)
        try:
            for schema, channel, message in reader.iter_messages(log_time_order=False):
                if channel.id not in content.channels:
                    if schema is not None:
                        content.schemas[schema.id] = schema
                    content.add_channel(channel.id, channel.topic, channel.schema_id)
                content.add_message(channel.id, message.data, message.log_time)
        # The public API documents no exception types for damaged input: whatever it raises
        # ends this file's read, and is reported with the loss, never as a traceback.
        except Exception as err:  # noqa: BLE001
            if not content.channels:
                raise UnreadableBagError(f'{path} is not a readable MCAP file: {err!r}') from None
            content.truncated = content.expected is None
            content.report(raw.tell(), f'{type(err).__name__} ({err}) from mcap.reader; the '
                           'rest of the file is unread')
        _metadata(raw, content)
    content.finish()


def _summary_counts(raw: BinaryIO, content: FileContent) -> None:
    """Channels and expected messages per topic from the summary, if it is readable."""
    try:
        summary = _reader(raw, seekable=True).get_summary()
        if summary is None:
            return
        content.schemas.update(summary.schemas)
        for channel in summary.channels.values():
            content.add_channel(channel.id, channel.topic, channel.schema_id)
        if summary.statistics is not None:
            expected: dict[str, int] = {}
            for channel_id, count in summary.statistics.channel_message_counts.items():
                topic = content.topic_of(channel_id)
                expected[topic] = expected.get(topic, 0) + count
            content.expected = expected
    except Exception:  # noqa: BLE001 - a cut file has no summary: counts come from metadata
        return


def _metadata(raw: BinaryIO, content: FileContent) -> None:
    """Metadata records: through the summary's index, else read in sequence up to a damage."""
    for seekable in (True, False):
        raw.seek(0)
        found: dict[str, dict[str, str]] = {}
        try:
            for record in _reader(raw, seekable).iter_metadata():
                found[record.name] = dict(record.metadata)
        except Exception:  # noqa: BLE001 - the damage is reported by the message read
            if seekable:
                continue
        content.metadata.update(found)
        return
