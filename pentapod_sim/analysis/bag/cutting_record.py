"""
A recorded cutting run read back from its bag (ROS-free): the process's state and the TCP's.

A cutting node publishes its operation once on :data:`pentapod_sim.interface.CUTTING_SPEC` and
its state every step on :data:`pentapod_sim.interface.CUTTING_STATE` (tooth angles, chips,
tangential forces); the plant publishes the TCP displacement on
:data:`pentapod_sim.interface.TCP_STATE`. :func:`cut_record` joins them step by step (by
stamp) into a :class:`CutRecord`; :func:`chatter_of` judges it with
:func:`pentapod_sim.machining.chatter.detect_chatter` (the operation's speed and teeth, the
recorded engagement).
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pentapod_sim.analysis.bag import cdr_arrays
from pentapod_sim.analysis.bag.excitation_record import string_of
from pentapod_sim.analysis.bag.reader import Bag, open_bag
from pentapod_sim.errors import BagError, ConfigError
from pentapod_sim.interface import cutting_joints, CUTTING_SPEC, CUTTING_STATE, TCP_STATE
from pentapod_sim.machining.chatter import ChatterVerdict, detect_chatter
from pentapod_sim.machining.cutting_spec import CuttingSpec, parse_spec_message

#: The topics a cutting record needs.
CUTTING_TOPICS = [CUTTING_SPEC, CUTTING_STATE, TCP_STATE]
#: Share of a record left out by default as the entry transient (the tool enters the cut at
#: full depth at step 0).
SETTLE_SHARE = 0.25


@dataclass(frozen=True)
class CutRecord:
    """
    One recorded cutting run, step by step.

    Attributes
    ----------
    spec : CuttingSpec
        The operation as run (conditions, sample rate, operation and source name).
    time : (n,) ndarray
        t_k [s] of the steps held by both the cutting state and the TCP state.
    displacement : (n, 2) ndarray
        TCP displacement in machine x, y [m].
    angles, chip, tooth_force : (n, N) ndarray
        Immersion angle [rad], chip thickness [m] and tangential force [N] of every tooth.
    engaged, in_cut : (n, N) bool ndarray
        Tooth within the engaged angles; tooth cutting a chip (engaged and h > 0).
    bag : str
        Where it was read from.
    """

    spec: CuttingSpec
    time: np.ndarray
    displacement: np.ndarray
    angles: np.ndarray
    chip: np.ndarray
    tooth_force: np.ndarray
    engaged: np.ndarray
    in_cut: np.ndarray
    bag: str = ''


def cutting_spec_of(bag: Bag) -> CuttingSpec:
    """The operation a bag's cutting node ran (BagError if it was not recorded or is bad)."""
    data = bag.topic(CUTTING_SPEC)
    if not data.count:
        raise BagError(f'{bag.path}: {CUTTING_SPEC} holds no message')
    try:
        return parse_spec_message(string_of(data.payloads[data.count - 1]))
    except (ConfigError, UnicodeDecodeError) as err:
        raise BagError(f'{CUTTING_SPEC} in {bag.path}: {err}') from None


def _columns(bag: Bag, topic: str, joints: list[str]) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Stamps [ns] and the (n, len(joints)) arrays of every JointState field of ``joints``."""
    data = bag.topic(topic)
    if not data.count:
        raise BagError(f'{bag.path}: {topic} holds no message')
    names, values = cdr_arrays.joint_state_arrays(data.payloads)
    missing = [j for j in joints if j not in names]
    if missing:
        raise BagError(f'{bag.path}: {topic} lacks the joints {missing} (it has {names})')
    index = [names.index(j) for j in joints]
    return bag.times_ns(topic), {f: v[:, index] for f, v in values.items()}


def cut_record(bag: Bag | str | Path) -> CutRecord:
    """
    The cutting run of a bag (a path or an open :class:`Bag`).

    Raises
    ------
    BagError
        If the bag lacks the cutting record, the cutting state or the TCP state, or the two
        states share no step.
    """
    if not isinstance(bag, Bag):
        bag = open_bag(bag, topics=CUTTING_TOPICS)
    for topic in CUTTING_TOPICS:
        if topic not in bag.topics:
            raise BagError(f'{bag.path} holds no {topic}: record a run with a cutting node '
                           f'(it needs {", ".join(CUTTING_TOPICS)})')
    spec = cutting_spec_of(bag)
    cut = spec.conditions.cut
    t_cut, state = _columns(bag, CUTTING_STATE, cutting_joints(cut.teeth))
    t_tcp, tcp = _columns(bag, TCP_STATE, ['tcp_x', 'tcp_y'])
    common, i_cut, i_tcp = np.intersect1d(t_cut, t_tcp, assume_unique=False,
                                          return_indices=True)
    if common.size == 0:
        raise BagError(f'{bag.path}: {CUTTING_STATE} and {TCP_STATE} share no step')
    angles, chip = state['position'][i_cut], state['velocity'][i_cut]
    engaged = (angles >= cut.entry_angle) & (angles <= cut.exit_angle)
    return CutRecord(spec, common * 1e-9, tcp['position'][i_tcp], angles, chip,
                     state['effort'][i_cut], engaged, engaged & (chip > 0.0), str(bag.path))


def settle_time(record: CutRecord, settle: float | None = None) -> float:
    """Time [s] from the record's start left out: ``settle`` or :data:`SETTLE_SHARE` of it."""
    if settle is None:
        return SETTLE_SHARE * float(record.time[-1] - record.time[0])
    if not (settle >= 0 and settle < record.time[-1] - record.time[0]):
        raise ConfigError(f'settle = {settle!r} s must lie within the record '
                          f'({record.time[-1] - record.time[0]:.4g} s)')
    return float(settle)


def chatter_of(record: CutRecord, settle: float | None = None) -> ChatterVerdict:
    """
    The verdict on a recorded cut: stable, chatter or tool left the cut (with its figures).

    ``settle`` [s] from the start is left out (default :func:`settle_time`); the thresholds are
    :func:`pentapod_sim.machining.chatter.detect_chatter`'s.
    """
    cond = record.spec.conditions
    return detect_chatter(record.time, record.displacement, cond.spindle_speed, cond.cut.teeth,
                          settle=settle_time(record, settle), engaged=record.engaged,
                          in_cut=record.in_cut)
