"""
Recover a bag whose writer died: a valid MCAP with summary, a new metadata.yaml, the losses.

:func:`recover_bag` reads every MCAP file of a bag without trusting its summary
(:mod:`pentapod_sim.recording.salvage`: records checked against the file end, chunks against
their CRC, a framing break bridged to the next intact chunk, a chunk cut by the end of the file
kept up to its last complete record) and writes what is intact with the mcap package's own
``Writer``: same schemas, channels (QoS metadata included), message bytes, log and publish
times, sequence numbers, metadata records and attachments, in file order, with chunk and
message indexes, statistics and footer; then the rosbag2 ``metadata.yaml`` and the MCAP
``rosbag2`` record for the recovered content. What was lost is a
:class:`~pentapod_sim.recording.recovery_report.Recovery` (per topic: kept, lost, steps
missing), also stored in the output as the metadata record :data:`RECOVERY_RECORD` and in
``custom_data`` as ``pentapod_recovery.<key>``.

It lives in :mod:`pentapod_sim.recording` because it makes a bag the recorder left behind
whole again (the scenario runner calls it when a recorder dies), and it uses only the readers'
verified chunk parsing from :mod:`pentapod_sim.analysis.bag`; it imports no ROS. docs/recording.md
compares it with ``mcap recover`` and ``ros2 bag reindex``.
"""
from __future__ import annotations

import logging
import os
from pathlib import Path
import shutil
from typing import Any, Callable, Mapping, Optional

import numpy as np
import numpy.typing as npt
import yaml

from pentapod_sim.analysis.bag.mcap_chunks import InternalsChanged
from pentapod_sim.errors import BagError
from pentapod_sim.interface import is_step_topic, RUN_STATUS
from pentapod_sim.recording.recovery_report import (
    last_run_status,
    LostRange,
    Recovery,
    step_gaps,
    TopicRecovery,
)
from pentapod_sim.recording.recovery_writer import ORIGINALS, RECOVERY_RECORD, write_bag
from pentapod_sim.recording.run_end import RunStatus
from pentapod_sim.recording.salvage import FileSurvey, survey_file

LOGGER = logging.getLogger(__name__)
#: Default output: the bag folder's name with this suffix, next to it.
SUFFIX = '-recovered'
__all__ = ['ORIGINALS', 'recover_bag', 'RECOVERY_RECORD', 'SUFFIX']
#: Topic -> log times [ns] of its kept messages, per file and chunk.
_Stamps = dict[str, list[npt.NDArray[np.int64]]]


def recover_bag(bag: str | os.PathLike[str], output: str | os.PathLike[str] | None = None, *,
                in_place: bool = False, expected_steps: Optional[int] = None,
                keep_unverified: bool = True, dry_run: bool = False,
                progress: Optional[Callable[[str, int, int], None]] = None) -> Recovery:
    """
    Rewrite a bag (folder or ``.mcap`` file) whose MCAP files lack a footer or are damaged.

    Parameters
    ----------
    bag : str or Path
        Bag folder (metadata.yaml, if readable, names its files; else its ``*.mcap``) or one
        ``.mcap`` file.
    output : str or Path, optional
        Folder of the recovered bag (must not exist or be empty); default ``<bag>-recovered``
        next to the bag.
    in_place : bool
        Replace the bag folder's files by the recovered ones and move the originals into its
        subfolder ``before-recovery/`` (nothing is moved if the bag was intact).
    expected_steps : int, optional
        Steps the run had, if the caller knows (the runner: the plant's last status);
        otherwise the run status recorded in the bag tells.
    keep_unverified : bool
        Keep the complete records of a chunk cut by the end of a file (they cannot be
        CRC-checked; the report counts them).
    dry_run : bool
        Only survey and report; write nothing.
    progress : callable, optional
        Called often as ``progress(phase, bytes done, bytes of the file)`` (phase e.g.
        ``'survey run_0.mcap'``, ``'write run_0.mcap'``).

    Returns
    -------
    Recovery
        What was kept and lost; ``describe()`` gives the report.

    Raises
    ------
    BagError
        If there is no bag, nothing in it is MCAP, or the output folder is not empty.
    """
    source = Path(bag)
    files, yaml_info = _bag_files(source)
    if in_place and not source.is_dir():
        raise BagError(f'{source}: in-place recovery needs a bag folder, not a file')
    out = _output_folder(source, output, in_place)
    try:
        surveys = [survey_file(f, frozenset({RUN_STATUS}), keep_unverified,
                               _phase(progress, f'survey {f.name}')) for f in files]
    except InternalsChanged as err:
        raise BagError(f'cannot recover with this mcap version ({err}); install the one '
                       'requirements.txt pins') from None
    except OSError as err:
        raise BagError(f'cannot read {source}: {err}') from None
    recovery = _report(source, surveys, yaml_info, expected_steps)
    if dry_run or (in_place and recovery.intact):
        recovery.output = None if dry_run else source
        return recovery
    target = out
    if in_place:                   # written next to the bag, then swapped in
        target = out.parent / f'.{out.name}.recovering'
        shutil.rmtree(target, ignore_errors=True)
    created = not target.exists()
    try:
        target.mkdir(parents=True, exist_ok=True)
        write_bag(target, out.name, surveys, recovery, yaml_info, progress)
    except OSError as err:      # a full disk, most likely: the damaged bag is unchanged
        if created or in_place:
            shutil.rmtree(target, ignore_errors=True)
        raise BagError(f'cannot write the recovered bag to {target}: {err}; {source} is '
                       'unchanged') from None
    if in_place:
        _swap_in(source, target)
    recovery.output = out
    LOGGER.info('%s', recovery.describe())
    return recovery


