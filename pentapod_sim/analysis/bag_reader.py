"""
Read rosbag2 MCAP bags (ours or any ros2 profile MCAP) ROS-free into numpy arrays.

The MCAP is read sequentially (``mcap.stream_reader.StreamReader``), not through its summary,
so a bag cut short by a crash still yields every complete chunk; the loss is reported with a
warning. Files that are not MCAP raise :class:`pentapod_sim.errors.BagError`.

Field specifications (``TOPIC.FIELD``; topic names contain no dots):

* JointState: ``position.<name>``, ``velocity.<name>``, ``effort.<name>`` (also
  ``<name>.position``)
* WrenchStamped: ``force.x`` ... ``torque.z`` (``wrench.`` prefix optional)
* Clock: ``clock``
* any other type: a dotted attribute path decoded with mcap_ros2 (slow, per message)

Times are header stamps (simulation time) [s] when the type has one, else MCAP log times.
"""
import dataclasses
import logging
from pathlib import Path
import struct
from typing import Optional
import warnings

from mcap.exceptions import McapError
from mcap.records import Channel, Chunk, Message, Metadata, Schema
from mcap.stream_reader import StreamReader
import numpy as np
import yaml

from pentapod_sim.analysis import cdr_arrays
from pentapod_sim.analysis.mcap_chunks import split_chunk
from pentapod_sim.analysis.message_store import MessageStore
from pentapod_sim.errors import BagError

LOGGER = logging.getLogger(__name__)
STAMPED_TYPES = ('sensor_msgs/msg/JointState', 'geometry_msgs/msg/WrenchStamped',
                 'rosgraph_msgs/msg/Clock')
WRENCH_FIELDS = ('force.x', 'force.y', 'force.z', 'torque.x', 'torque.y', 'torque.z')


@dataclasses.dataclass
class TopicData:
    """Raw messages of one topic: CDR payloads and their MCAP log times [ns]."""

    name: str
    msg_type: str
    schema_text: str
    payloads: MessageStore = dataclasses.field(default_factory=MessageStore)
    _times: list = dataclasses.field(default_factory=list)

    @property
    def count(self) -> int:
        """Number of messages."""
        return len(self.payloads)

    @property
    def log_time_ns(self) -> np.ndarray:
        """(N,) int64 MCAP log times [ns]."""
        if len(self._times) != 1:
            self._times = [np.concatenate([np.atleast_1d(t) for t in self._times])
                           if self._times else np.zeros(0, np.int64)]
        return self._times[0]


@dataclasses.dataclass
class Series:
    """
    One recorded signal.

    Attributes
    ----------
    time : (N,) ndarray
        Time [s] (header stamp if present, else log time).
    values : (N,) ndarray
        Samples in SI units.
    unit : str
        Unit of ``values``.
    label : str
        ``TOPIC.FIELD`` it came from.
    time_ns : (N,) int64 ndarray
        Exact integer times [ns], for aligning two series.
    """

    time: np.ndarray
    values: np.ndarray
    unit: str
    label: str
    time_ns: np.ndarray


def joint_unit(field: str, name: str) -> str:
    """Guess the SI unit of a JointState field from the testbed's naming (docs/architecture)."""
    angular = 'bending' in name or name.endswith(('_rx', '_ry', '_rz'))
    if field == 'effort':
        return 'N m' if ('moment' in name or angular) else 'N'
    base = 'rad' if angular else 'm'
    return base if field == 'position' else f'{base}/s'


