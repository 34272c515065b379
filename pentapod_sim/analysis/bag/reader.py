"""
Read rosbag2 MCAP bags (ours or any ros2 profile MCAP) ROS-free into numpy arrays.

Each file is read by the fast, verifying reader (:mod:`pentapod_sim.analysis.bag.mcap_scan`):
chunk CRCs and record lengths are checked, a damaged chunk is skipped, a file cut by a crash
yields every intact chunk, and each loss is a :class:`~.bag_file.Damage` in ``Bag.damage``
(file, byte, reason, topics, log-time span, messages lost) plus one
:class:`~.bag_file.BagDamageWarning` per bag. If the mcap internals that reader uses are
missing or changed, files are read with the public ``mcap.reader`` API instead
(:mod:`pentapod_sim.analysis.bag.mcap_public`, one :class:`~.bag_file.McapInternalsWarning`).
Files that are not MCAP, or hold nothing readable, raise :class:`~.bag_file.UnreadableBagError`
(a :class:`pentapod_sim.errors.BagError`).

Field specifications (``TOPIC.FIELD``; topic names contain no dots):

* JointState: ``position.<name>``, ``velocity.<name>``, ``effort.<name>`` (also
  ``<name>.position``)
* WrenchStamped: ``force.x`` ... ``torque.z`` (``wrench.`` prefix optional)
* Clock: ``clock``
* any other type: a dotted attribute path decoded with mcap_ros2 (slow, per message)

Times are header stamps (simulation time) [s] when the type has one, else MCAP log times.
"""
from __future__ import annotations

import dataclasses
import logging
import os
from pathlib import Path
from typing import Any, NoReturn, Optional, TYPE_CHECKING
import warnings

import numpy as np
import numpy.typing as npt
import yaml

from pentapod_sim.analysis.bag import cdr_arrays, mcap_public, mcap_scan
from pentapod_sim.analysis.bag.file_content import (
    BagDamageWarning,
    Damage,
    FileContent,
    McapInternalsWarning,
    reconcile,
    UnreadableBagError,
)
from pentapod_sim.analysis.bag.mcap_chunks import InternalsChanged
from pentapod_sim.analysis.bag.message_store import MessageStore
from pentapod_sim.errors import BagError

if TYPE_CHECKING:
    from mcap.records import Schema

LOGGER = logging.getLogger(__name__)
STAMPED_TYPES = ('sensor_msgs/msg/JointState', 'geometry_msgs/msg/WrenchStamped',
                 'rosgraph_msgs/msg/Clock')
WRENCH_FIELDS = ('force.x', 'force.y', 'force.z', 'torque.x', 'torque.y', 'torque.z')
READERS = ('fast', 'mcap.reader')
YAML_LOADER = getattr(yaml, 'CSafeLoader', yaml.SafeLoader)  # libyaml: 20x faster
#: Why the fast reader cannot be used in this process (set once, with the one warning).
FALLBACK: dict[str, Optional[str]] = {'reason': None}


