"""
The study's results as typed records: what each stage returns and what the report reads.

A record is keyed by its position (``'P1'``) or by a :data:`Pair` (position, scenario). Every
stage function of :mod:`pentapod_damper.study.stages` returns one record; its ``describe()``
is the progress line printed when the stage finishes. :class:`StudyResults` holds them all.

Units: SI (m/N, Hz, s, kg); table columns name their unit (``peak_um_per_N``).
"""
from __future__ import annotations

from dataclasses import dataclass, field
import math
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from pentapod_damper.study.analytic import DiscreteFrf, SampledLoop
from pentapod_damper.study.config import StudyConfig
from pentapod_damper.study.damping import ModeDamping
from pentapod_damper.study.measured_damping import Identified, IdentifiedMode, SETTLE_MODES
from pentapod_damper.study.pma import PmaDesign
from pentapod_damper.study.runs import RunResult
from pentapod_sim.machining.loop_lobes import LoopLobes
from pentapod_sim.plant.frf_peaks import Peak, PoleResidueFrf
from pentapod_sim.plant.model import PlantModel
from pentapod_sim.scenario.cutting import RecordedCut
from pentapod_sim.sim.stability import LoopCheck

FloatArray = npt.NDArray[np.float64]
ComplexArray = npt.NDArray[np.complex128]
#: (position, scenario)
Pair = tuple[str, str]
#: A row of a table (CSV and Markdown): column -> value.
Row = dict[str, Any]


@dataclass
class PositionModel:
    """
    The reduced plant of one position, saved for the plant node to load.

    ``check_plant`` is the position's check model (every FE mode below the check cut-off, for
    the truncation check); None for a plant without an FE model behind it.
    """

    position: str
    plant: PlantModel
    model_file: Path
    model_hash: str
    check_plant: PlantModel | None = None
    #: How the model was made (the last message of its build).
    origin: str = ''

    def describe(self) -> str:
        meta = self.plant.meta
        return (f'{self.position}: FE model {meta.get("n_dof")} DOF, plant with '
                f'{self.plant.n_modes} of {meta.get("n_modes_computed")} modes below '
                f'{meta.get("modes_f_max_hz", 0):g} Hz; {self.origin}')


@dataclass(frozen=True)
class PmaSpec:
    """The proof-mass actuator of a scenario: mass [kg], gain [1/s], directions."""

    mass: float
    gain: float
    directions: tuple[str, ...]


@dataclass
class ScenarioAnalytic:
    """
    Analytic results of one scenario at one position (excited TCP direction d).

    ``continuous`` is TCP displacement d / TCP force d [m/N] of the continuous loop on the
    study's frequency grid, ``frf`` the same FRF exact at any frequency and ``peak`` its exact
    peak over the band; ``discrete`` holds the sampled lockstep loop's FRFs (every output and
    effort) on the bins of the measured FRFs; ``loop`` is the truncation check and ``sampled``
    the sampled loop with its eigen-decomposition. ``modes``: the dominant modes of every TCP
    direction (:func:`pentapod_damper.study.damping.damping_rows`); ``settle_modes``: the
    modes whose decay sets a damping run's settling time (empty without a damping run).
    """

    name: str
    laws: list[Any]
    dampers: dict[str, float]
    continuous: ComplexArray
    discrete: DiscreteFrf
    pma: PmaSpec | None = None
    frf: PoleResidueFrf | None = None
    peak: Peak | None = None
    loop: LoopCheck | None = None
    sampled: SampledLoop | None = None
    position: str = ''
    modes: list[ModeDamping] = field(default_factory=list)
    settle_modes: list[ModeDamping] = field(default_factory=list)
    #: The plant the scenario's plant node steps (the position's, with the feed drives'
    #: rotors if the scenario has ``drives``): every loop above is closed on it.
    plant: Any = None

    def describe(self) -> str:
        assert self.loop is not None
        flag = '' if self.loop.verdict == 'stable' else '  <-- !!!'
        return (f'{self.position} {self.name}: analytic FRFs and poles; sampled loop '
                f'{self.loop.verdict}, margin {self.loop.plant_margin:.3g} on the plant, '
                f'{self.loop.check_margin:.3g} on the check model{flag}')


