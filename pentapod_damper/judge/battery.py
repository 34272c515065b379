"""
The battery: plan the runs, run them, and analyse every bag into the judged results.

Per position: the baseline's multisine runs, then for each judged controller (the one under
judgement, and the reference law or the second controller of ``--compare``) its multisine runs
and its robustness run. The ports a controller answers, if not given, are read from its first
run's bag before its robustness run needs them. Everything the report shows is computed here
from the bags; analytic references come from the plant and the models the controllers
published in their recordings.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
import logging
from pathlib import Path
import time
from typing import Callable, Sequence

from pentapod_damper.design.table import DamperRow
from pentapod_damper.judge import damping
from pentapod_damper.judge.buildable import buildable_rows
from pentapod_damper.judge.config import JudgeConfig
from pentapod_damper.judge.controller import BASELINE, Controller, law_ports
from pentapod_damper.judge.damping import DominantMode, Pole
from pentapod_damper.judge.demand import demand, faults, PortDemand, RunFaults
from pentapod_damper.judge.machining import (
    analytic_matrix,
    milling_cut,
    stable_depth,
    StableDepth,
)
from pentapod_damper.judge.measure import (
    analyse_multisine,
    Analytic,
    analytic_reference,
    MultisineRun,
)
from pentapod_damper.judge.models import PositionModel
from pentapod_damper.judge.robustness import (
    answered_ports,
    assess,
    published_models,
    Robustness,
)
from pentapod_damper.judge.runs import (
    MULTISINE,
    ROBUSTNESS,
    run_document,
    Runner,
    RunRecord,
    RunSpec,
    settle_periods,
)
from pentapod_sim import __version__
from pentapod_sim.analysis.bag.reader import open_bag
from pentapod_sim.sim.controllers import DiscreteController

LOG = logging.getLogger(__name__)
#: Sections of the battery: those that need the multisine runs, and the loop check.
MULTISINE_SECTIONS = ('damping', 'compliance', 'demand', 'machining', 'faults')
SECTIONS = MULTISINE_SECTIONS + ('robustness', 'buildable')


@dataclass
class Judged:
    """One controller (or the baseline) at one position: everything measured from its runs."""

    controller: Controller
    records: list[RunRecord] = field(default_factory=list)
    multisine: dict[str, MultisineRun] = field(default_factory=dict)
    models: list[DiscreteController] | None = None
    analytic: dict[str, Analytic] = field(default_factory=dict)
    measured_poles: dict[str, list[Pole]] = field(default_factory=dict)
    analytic_poles: dict[str, list[Pole]] = field(default_factory=dict)
    demand: list[PortDemand] = field(default_factory=list)
    faults: list[RunFaults] = field(default_factory=list)
    robustness: Robustness | None = None
    machining: StableDepth | None = None
    buildable: dict[str, DamperRow] = field(default_factory=dict)   # per TCP direction

    @property
    def has_model(self) -> bool:
        """The analytic reference exists (the baseline, or a published linear model)."""
        return self.models is not None

    @property
    def wall_time(self) -> float:
        """Wall time of its runs [s] (reused runs count with their recorded time)."""
        return sum(r.wall_time for r in self.records)


@dataclass
class PositionResult:
    """The judged controllers at one position."""

    position: PositionModel
    settle_periods: int
    dominant: dict[str, list[DominantMode]]
    judged: dict[str, Judged]                  # 'baseline', then the controllers' labels
    seconds: float = 0.0


def plan(cfg: JudgeConfig, positions: Sequence[PositionModel], controllers: Sequence[Controller],
         sections: Sequence[str]) -> tuple[list[RunSpec], dict[str, int]]:
    """Every run of the battery, in order, and the settling periods per position."""
    specs: list[RunSpec] = []
    settle: dict[str, int] = {}
    multisine = any(s in MULTISINE_SECTIONS for s in sections)
    for pos in positions:
        settle[pos.name] = settle_periods(cfg, pos)
        ms = cfg.multisine
        steps_ms = round((settle[pos.name] + ms.periods) * ms.period * cfg.sample_rate)
        steps_rb = round(cfg.robustness.duration * cfg.sample_rate)
        for ctrl in (BASELINE, *controllers):
            if multisine:
                specs += [RunSpec(pos.name, ctrl, MULTISINE, d, steps_ms) for d in cfg.directions]
            if ctrl is not BASELINE and 'robustness' in sections:
                specs.append(RunSpec(pos.name, ctrl, ROBUSTNESS, '', steps_rb))
    return specs, settle


def _run(runner: Runner, spec: RunSpec, cfg: JudgeConfig, pos: PositionModel, settle: int,
         ports: tuple[str, ...], sensors: tuple[str, ...]) -> RunRecord:
    info = {'judge_run': spec.name, 'position': pos.name, 'controller': spec.controller.label,
            'kind': spec.kind, 'direction': spec.direction, 'model_hash':
            pos.plant.content_hash(), 'sample_rate': cfg.sample_rate,
            'package_version': __version__}
    doc = run_document(spec, cfg, pos, settle, ports, sensors, Path('bag'), info)
    return runner.run(spec, doc, pos)


def run_position(cfg: JudgeConfig, pos: PositionModel, controllers: Sequence[Controller],
                 specs: Sequence[RunSpec], settle: int, runner: Runner,
                 sections: Sequence[str], say: Callable[[str], None]) -> PositionResult:
    """Run and analyse everything of one position."""
    t0 = time.perf_counter()
    dominant = {d: damping.dominant_modes(pos, d, cfg.multisine.band, cfg.identification.modes)
                for d in cfg.directions}
    result = PositionResult(pos, settle, dominant, {})
    for ctrl in (BASELINE, *controllers):
        judged = Judged(ctrl)
        result.judged[ctrl.label] = judged
        ports = ctrl.ports or (law_ports(ctrl, cfg.dt) if ctrl is not BASELINE else ())
        for spec in [s for s in specs if s.position == pos.name and s.controller is ctrl]:
            if spec.kind == ROBUSTNESS and not ports:
                raise_no_ports(ctrl)
            record = _run(runner, spec, cfg, pos, settle, ports, ctrl.sensors)
            judged.records.append(record)
            if ctrl is not BASELINE and not ports and not record.failed:
                ports = answered_ports(open_bag(record.bag), ctrl.sources)
                say(f'{ctrl.label} answers on {", ".join(ports)}')
        analyse(cfg, pos, result, judged, sections, say)
    result.seconds = time.perf_counter() - t0
    return result


def raise_no_ports(ctrl: Controller) -> None:
    """A robustness run without known ports (no multisine run told them)."""
    from pentapod_sim.errors import ConfigError
    raise ConfigError(f'the ports {ctrl.label} answers are not known: give them with --ports '
                      '(or run the multisine sections, whose recordings tell them)')


def analyse(cfg: JudgeConfig, pos: PositionModel, result: PositionResult, judged: Judged,
            sections: Sequence[str], say: Callable[[str], None]) -> None:
    """Everything the bags of one controller give (module docstring)."""
    ctrl, dt = judged.controller, cfg.dt
    band = cfg.multisine.band
    t0 = time.perf_counter()
    # a run that ended early is judged by its faults only; a multisine section needs every
    # direction, so one failed multisine run leaves them all out
    by_kind = {(r.spec.kind, r.spec.direction): r for r in judged.records if not r.failed}
    if any(r.failed and r.spec.kind == MULTISINE for r in judged.records):
        by_kind = {k: r for k, r in by_kind.items() if k[0] != MULTISINE}
    if ctrl is BASELINE:
        judged.models = []
    elif by_kind:
        judged.models = published_models(open_bag(next(iter(by_kind.values())).bag),
                                         ctrl.sources)
    for d in cfg.directions if (MULTISINE, cfg.directions[0]) in by_kind else ():
        record = by_kind[(MULTISINE, d)]
        run = analyse_multisine(record.bag, d, band, cfg.identification.max_order)
        judged.multisine[d] = run
        if judged.models is not None:
            judged.analytic[d] = analytic_reference(pos.plant, judged.models, dt, d, run.freq,
                                                    band)
        if ctrl is not BASELINE:
            judged.demand += demand(record.bag, d, ctrl.sources, cfg.thresholds.force_limit)
    if judged.multisine:
        _damping(cfg, pos, result, judged)
        if 'machining' in sections and {'x', 'y'} <= set(judged.multisine):
            analytic = None if judged.models is None else analytic_matrix(
                pos.plant, judged.models, dt, band, f'{ctrl.label}, analytic')
            judged.machining = stable_depth(
                judged.multisine, {d: by_kind[(MULTISINE, d)].bag for d in ('x', 'y')},
                milling_cut(cfg.operation), band, ctrl.label, analytic)
    judged.faults = [dataclasses.replace(faults(r.bag, r.spec.name, r.spec.steps,
                                                ctrl.sources, dt), error=r.failed)
                     for r in judged.records]
    if 'buildable' in sections and ctrl is not BASELINE and judged.models:
        judged.buildable = buildable_rows(pos, judged.models, cfg.sample_rate, cfg.directions,
                                          band, ctrl.label)
    if (ROBUSTNESS, '') in by_kind:
        judged.robustness = assess(by_kind[(ROBUSTNESS, '')].bag, ctrl.sources, ctrl.sensors,
                                   pos.plant, pos.check, dt, cfg.robustness.nperseg,
                                   f'{ctrl.label} at {pos.name}')
    say(f'{pos.name} {ctrl.label}: analysed in {time.perf_counter() - t0:.1f} s')


def _damping(cfg: JudgeConfig, pos: PositionModel, result: PositionResult,
             judged: Judged) -> None:
    """Measured (and analytic) poles of the dominant modes of every direction."""
    base = result.judged['baseline']
    loop = (damping.analytic_poles(pos, judged.models, cfg.dt)
            if judged.models is not None else None)
    for d, modes in result.dominant.items():
        run = judged.multisine[d]
        if loop is not None:
            targets = [damping.analytic_pole(loop, m) for m in modes]
            judged.analytic_poles[d] = targets
            judged.measured_poles[d] = [damping.near_analytic(run, t) for t in targets]
        else:
            judged.measured_poles[d] = damping.paired_with_baseline(
                run, base.multisine[d], base.measured_poles[d],
                cfg.identification.pair_tolerance)