@dataclasses.dataclass
class TopicData:
    """Raw messages of one topic: CDR payloads and their MCAP log times [ns]."""

    name: str
    msg_type: str
    schema_text: str
    payloads: MessageStore = dataclasses.field(default_factory=MessageStore)
    _times: list[npt.NDArray[np.int64]] = dataclasses.field(default_factory=list)
    schema: Optional[Schema] = None  # the file's mcap Schema record (for mcap_ros2)

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
    reader : str
        ``'fast'`` (default; falls back to ``'mcap.reader'`` if mcap's internals changed) or
        ``'mcap.reader'`` (the public API, slower, stops a file at its first damage).

    Attributes
    ----------
    topics : dict
        ``{topic: TopicData}``.
    custom_data : dict
        Run information (metadata.yaml custom_data merged with MCAP ``pentapod_run`` record).
    damage : list of Damage
        Damaged or missing parts; their messages were skipped, everything else was read.
    truncated : bool
        True when a file ended early (crash); only its complete part was loaded.
    reader : str
        The reader that read the files.
    """

    def __init__(self, path: str | os.PathLike[str], topics: Optional[list[str]] = None,
                 reader: str = 'fast') -> None:
        if reader not in READERS:
            raise BagError(f'unknown bag reader {reader!r}; use one of {READERS}')
        self.path = Path(path)
        self.wanted = set(topics) if topics is not None else None
        self.topics: dict[str, TopicData] = {}
        self.custom_data: dict[str, Any] = {}
        self.mcap_metadata: dict[str, dict[str, str]] = {}
        self.metadata_yaml: Optional[dict[str, Any]] = None
        self.damage: list[Damage] = []
        self.truncated = False
        self.reader = reader
        for file in self._mcap_files():
            self._merge(self._read_file(file))
        if self.metadata_yaml:
            self.custom_data.update(self.metadata_yaml.get('custom_data') or {})
            if any(d.lost is None for d in self.damage):
                self._reconcile_with_metadata_yaml()
        self.custom_data.update(self.mcap_metadata.get('pentapod_run', {}))
        if not self.topics:
            raise UnreadableBagError(f'nothing readable in {self.path}: '
                                     + '; '.join(d.describe() for d in self.damage))
        if self.damage:
            warnings.warn(BagDamageWarning(self.damage_summary()), stacklevel=3)

    def _mcap_files(self) -> list[Path]:
        if self.path.is_file():
            return [self.path]
        if not self.path.is_dir():
            raise BagError(f'no bag at {self.path}')
        meta = self.path / 'metadata.yaml'
        if meta.is_file():
            try:
                doc = yaml.load(meta.read_text(encoding='utf-8'), Loader=YAML_LOADER)
                self.metadata_yaml = doc['rosbag2_bagfile_information']
                files = [self.path / f for f in self.metadata_yaml['relative_file_paths']]
                if all(f.is_file() for f in files):
                    return files
            except (yaml.YAMLError, KeyError, TypeError) as err:
                self.metadata_yaml = None
                warnings.warn(f'{meta}: unreadable ({err}); using the .mcap files of the folder')
        files = sorted(self.path.glob('*.mcap'))
        if not files:
            raise BagError(f'bag folder {self.path} holds no .mcap file')
        return files

    def _read_file(self, file: Path) -> FileContent:
        """Read one file with the fast reader, or with mcap.reader if its internals changed."""
        content = FileContent(file, self.wanted)
        try:
            if self.reader == 'fast' and FALLBACK['reason'] is None:
                try:
                    mcap_scan.read_file(file, content)
                    return content
                except InternalsChanged as err:
                    _fall_back(err)
                    content = FileContent(file, self.wanted)
            mcap_public.read_file(file, content)
        except UnreadableBagError as err:
            content = FileContent(file, self.wanted)
            content.report(0, str(err))
        except OSError as err:
            raise BagError(f'cannot read {file}: {err}') from None
        return content

    def _merge(self, content: FileContent) -> None:
        for info in content.channels.values():
            if info.topic not in self.topics:
                self.topics[info.topic] = TopicData(info.topic, info.msg_type, info.schema_text,
                                                    schema=info.schema)
        for topic, segments in content.segments.items():
            for data, starts, lengths, times in segments:
                self.topics[topic].payloads.add_segment(data, starts, lengths)
                self.topics[topic]._times.append(times)
        for topic, (payloads, log_times) in content.loose.items():
            for payload in payloads:
                self.topics[topic].payloads.append(payload)
            self.topics[topic]._times.append(np.asarray(log_times, dtype=np.int64))
        self.mcap_metadata.update(content.metadata)
        self.damage.extend(content.damage)
        self.truncated |= content.truncated
        if content.reader != 'fast':
            self.reader = content.reader
        LOGGER.info('read %s (%s): %d messages, %d damaged parts', content.path,
                    content.reader, content.message_count, len(content.damage))

    def _reconcile_with_metadata_yaml(self) -> None:
        """Count what a cut file lost from metadata.yaml's per-topic message counts."""
        if self.metadata_yaml is None:
            return
        try:
            expected = {entry['topic_metadata']['name']: int(entry['message_count'])
                        for entry in self.metadata_yaml['topics_with_message_count']}
        except (KeyError, TypeError, ValueError):
            return
        read = {name: data.count for name, data in self.topics.items()}
        reconcile(self.damage, expected, read, self.wanted, 'metadata.yaml', 'metadata.yaml')

    def damage_summary(self) -> str:
        """The damage in one paragraph (the text of the BagDamageWarning)."""
        state = 'ends early (cut short)' if self.truncated else 'is damaged'
        parts = ' | '.join(d.describe() for d in self.damage)
        return (f'bag {self.path} {state}: loaded the intact part, {self.message_count} '
                f'messages; {len(self.damage)} damaged or missing part(s): {parts}')

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

    def fields(self, name: str) -> list[str]:
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
        values: npt.NDArray[np.floating[Any]]
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

    def _joint_field(self, data: TopicData, field: str) -> tuple[npt.NDArray[np.float64], str]:
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
    def _wrench_field(data: TopicData, field: str) -> tuple[npt.NDArray[np.float64], str]:
        field = field.removeprefix('wrench.')
        if field not in WRENCH_FIELDS:
            raise BagError(f'field {field!r} not in {data.name}; use one of {WRENCH_FIELDS}')
        index = WRENCH_FIELDS.index(field)
        return cdr_arrays.wrench_arrays(data.payloads, index), 'N' if index < 3 else 'N m'


def _generic_field(data: TopicData, field: str) -> np.ndarray:
    """Decode a dotted numeric field of any type with mcap_ros2 (one object per message)."""
    from mcap_ros2.decoder import DecoderFactory
    try:
        decode = DecoderFactory().decoder_for('cdr', data.schema)
    except Exception as err:  # noqa: BLE001 - mcap_ros2's schema parser raises several types
        raise BagError(f'cannot decode type {data.msg_type!r} of {data.name}: {err}') from None
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


def _unknown_joint_field(data: TopicData, field: str, names: list[str]) -> NoReturn:
    """Raise BagError listing the JointState fields that exist."""
    choices = [f'{f}.{n}' for f in cdr_arrays.JOINT_STATE_FIELDS for n in names]
    raise BagError(f'field {field!r} not in {data.name}; use one of {choices}')


def open_bag(path: str | os.PathLike[str], topics: Optional[list[str]] = None,
             reader: str = 'fast') -> Bag:
    """
    Load a bag folder or .mcap file.

    Parameters
    ----------
    path : str or Path
        Bag folder or ``.mcap`` file.
    topics : list of str, optional
        Load only these topics (others are listed in ``topics`` without messages).
    reader : str
        ``'fast'`` or ``'mcap.reader'`` (see :class:`Bag`).

    Returns
    -------
    Bag

    Raises
    ------
    BagError
        If there is no bag at ``path``, or nothing in it is readable.
    """
    return Bag(path, topics, reader)


def _fall_back(err: Exception) -> None:
    """Use mcap.reader from now on; say so once per process."""
    FALLBACK['reason'] = str(err)
    warnings.warn(McapInternalsWarning(
        f'the mcap internals of the fast bag reader are missing or changed ({err}); reading '
        'bags with the public mcap.reader API instead (slower, stops a file at its first '
        'damaged chunk). Install the mcap version that requirements.txt pins.'), stacklevel=5)
