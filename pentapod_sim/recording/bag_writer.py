"""
Write rosbag2-compatible MCAP bags (a folder with metadata.yaml and ``<name>_0.mcap``) ROS-free.

The file uses MCAP profile ``ros2``, ``ros2msg`` schemas with the full message definition and
``cdr`` channels whose ``offered_qos_profiles`` metadata is the very string (re-parsed) that
metadata.yaml holds, because rosbags matches connections on it (a mismatch reads 0 messages).

Crash safety: messages go into small chunks; :meth:`BagWriter.flush` (called every
``flush_period_s`` of wall time by :meth:`BagWriter.write`) closes the chunk, flushes it to
the file and rewrites metadata.yaml, so after a SIGKILL everything up to the last flush is
readable by :mod:`pentapod_sim.analysis.bag.reader` (which tolerates a missing summary).
Run information (model hash, pose, scenario, version) is stored in ``custom_data`` of
metadata.yaml and as an MCAP metadata record named ``pentapod_run`` at the start of the file.
"""
import dataclasses
import logging
import os
from pathlib import Path
import time
from typing import Any, Mapping, Optional

from mcap.writer import CompressionType, Writer

from pentapod_sim import __version__
from pentapod_sim.errors import BagError
from pentapod_sim.recording.msgdefs import message_definition
from pentapod_sim.recording.rosbag2_metadata import (
    bagfile_information,
    dump_yaml,
    FileEntry,
    record_text,
    ROSBAG2_RECORD,
    RUN_METADATA_NAME,
    TopicEntry,
    write_metadata_yaml,
)

LOGGER = logging.getLogger(__name__)


def qos_profile(reliability: str, depth: int, durability: str = 'volatile') -> dict[str, Any]:
    """
    Build one rosbag2 v9 QoS profile entry (durations 0 = infinite, rosbag2's convention).

    Parameters
    ----------
    reliability : str
        ``'reliable'`` or ``'best_effort'``.
    depth : int
        History depth [messages].
    durability : str
        ``'volatile'`` or ``'transient_local'``.

    Returns
    -------
    dict
    """
    zero = {'sec': 0, 'nsec': 0}
    return {
        'history': 'keep_last', 'depth': int(depth), 'reliability': reliability,
        'durability': durability, 'deadline': dict(zero), 'lifespan': dict(zero),
        'liveliness': 'automatic', 'liveliness_lease_duration': dict(zero),
        'avoid_ros_namespace_conventions': False,
    }


QOS_RELIABLE = qos_profile('reliable', 1000)
QOS_BEST_EFFORT = qos_profile('best_effort', 10)


@dataclasses.dataclass
class _Topic:
    name: str
    msg_type: str
    channel_id: int
    qos_profiles: list[dict[str, Any]]
    count: int = 0