def _bag_files(source: Path) -> tuple[list[Path], dict[str, Any]]:
    """The MCAP files of a bag and its metadata.yaml (``{}`` if absent or unreadable)."""
    if source.is_file():
        return [source], {}
    if not source.is_dir():
        raise BagError(f'no bag at {source}')
    info: Any = {}             # the YAML document, until it is checked to be a mapping
    meta = source / 'metadata.yaml'
    if meta.is_file():
        try:
            info = yaml.safe_load(meta.read_text(encoding='utf-8'))['rosbag2_bagfile_information']
            files = [source / Path(f).name for f in info['relative_file_paths']]
            if files and all(f.is_file() for f in files):
                return files, info
        except (yaml.YAMLError, KeyError, TypeError, UnicodeDecodeError) as err:
            LOGGER.warning('%s: unreadable (%s); using the .mcap files of the folder', meta, err)
            info = {}
    files = sorted(source.glob('*.mcap'))
    if not files:
        raise BagError(f'bag folder {source} holds no .mcap file')
    return files, info if isinstance(info, dict) else {}


def _output_folder(source: Path, output: str | os.PathLike[str] | None, in_place: bool) -> Path:
    if in_place:
        if output is not None:
            raise BagError('give either an output folder or in-place recovery, not both')
        if (source / ORIGINALS).exists():
            raise BagError(f'{source / ORIGINALS} exists: this bag was recovered in place '
                           'before; recover it into another folder')
        return source
    name = source.stem if source.is_file() else source.name
    out = Path(output) if output is not None else source.parent / f'{name}{SUFFIX}'
    if out.resolve() == source.resolve() or (out.exists() and any(out.iterdir())):
        raise BagError(f'output folder {out} exists and is not empty')
    return out


def _listed(yaml_info: Mapping[str, Any]) -> dict[str, int]:
    """Messages per topic that metadata.yaml counted (the writer's last flush)."""
    try:
        return {e['topic_metadata']['name']: int(e['message_count'])
                for e in yaml_info.get('topics_with_message_count') or []}
    except (KeyError, TypeError, ValueError):
        return {}


