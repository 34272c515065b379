"""
The rosbag2 side of a bag: the ``metadata.yaml`` document and the MCAP ``rosbag2`` record.

One home for the layout that :class:`~pentapod_sim.recording.bag_writer.BagWriter` writes while
it records and that :func:`pentapod_sim.recording.recover.recover_bag` writes for a recovered
bag: rosbag2 version 9, storage ``mcap``, durations in ns, one ``files`` entry per MCAP file.
"""
from __future__ import annotations

import dataclasses
import os
from pathlib import Path
from typing import Any, Mapping, Optional, Sequence

import yaml

ROSBAG2_VERSION = 9
#: Name of the MCAP metadata record in which rosbag2 keeps the metadata at the close of a bag.
ROSBAG2_RECORD = 'rosbag2'
#: Name of the MCAP metadata record with the run information of the testbed.
RUN_METADATA_NAME = 'pentapod_run'


@dataclasses.dataclass
class TopicEntry:
    """One ``topics_with_message_count`` entry (QoS as a list of dicts, or YAML text)."""

    name: str
    msg_type: str
    qos_profiles: list[dict[str, Any]] | str
    count: int
    serialization_format: str = 'cdr'
    type_description_hash: str = ''


@dataclasses.dataclass
class FileEntry:
    """One MCAP file of a bag: its name, message count and log-time span [ns] (None: empty)."""

    path: str
    count: int
    start_ns: Optional[int] = None
    end_ns: Optional[int] = None


def _span(start_ns: Optional[int], end_ns: Optional[int]) -> tuple[int, int]:
    start = start_ns or 0
    return start, (end_ns - start) if end_ns is not None else 0


def bagfile_information(files: Sequence[FileEntry], topics: Sequence[TopicEntry],
                        custom_data: Mapping[str, str],
                        ros_distro: str = 'jazzy') -> dict[str, Any]:
    """
    Build the ``rosbag2_bagfile_information`` mapping of a bag.

    Parameters
    ----------
    files : sequence of FileEntry
        The bag's MCAP files in order.
    topics : sequence of TopicEntry
        The topics with their message counts (all files).
    custom_data : mapping
        Run information (str to str).
    ros_distro : str
        ROS distribution named in the metadata.

    Returns
    -------
    dict
    """
    starts = [f.start_ns for f in files if f.start_ns is not None]
    ends = [f.end_ns for f in files if f.end_ns is not None]
    start, duration = _span(min(starts) if starts else None, max(ends) if ends else None)
    entries = []
    for f in files:
        f_start, f_duration = _span(f.start_ns, f.end_ns)
        entries.append({'path': f.path, 'starting_time': {'nanoseconds_since_epoch': f_start},
                        'duration': {'nanoseconds': f_duration}, 'message_count': f.count})
    return {
        'version': ROSBAG2_VERSION,
        'storage_identifier': 'mcap',
        'relative_file_paths': [f.path for f in files],
        'duration': {'nanoseconds': duration},
        'starting_time': {'nanoseconds_since_epoch': start},
        'message_count': sum(f.count for f in files),
        'topics_with_message_count': [
            {'topic_metadata': {'name': t.name, 'type': t.msg_type,
                                'serialization_format': t.serialization_format,
                                'offered_qos_profiles': t.qos_profiles,
                                'type_description_hash': t.type_description_hash},
             'message_count': t.count}
            for t in topics],
        'compression_format': '',
        'compression_mode': '',
        'files': entries,
        'custom_data': dict(custom_data),
        'ros_distro': ros_distro,
    }


def dump_yaml(data: object) -> str:
    """YAML text of ``data`` in writing order, repeated objects written in full (no anchors)."""
    return yaml.dump(data, Dumper=_NoAliasDumper, sort_keys=False)


def record_text(info: Mapping[str, Any]) -> str:
    """The ``serialized_metadata`` value of the MCAP ``rosbag2`` record for ``info``."""
    return dump_yaml(dict(info)).strip()


def write_metadata_yaml(folder: Path, info: Mapping[str, Any]) -> None:
    """Atomically (write + rename) replace ``folder``/metadata.yaml with ``info``."""
    text = dump_yaml({'rosbag2_bagfile_information': dict(info)})
    tmp = Path(folder) / 'metadata.yaml.tmp'
    tmp.write_text(text, encoding='utf-8')
    os.replace(tmp, Path(folder) / 'metadata.yaml')


# PyYAML carries no type information here, so its classes are Any to the type checker
class _NoAliasDumper(yaml.SafeDumper):  # type: ignore[misc]
    """Safe YAML dumper that writes repeated objects in full (no &id anchors)."""

    def ignore_aliases(self, data: object) -> bool:
        return True