class BagWriter:
    """
    Write one rosbag2 MCAP bag folder.

    Parameters
    ----------
    path : str or Path
        Bag folder to create (must not exist or be empty).
    run_info : mapping, optional
        Reproducibility data (model content hash, pose, scenario parameters, ...); values are
        converted to str. ``package_version`` is added.
    chunk_size : int
        MCAP chunk size [bytes]; small chunks lose less on a crash.
    flush_period_s : float
        Wall-time period [s] of automatic :meth:`flush` calls from :meth:`write`; 0 disables.
    compression : str
        ``''`` (none, rosbag2's default), ``'zstd'`` or ``'lz4'``.
    """

    def __init__(self, path: str | os.PathLike[str], run_info: Optional[Mapping[str, Any]] = None,
                 chunk_size: int = 64 * 1024, flush_period_s: float = 0.5,
                 compression: str = '') -> None:
        self.path = Path(path)
        compressions = {'': CompressionType.NONE, 'zstd': CompressionType.ZSTD,
                        'lz4': CompressionType.LZ4}
        if compression not in compressions:
            raise BagError(f'unknown compression {compression!r}; use one of {list(compressions)}')
        if self.path.exists() and any(self.path.iterdir()):
            raise BagError(f'bag folder {self.path} exists and is not empty')
        self.path.mkdir(parents=True, exist_ok=True)
        self.mcap_name = f'{self.path.name}_0.mcap'
        self.custom_data = {str(k): str(v) for k, v in (run_info or {}).items()}
        self.custom_data.setdefault('package_version', __version__)
        self.flush_period_s = float(flush_period_s)
        self._topics: dict[str, _Topic] = {}
        self._schemas: dict[str, int] = {}      # message type -> schema id
        self._start_ns: Optional[int] = None
        self._end_ns: Optional[int] = None
        self._last_flush = time.monotonic()
        self._closed = False
        self._stream = open(self.path / self.mcap_name, 'wb')
        self._writer = Writer(self._stream, chunk_size=chunk_size,
                              compression=compressions[compression])
        self._writer.start(profile='ros2', library=f'pentapod_testbed {__version__}')
        self._writer.add_metadata(RUN_METADATA_NAME, dict(self.custom_data))
        self.flush()

    @property
    def message_count(self) -> int:
        """Messages written so far (all topics)."""
        return sum(t.count for t in self._topics.values())

    def topic_counts(self) -> dict[str, int]:
        """Return ``{topic: messages written}``."""
        return {name: t.count for name, t in self._topics.items()}

    def add_topic(self, topic: str, msg_type: str,
                  qos_profiles: Optional[list[dict[str, Any]]] = None) -> None:
        """
        Register a topic (once) with its type ``pkg/msg/Type`` and offered QoS profiles.

        Parameters
        ----------
        topic : str
            Topic name.
        msg_type : str
            Message type, e.g. ``'sensor_msgs/msg/JointState'``.
        qos_profiles : list of dict, optional
            rosbag2 v9 QoS dicts (see :data:`QOS_RELIABLE`); default one reliable profile.
        """
        if topic in self._topics:
            if self._topics[topic].msg_type != msg_type:
                raise BagError(f'topic {topic!r} already registered with type '
                               f'{self._topics[topic].msg_type!r}, not {msg_type!r}')
            return
        if msg_type not in self._schemas:
            text = message_definition(msg_type)
            self._schemas[msg_type] = self._writer.register_schema(
                name=msg_type, encoding='ros2msg', data=text.encode('utf-8'))
        profiles = [dict(p) for p in (qos_profiles or [QOS_RELIABLE])]
        channel_id = self._writer.register_channel(
            topic=topic, message_encoding='cdr', schema_id=self._schemas[msg_type],
            metadata={'offered_qos_profiles': _dump_qos(profiles)})
        self._topics[topic] = _Topic(topic, msg_type, channel_id, profiles)
        self.write_metadata_yaml()

    def add_record(self, name: str, data: Mapping[str, Any]) -> None:
        """
        Store ``data`` as an MCAP metadata record ``name`` and in metadata.yaml.

        Values are converted to str; metadata.yaml's ``custom_data`` holds them as
        ``<name>.<key>``.
        """
        text = {str(k): str(v) for k, v in data.items()}
        self._writer.add_metadata(name, text)
        self.custom_data.update({f'{name}.{k}': v for k, v in text.items()})
        self.write_metadata_yaml()

    def write(self, topic: str, data: bytes, log_time_ns: int,
              publish_time_ns: Optional[int] = None) -> None:
        """
        Append one CDR-serialised message.

        Parameters
        ----------
        topic : str
            A topic registered with :meth:`add_topic`.
        data : bytes
            CDR bytes including the 4-byte encapsulation header.
        log_time_ns : int
            Log time [ns] (sim time of the message when it has a stamp).
        publish_time_ns : int, optional
            Publish/receive time [ns]; defaults to the log time.
        """
        entry = self._topics.get(topic)
        if entry is None:
            raise BagError(f'topic {topic!r} was not added to bag {self.path}')
        log_time_ns = int(log_time_ns)
        self._writer.add_message(
            channel_id=entry.channel_id, log_time=log_time_ns, data=data,
            publish_time=log_time_ns if publish_time_ns is None else int(publish_time_ns),
            sequence=entry.count)
        entry.count += 1
        if self._start_ns is None or log_time_ns < self._start_ns:
            self._start_ns = log_time_ns
        if self._end_ns is None or log_time_ns > self._end_ns:
            self._end_ns = log_time_ns
        if self.flush_period_s > 0 and time.monotonic() - self._last_flush > self.flush_period_s:
            self.flush()

    def flush(self) -> None:
        """Close the open chunk, push it to disk and rewrite metadata.yaml."""
        self._writer.flush()
        self._stream.flush()
        os.fsync(self._stream.fileno())
        self.write_metadata_yaml()
        self._last_flush = time.monotonic()

    def metadata(self) -> dict[str, Any]:
        """Return the rosbag2 ``rosbag2_bagfile_information`` dict for the current state."""
        files = [FileEntry(self.mcap_name, self.message_count, self._start_ns, self._end_ns)]
        topics = [TopicEntry(t.name, t.msg_type, t.qos_profiles, t.count)
                  for t in self._topics.values()]
        return bagfile_information(files, topics, self.custom_data)

    def write_metadata_yaml(self) -> None:
        """Atomically (write + rename) replace metadata.yaml with the current state."""
        write_metadata_yaml(self.path, self.metadata())

    def close(self) -> None:
        """Finish the MCAP (summary, footer, rosbag2 metadata record) and metadata.yaml."""
        if self._closed:
            return
        self._closed = True
        self._writer.add_metadata(ROSBAG2_RECORD,
                                  {'serialized_metadata': record_text(self.metadata())})
        self._writer.finish()
        self._stream.close()
        self.write_metadata_yaml()
        LOGGER.info('closed bag %s: %d messages on %d topics', self.path,
                    self.message_count, len(self._topics))

    def __enter__(self) -> 'BagWriter':
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _dump_qos(profiles: list[dict[str, Any]]) -> str:
    """Serialise QoS profiles as YAML text for the MCAP channel metadata."""
    return dump_yaml(profiles).strip()
