"""
What :func:`pentapod_sim.recording.recover.recover_bag` kept and lost, per topic and step.

Losses come from three sources, the best one available per topic:

* the summary statistics of a file whose summary survived (its CRC checked): exact;
* the Message Index records after a damaged chunk: exact for that chunk;
* metadata.yaml, which the recorder rewrites at every flush: a lower bound (messages written
  after the last flush are not in it).

Steps: the plant's run status in the bag (:mod:`pentapod_sim.recording.run_end`) says how many
steps were run; a status of a finished or stopped run gives the exact count, one of a run still
running when the recorder died a lower bound (the caller, e.g. the scenario runner, can pass the
count it knows). A per-step topic (:func:`pentapod_sim.interface.is_step_topic`) then misses the
steps whose stamp is not among its kept messages; runs of missing steps are reported as step
index and time spans.
"""
from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Mapping, Optional, Sequence

import numpy as np
import numpy.typing as npt

from pentapod_sim.errors import BagError
from pentapod_sim.recording.run_end import RunStatus

#: Runs of missing steps listed per topic (the rest are counted).
MAX_GAPS = 5


@dataclasses.dataclass
class LostRange:
    """Bytes of one file that gave no intact message (``lost``: topic -> messages, or None)."""

    file: str
    start: int
    end: int
    reason: str
    lost: Optional[dict[str, int]] = None
    start_ns: Optional[int] = None
    end_ns: Optional[int] = None

    def describe(self) -> str:
        """One line: where, why, what was lost."""
        if self.lost is None:
            loss = 'loss not known from the file'
        elif not self.lost:
            loss = 'no message lost'
        else:
            loss = 'lost ' + ', '.join(f'{t}: {n}' for t, n in sorted(self.lost.items()))
        span = ''
        if self.start_ns is not None and self.end_ns is not None:
            span = f'; log time {self.start_ns * 1e-9:.6f} .. {self.end_ns * 1e-9:.6f} s'
        return f'{self.file} bytes {self.start}..{self.end}: {self.reason}; {loss}{span}'


#: A run of missing steps: first step, last step, first stamp [s], last stamp [s].
StepRun = tuple[int, int, float, float]


@dataclasses.dataclass
class StepGaps:
    """Steps of one per-step topic: expected (``exact`` or a lower bound), missing and where."""

    expected: int
    exact: bool
    missing: int
    gaps: list[StepRun]

    def describe(self) -> str:
        expected = f'{self.expected}' if self.exact else f'>= {self.expected}'
        if not self.missing:
            return f'steps {expected}, none missing'
        spans = ', '.join(f'{a}-{b} ({ta:.6f}-{tb:.6f} s)' for a, b, ta, tb in
                          self.gaps[:MAX_GAPS])
        more = f' and {len(self.gaps) - MAX_GAPS} more runs' if len(self.gaps) > MAX_GAPS else ''
        bound = '' if self.exact else 'at least '
        return f'steps {expected}, {bound}{self.missing} missing: {spans}{more}'


@dataclasses.dataclass
class TopicRecovery:
    """
    One topic of a recovered bag.

    Attributes
    ----------
    kept : int
        Messages in the recovered bag.
    unverified : int
        Of them, messages of a chunk cut by the end of the file (not CRC-checkable).
    lost : int
        Messages lost (exact if ``lost_exact``, else a lower bound).
    listed : int or None
        Messages metadata.yaml counted at the writer's last flush.
    steps : StepGaps or None
        For a per-step topic of a bag with a run status (or an expected step count).
    """

    topic: str
    msg_type: str
    kept: int
    unverified: int = 0
    lost: int = 0
    lost_exact: bool = True
    listed: Optional[int] = None
    steps: Optional[StepGaps] = None

    def describe(self) -> str:
        text = f'{self.topic} ({self.msg_type}): {self.kept} kept'
        if self.unverified:
            text += f' ({self.unverified} of them unverified: cut chunk)'
        if not self.lost_exact and not self.lost:
            text += (', loss not known (the bag holds no count of it)' if self.listed is None
                     else ', none lost of those counted at the last flush; later ones unknown')
        elif self.lost:
            text += f', {"" if self.lost_exact else ">= "}{self.lost} lost'
        if self.listed is not None and self.listed != self.kept:
            text += f' (metadata.yaml listed {self.listed} at the last flush)'
        return text + (f'; {self.steps.describe()}' if self.steps else '')