class Bag:
    """
    A recorded bag loaded into memory.

    Parameters
    ----------
    path : str or Path
        Bag folder (with metadata.yaml and/or ``*.mcap``) or a single ``.mcap`` file.
    topics : list of str, optional
        Load only these topics (saves memory: their bytes are copied out of each chunk).

    Attributes
    ----------
    topics : dict
        ``{topic: TopicData}``.
    custom_data : dict
        Run information (metadata.yaml custom_data merged with MCAP ``pentapod_run`` record).
    truncated : bool
        True when a file ended early (crash); only its complete part was loaded.
    """

    def __init__(self, path, topics: Optional[list] = None) -> None:
        self.path = Path(path)
        self.wanted = set(topics) if topics is not None else None
        self.topics: dict = {}
        self.custom_data: dict = {}
        self.mcap_metadata: dict = {}
        self.metadata_yaml: Optional[dict] = None
        self.truncated = False
        for file in self._mcap_files():
            self._read_file(file)
        if self.metadata_yaml:
            self.custom_data.update(self.metadata_yaml.get('custom_data') or {})
        self.custom_data.update(self.mcap_metadata.get('pentapod_run', {}))

    def _mcap_files(self) -> list:
        if self.path.is_file():
            return [self.path]
        if not self.path.is_dir():
            raise BagError(f'no bag at {self.path}')
        meta = self.path / 'metadata.yaml'
        if meta.is_file():
            try:
                doc = yaml.safe_load(meta.read_text(encoding='utf-8'))
                self.metadata_yaml = doc['rosbag2_bagfile_information']
                files = [self.path / f for f in self.metadata_yaml['relative_file_paths']]
                if all(f.is_file() for f in files):
                    return files
            except (yaml.YAMLError, KeyError, TypeError) as err:
                warnings.warn(f'{meta}: unreadable ({err}); using the .mcap files of the folder')
        files = sorted(self.path.glob('*.mcap'))
        if not files:
            raise BagError(f'bag folder {self.path} holds no .mcap file')
        return files

    def _read_file(self, file: Path) -> None:
        schemas, channels, n_before = {}, {}, self.message_count
        with open(file, 'rb') as stream:
            try:
                reader = StreamReader(stream, emit_chunks=True, record_size_limit=2**31)
                for n_records, record in enumerate(reader.records):
                    self._take(record, schemas, channels)
                    if n_records % 5000 == 4999:  # progress on large bags
                        LOGGER.info('%s: %d MB read', file.name, stream.tell() >> 20)
            except McapError as err:
                if self.message_count == n_before and not channels:
                    raise BagError(f'{file} is not a readable MCAP file: {err!r}') from None
                self._warn_truncated(file, err)
            except (ValueError, EOFError, OSError, struct.error) as err:
                if not channels:
                    raise BagError(f'{file} is not a readable MCAP file: {err!r}') from None
                self._warn_truncated(file, err)
        LOGGER.info('read %s: %d messages', file, self.message_count - n_before)

    def _warn_truncated(self, file: Path, err: Exception) -> None:
        self.truncated = True
        warnings.warn(f'{file} ends early ({type(err).__name__}); loaded the readable part: '
                      f'{self.message_count} messages')

    def _take(self, record, schemas: dict, channels: dict) -> None:
        if isinstance(record, Chunk):
            data, channel_ids, times, starts, lengths, others = split_chunk(record)
            for other in others:
                self._take(other, schemas, channels)
            for channel_id in np.unique(channel_ids):
                topic = channels.get(int(channel_id))
                if topic is not None:
                    mine = channel_ids == channel_id
                    segment = (data, starts[mine], lengths[mine])
                    if self.wanted is not None:
                        segment = _compact(*segment)  # do not keep the whole chunk alive
                    topic.payloads.add_segment(*segment)
                    topic._times.append(times[mine])
        elif isinstance(record, Message):
            topic = channels.get(record.channel_id)
            if topic is not None:
                topic.payloads.append(record.data)
                topic._times.append(np.array([record.log_time], dtype=np.int64))
        elif isinstance(record, Schema):
            schemas[record.id] = record
        elif isinstance(record, Channel):
            schema = schemas.get(record.schema_id)
            name = schema.name if schema else ''
            if record.topic not in self.topics:
                text = schema.data.decode('utf-8', 'replace') if schema else ''
                self.topics[record.topic] = TopicData(record.topic, name, text)
            if self.wanted is None or record.topic in self.wanted:
                channels[record.id] = self.topics[record.topic]
        elif isinstance(record, Metadata):
            self.mcap_metadata[record.name] = dict(record.metadata)

    @property
    def message_count(self) -> int:
        """Messages loaded (all topics)."""
        return sum(t.count for t in self.topics.values())

    def topic(self, name: str) -> TopicData:
        """Return the data of one topic; BagError naming the available topics if absent."""
        if name not in self.topics:
            raise BagError(f'topic {name!r} not in bag {self.path}; it has {sorted(self.topics)}')
        return self.topics[name]

    def times_ns(self, name: str) -> np.ndarray:
        """Header stamps [ns] of a stamped topic, else its log times [ns]."""
        data = self.topic(name)
        if data.msg_type in STAMPED_TYPES and data.count:
            return cdr_arrays.stamps_ns(data.payloads)
        return data.log_time_ns

    def fields(self, name: str) -> list:
        """List the field specs :meth:`series` accepts for a topic (known types only)."""
        data = self.topic(name)
        if data.msg_type == 'sensor_msgs/msg/JointState' and data.count:
            names, values = cdr_arrays.joint_state_arrays([data.payloads[0]])
            return [f'{f}.{n}' for f in cdr_arrays.JOINT_STATE_FIELDS for k, n in enumerate(names)
                    if not np.isnan(values[f][0, k])]
        if data.msg_type == 'geometry_msgs/msg/WrenchStamped':
            return list(WRENCH_FIELDS)
        if data.msg_type == 'rosgraph_msgs/msg/Clock':
            return ['clock']
        return []

    def series(self, spec: str) -> Series:
        """
        Load one signal ``TOPIC.FIELD`` (see the module docstring).

        Raises
        ------
        BagError
            If the topic or field is absent (the message lists what exists).
        """
        topic, _, field = spec.partition('.')
        data = self.topic(topic)
        if data.count == 0:
            raise BagError(f'topic {topic!r} in {self.path} has no messages')
        if data.msg_type == 'sensor_msgs/msg/JointState':
            values, unit = self._joint_field(data, field)
        elif data.msg_type == 'geometry_msgs/msg/WrenchStamped':
            values, unit = self._wrench_field(data, field)
        elif data.msg_type == 'rosgraph_msgs/msg/Clock':
            ns = cdr_arrays.stamps_ns(data.payloads)
            values, unit = ns * 1e-9, 's'
        else:
            values, unit = _generic_field(data, field), ''
        t_ns = self.times_ns(topic)
        return Series(t_ns * 1e-9, values, unit, spec, t_ns)

    def _joint_field(self, data: TopicData, field: str) -> tuple:
        first, _, second = field.partition('.')
        if second in cdr_arrays.JOINT_STATE_FIELDS and first not in cdr_arrays.JOINT_STATE_FIELDS:
            first, second = second, first
        if first not in cdr_arrays.JOINT_STATE_FIELDS:
            layout = cdr_arrays.joint_state_layout(data.payloads[0])
            _unknown_joint_field(data, field, layout.names)
        column, names = cdr_arrays.joint_state_column(data.payloads, first, second)
        if second not in names:
            _unknown_joint_field(data, field, names)
        if np.all(np.isnan(column)):
            raise BagError(f'{data.name} carries no {first} values for {second!r}')
        return column, joint_unit(first, second)

    @staticmethod
    def _wrench_field(data: TopicData, field: str) -> tuple:
        field = field.removeprefix('wrench.')
        if field not in WRENCH_FIELDS:
            raise BagError(f'field {field!r} not in {data.name}; use one of {WRENCH_FIELDS}')
        index = WRENCH_FIELDS.index(field)
        return cdr_arrays.wrench_arrays(data.payloads, index), 'N' if index < 3 else 'N m'