@dataclass
class Measured:
    """What one testbed run's bag gives: the TCP FRF and, for PMA runs, stroke and force."""

    run: RunResult
    freq: FloatArray
    h: ComplexArray
    periodicity: float                         # last vs first period, relative (measure)
    pma_stroke: ComplexArray | None = None     # stroke / TCP force [m/N]
    pma_force: ComplexArray | None = None      # force / TCP force [N/N]
    n_messages: dict[str, int] = field(default_factory=dict)


@dataclass
class FrfRun:
    """
    A multisine testbed run from the periodic steady state; its FRF against the sampled loop's.

    ``deviation_db``: largest |dB| difference over every line of the band;
    ``peak_deviation_db``: measured over analytic peak (the largest over the lines) [dB].
    """

    measured: Measured
    deviation_db: float
    peak_deviation_db: float

    def describe(self) -> str:
        run = self.measured.run
        recorded = ', '.join(f'{n} {t}' for t, n in self.measured.n_messages.items())
        return (f'run {run.scenario} at {run.position}: {run.steps} steps in '
                f'{run.wall_time:.1f} s ({run.steps / run.wall_time:.0f} steps/s, lockstep); '
                f'recorded {recorded}; measured vs analytic over all {self.measured.freq.size} '
                f'lines: max {self.deviation_db:.2g} dB, peaks {self.peak_deviation_db:+.2g} '
                f'dB; periods differ by {self.measured.periodicity:.1e} of the peak')


@dataclass
class StepRun:
    """A PMA step-response run: time [s], stroke [m] and force [N] of the PMA."""

    run: RunResult
    time: FloatArray
    stroke: FloatArray
    force: FloatArray

    def describe(self) -> str:
        return (f'step-response run {self.run.scenario} at {self.run.position}: '
                f'{self.run.steps} steps in {self.run.wall_time:.1f} s')


def settling_text(cfg: StudyConfig) -> str:
    """How the study's damping runs settle, in words (docs, report)."""
    if cfg.damping_start == 'steady':
        return ("started at the loop's periodic steady state under the multisine (from the "
                f"linear models of plant and laws), {max(1, cfg.settle_periods)} period(s) "
                "discarded for the laws' own start")
    return (f'settled {cfg.damping_time_constants:g} decay times of the slowest of the '
            f'{SETTLE_MODES} modes with the largest terms in the response')


@dataclass
class DampingRun:
    """
    A multisine testbed run, its identified modes and their comparison with the loop's poles.

    ``settle_periods`` periods of ``period`` s settle (``start`` ``'steady'``: the run starts at
    the loop's periodic steady state and they settle only the laws' own start; ``'rest'``:
    ``time_constants`` decay times of the slowest of the loop's :data:`SETTLE_MODES` strongest
    modes), then ``periods`` are averaged.
    """

    run: RunResult
    settle_periods: int
    period: float
    periods: int
    time_constants: float
    identified: Identified
    modes: list[IdentifiedMode]
    figures: tuple[Path, Path]
    start: str = 'rest'

    def describe(self) -> str:
        worst = max((abs(m.zeta_error) for m in self.modes), default=math.nan)
        run = self.run
        why = ("from the loop's periodic steady state" if self.start == 'steady' else
               f'{self.time_constants:g} decay times of the slowest of the {SETTLE_MODES} '
               'strongest modes')
        return (f'damping run {run.scenario} at {run.position}: multisine, settle '
                f'{self.settle_periods * self.period:g} s ({why}) + {self.periods} '
                f'periods of {self.period:g} s; {run.steps} steps in {run.wall_time:.1f} s '
                f'({run.steps / run.wall_time:.0f} steps/s); '
                f'{len(self.identified.model.freq_hz)} modes identified; dominant modes: '
                f'damping ratio within {worst:.1%} of the sampled-loop poles')