@dataclasses.dataclass
class Recovery:
    """
    The outcome of a recovery.

    Attributes
    ----------
    source, output : Path
        The damaged bag and the recovered one (``output`` is None for a dry run).
    damage : list of LostRange
        Every damaged or missing part (empty: the bag was intact).
    topics : dict
        ``{topic: TopicRecovery}``.
    run : RunStatus or None
        The last run status found in the bag.
    expected_steps, steps_exact
        Steps the run had (``steps_exact`` False: a lower bound), None if unknown.
    """

    source: Path
    output: Optional[Path]
    files: list[str]
    damage: list[LostRange]
    topics: dict[str, TopicRecovery]
    run: Optional[RunStatus] = None
    expected_steps: Optional[int] = None
    steps_exact: bool = False
    notes: list[str] = dataclasses.field(default_factory=list)

    @property
    def intact(self) -> bool:
        """True if nothing was damaged or missing."""
        return not self.damage

    @property
    def kept(self) -> int:
        """Messages in the recovered bag."""
        return sum(t.kept for t in self.topics.values())

    def describe(self) -> str:
        """The report for people (several lines)."""
        where = f' -> {self.output}' if self.output is not None else ' (dry run: nothing written)'
        lines = [f'recover {self.source}{where}: {self.kept} messages kept; '
                 + ('intact, nothing lost' if self.intact else
                    f'{len(self.damage)} damaged or missing part(s)')]
        lines += [f'  damaged: {d.describe()}' for d in self.damage]
        if self.run is not None:
            lines.append(f'  run status in the bag: {self.run.state} after {self.run.steps} '
                         'steps')
        lines += [f'  {note}' for note in self.notes]
        lines += [f'  {t.describe()}' for _, t in sorted(self.topics.items())]
        return '\n'.join(lines)

    def record(self) -> dict[str, str]:
        """Key/value strings of the ``pentapod_recovery`` metadata record of the output."""
        lost = {t: (f'{r.lost}' if r.lost_exact else f'>= {r.lost}')
                for t, r in self.topics.items() if r.lost or not r.lost_exact}
        missing = {t: r.steps.missing for t, r in self.topics.items()
                   if r.steps and r.steps.missing}
        return {'source': str(self.source), 'files': ', '.join(self.files),
                'damage': ' | '.join(d.describe() for d in self.damage) or 'none',
                'kept': _flow({t: r.kept for t, r in self.topics.items()}),
                'unverified': _flow({t: r.unverified for t, r in self.topics.items()
                                     if r.unverified}),
                'lost': _flow(lost),
                'expected_steps': '' if self.expected_steps is None else (
                    f'{self.expected_steps}' if self.steps_exact else
                    f'>= {self.expected_steps}'),
                'missing_steps': _flow(missing)}


def _flow(mapping: Mapping[str, object]) -> str:
    """A mapping as one-line YAML (``{a: 1, b: 2}``)."""
    return '{' + ', '.join(f'{k}: {v}' for k, v in mapping.items()) + '}'


def last_run_status(values: Sequence[Mapping[str, str]]) -> Optional[RunStatus]:
    """The run status with the most steps (an ended one on a tie) among key/value mappings."""
    found = []
    for pairs in values:
        try:
            found.append(RunStatus.from_values(pairs))
        except BagError:
            continue    # a status message of another plant version: not used
    if not found:
        return None
    return max(found, key=lambda s: (s.steps, s.ended))


def step_gaps(stamps_ns: npt.NDArray[np.int64], expected: int, exact: bool, dt_ns: int,
              first_ns: int) -> StepGaps:
    """
    Missing steps of a per-step topic.

    Parameters
    ----------
    stamps_ns : (N,) int64 ndarray
        Stamps [ns] of the kept messages (any order, repeats allowed).
    expected : int
        Steps the run had (or at least had, ``exact`` False).
    dt_ns : int
        Step [ns].
    first_ns : int
        Stamp [ns] of step 0.
    """
    steps = np.rint((np.asarray(stamps_ns, np.int64) - first_ns) / dt_ns).astype(np.int64)
    present = np.zeros(max(expected, 0), bool)
    present[steps[(steps >= 0) & (steps < expected)]] = True
    missing = np.flatnonzero(~present)
    gaps: list[StepRun] = []
    if len(missing):
        runs = np.split(missing, np.flatnonzero(np.diff(missing) > 1) + 1)
        gaps = [(int(r[0]), int(r[-1]), (first_ns + int(r[0]) * dt_ns) * 1e-9,
                 (first_ns + int(r[-1]) * dt_ns) * 1e-9) for r in runs]
    return StepGaps(int(expected), exact, int(len(missing)), gaps)