def _generic_field(data: TopicData, field: str) -> np.ndarray:
    """Decode a dotted numeric field of any type with mcap_ros2 (one object per message)."""
    from mcap.records import Schema as McapSchema
    from mcap_ros2.decoder import DecoderFactory
    schema = McapSchema(id=1, name=data.msg_type, encoding='ros2msg',
                        data=data.schema_text.encode('utf-8'))
    decode = DecoderFactory().decoder_for('cdr', schema)
    if decode is None:
        raise BagError(f'cannot decode type {data.msg_type!r} of {data.name}')
    out = np.empty(data.count)
    for k, payload in enumerate(data.payloads):
        value = decode(payload)
        try:
            for part in field.split('.'):
                value = getattr(value, part)
            out[k] = float(value)
        except (AttributeError, TypeError, ValueError):
            raise BagError(f'field {field!r} of {data.name} ({data.msg_type}) is not a '
                           'numeric attribute path') from None
    return out


def _unknown_joint_field(data: TopicData, field: str, names: list) -> None:
    """Raise BagError listing the JointState fields that exist."""
    choices = [f'{f}.{n}' for f in cdr_arrays.JOINT_STATE_FIELDS for n in names]
    raise BagError(f'field {field!r} not in {data.name}; use one of {choices}')


def _compact(data: np.ndarray, starts: np.ndarray, lengths: np.ndarray) -> tuple:
    """Copy the given messages of a chunk into a new contiguous array; return a segment."""
    ends = np.cumsum(lengths)
    new_starts = ends - lengths
    positions = np.arange(int(ends[-1]) if len(ends) else 0) + np.repeat(starts - new_starts,
                                                                          lengths)
    return data[positions], new_starts, lengths


def open_bag(path, topics: Optional[list] = None) -> Bag:
    """
    Load a bag folder or .mcap file.

    Parameters
    ----------
    path : str or Path
        Bag folder or ``.mcap`` file.
    topics : list of str, optional
        Load only these topics (others are listed in ``topics`` without messages).

    Returns
    -------
    Bag
    """
    return Bag(path, topics)