@dataclass(frozen=True)
class BendingModel:
    """
    One strut bending damper model at one position (:mod:`pentapod_damper.study.bending`).

    ``optimal_gain`` [``gain_unit``] minimises the all-struts exact TCP peak; at it (``_opt``)
    and at the paper's gain (``_paper``): the exact peak reduction with all struts and with
    struts 1+2, and the share of the all-struts improvement that struts 1+2 achieve by exact
    peak and by RMS of |H| over the band.
    """

    position: str
    model: str
    gain_unit: str
    optimal_gain: float
    reduction_all_opt: float
    reduction_12_opt: float
    peak_share_12_opt: float
    rms_share_12_opt: float
    reduction_all_paper: float
    reduction_12_paper: float
    peak_share_12_paper: float
    rms_share_12_paper: float


@dataclass
class BendingComparison:
    """Both bending damper models at one position; ``curves``: label -> peak reduction."""

    position: str
    models: list[BendingModel]
    curves: dict[str, FloatArray]

    def describe(self) -> str:
        return f'{self.position}: both bending damper models, gain sweeps and optimal gains'


@dataclass
class PmaRequirements:
    """
    Stroke [m] and force [N] of a scenario's PMA at the step position (continuous loop).

    ``stroke`` and ``force`` on the study's grid for the PMA as run; ``ideal`` is that design,
    ``highpass`` the same PMA with the study's high-pass on the mount velocity.
    """

    scenario: str
    stroke: FloatArray
    force: FloatArray
    ideal: PmaDesign
    highpass: PmaDesign

    def describe(self) -> str:
        return f'{self.scenario}: PMA stroke and force, ideal and with a high-pass'


@dataclass
class Figures:
    """A group of PNG figures: caption -> file."""

    group: str
    paths: dict[str, Path] = field(default_factory=dict)

    def describe(self) -> str:
        return self.group


@dataclass
class CuttingCheck:
    """The recorded cuts of one (position, scenario) at the speed of the check."""

    position: str
    scenario: str
    operation: str
    speed: float
    depth: float
    chatter_freq: float
    cuts: list[RecordedCut]

    def describe(self) -> str:
        runs = ', '.join(f'{c.run.factor:g}x {c.verdict.verdict}' for c in self.cuts)
        return (f'{self.position} {self.scenario}: cuts at {self.speed:.0f} rpm around the '
                f'limit {self.depth * 1e3:.4g} mm: {runs}')


@dataclass
class Table:
    """
    A table a stage adds to the report as it is: CSV ``<name>.csv`` and a Markdown section.

    The way in for a new stage whose result is a table: the report writes every
    :attr:`StudyResults.tables` entry after its own sections.
    """

    name: str
    title: str
    text: str
    rows: list[Row]

    def describe(self) -> str:
        return f'{self.title}: {len(self.rows)} rows'


@dataclass
class StudyResults:
    """Every result of one study run, in the study file's order of positions and scenarios."""

    cfg: StudyConfig
    freq: FloatArray
    out_dir: Path = Path('out/study')
    models: dict[str, PositionModel] = field(default_factory=dict)
    analytic: dict[Pair, ScenarioAnalytic] = field(default_factory=dict)
    frf_runs: dict[Pair, FrfRun] = field(default_factory=dict)
    damping_runs: dict[Pair, DampingRun] = field(default_factory=dict)
    step_runs: dict[str, StepRun] = field(default_factory=dict)
    bending: dict[str, BendingComparison] = field(default_factory=dict)
    pma: dict[str, PmaRequirements] = field(default_factory=dict)
    lobes: dict[Pair, LoopLobes] = field(default_factory=dict)
    cutting: dict[Pair, CuttingCheck] = field(default_factory=dict)
    figures: list[Figures] = field(default_factory=list)
    tables: list[Table] = field(default_factory=list)
    #: stage -> seconds (busy time and first start to last end), and the total
    timings: dict[str, float] = field(default_factory=dict)


def as_row(record: Any, drop_none: bool = True) -> Row:
    """A record's fields as a table row (fields that are None left out)."""
    return {k: v for k, v in vars(record).items() if not (drop_none and v is None)}