def _report(source: Path, surveys: list[FileSurvey], yaml_info: Mapping[str, Any],
            expected_steps: Optional[int]) -> Recovery:
    """Kept, lost and missing steps per topic, from the surveys and the bag's own counts."""
    topics: dict[str, TopicRecovery] = {}
    damage: list[LostRange] = []
    statuses: list[dict[str, str]] = []
    stamps: _Stamps = {}
    exact_totals = all(s.statistics is not None for s in surveys)
    expected: dict[str, int] = {}
    for survey in surveys:
        name = survey.path.name
        kept = survey.counts()
        orphans: dict[str, int] = {}          # 'channel <id>' -> messages
        for channel, n in kept.items():
            record = survey.channels.get(channel)
            if record is None:
                orphans[f'channel {channel}'] = n
                continue
            schema = survey.schemas.get(record.schema_id)
            entry = topics.setdefault(record.topic, TopicRecovery(
                record.topic, schema.name if schema else '', 0))
            entry.kept += n
            entry.unverified += survey.unverified.get(channel, 0)
            stamps.setdefault(record.topic, []).append(survey.log_times(channel))
        for record in survey.channels.values():
            schema = survey.schemas.get(record.schema_id)
            topics.setdefault(record.topic, TopicRecovery(record.topic,
                                                          schema.name if schema else '', 0))
        for channel, n in (survey.statistics or {}).items():
            topic = _topic(survey, channel)
            expected[topic] = expected.get(topic, 0) + n
        for d in survey.damage:
            lost = None if d.lost is None else {_topic(survey, c): n for c, n in d.lost.items()}
            damage.append(LostRange(name, d.start, d.end, d.reason, lost, d.start_ns, d.end_ns))
        if orphans:
            damage.append(LostRange(name, 0, 0, 'messages on channels whose Channel record '
                                    'was in a damaged part (not written)', orphans))
        for channel, payloads in survey.payloads.items():
            statuses += _status_values(survey, channel, payloads)
    unknown = any(d.lost is None for d in damage)
    for entry in yaml_info.get('topics_with_message_count') or []:
        try:       # a topic whose Channel record was lost: only metadata.yaml names it
            meta = entry['topic_metadata']
            topics.setdefault(meta['name'], TopicRecovery(meta['name'], str(meta['type']), 0))
        except (KeyError, TypeError):
            continue
    for topic, entry in topics.items():
        known = sum((d.lost or {}).get(topic, 0) for d in damage)
        entry.listed = _listed(yaml_info).get(topic)
        if exact_totals:
            entry.lost, entry.lost_exact = max(expected.get(topic, 0) - entry.kept, 0), True
        else:
            floor = (entry.listed or 0) - entry.kept
            entry.lost, entry.lost_exact = max(known, floor, 0), not unknown and floor <= known
    recovery = Recovery(source, None, [s.path.name for s in surveys], damage, topics)
    _steps(recovery, last_run_status(statuses), expected_steps, stamps)
    return recovery


def _topic(survey: FileSurvey, channel: int) -> str:
    record = survey.channels.get(channel)
    return record.topic if record is not None else f'channel {channel}'


def _status_values(survey: FileSurvey, channel: int,
                   payloads: list[bytes]) -> list[dict[str, str]]:
    """Key/value mappings of the run-status messages (undecodable ones are left out)."""
    from mcap_ros2.decoder import DecoderFactory  # only for bags with a run status
    schema = survey.schemas.get(survey.channels[channel].schema_id)
    try:
        decode = DecoderFactory().decoder_for('cdr', schema)
    except Exception:  # noqa: BLE001 - mcap_ros2's schema parser raises several types
        return []
    if decode is None:
        return []
    values = []
    for payload in payloads:
        try:
            values.append({kv.key: kv.value for kv in decode(payload).values})
        except Exception:  # noqa: BLE001 - a status that does not decode is not used
            continue
    return values


def _steps(recovery: Recovery, status: Optional[RunStatus], expected_steps: Optional[int],
           stamps: _Stamps) -> None:
    """Expected and missing steps of the per-step topics."""
    recovery.run = status
    steps, exact = None, False
    if expected_steps is not None:
        steps, exact = int(expected_steps), True
        recovery.notes.append(f'expected steps {steps}: given by the caller')
    elif status is not None:
        steps, exact = status.steps, status.ended
        if not exact:
            recovery.notes.append('the run was still running at its last recorded status: '
                                  f'it had at least {steps} steps')
    recovery.expected_steps, recovery.steps_exact = steps, exact
    if steps is None or status is None or status.dt <= 0:
        return
    dt_ns = int(round(status.dt * 1e9))
    first_ns = status.last_stamp_ns - (status.steps - 1) * dt_ns
    for topic, entry in recovery.topics.items():
        if topic in status.step_topics or (is_step_topic(topic) and entry.kept):
            times = np.concatenate(stamps.get(topic, [np.zeros(0, np.int64)]))
            # the recorder logs a stamped message (all per-step types) at its stamp
            entry.steps = step_gaps(times, steps, exact, dt_ns, first_ns)


def _phase(progress: Optional[Callable[[str, int, int], None]],
           phase: str) -> Optional[Callable[[int, int], None]]:
    if progress is None:
        return None
    return lambda done, total: progress(phase, done, total)


def _swap_in(bag: Path, target: Path) -> None:
    """Move the bag's files into ``bag/before-recovery/`` and the recovered ones into ``bag``."""
    keep = bag / ORIGINALS
    keep.mkdir()
    for path in sorted(bag.iterdir()):      # also a metadata.yaml.tmp the writer left
        if path != keep and path.is_file():
            path.replace(keep / path.name)
    for path in sorted(target.iterdir()):
        path.replace(bag / path.name)
    target.rmdir()

