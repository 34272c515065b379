"""
The study's stages: plain functions from the settings and earlier results to one typed record.

Each function computes one thing for one position or one (position, scenario) and returns a
record of :mod:`pentapod_damper.study.records`; :mod:`pentapod_damper.study.schedule` says what
each needs and runs them. ROS appears only in the testbed runs
(:func:`pentapod_damper.study.runs.run_on_testbed` starts the nodes).
"""
from __future__ import annotations

from pathlib import Path
from typing import Any

from pentapod_damper.study import bending, damping, measured_damping, pipeline, strut_laws
from pentapod_damper.study.config import StudyConfig
from pentapod_damper.study.figures import FIGURE_LOCK
from pentapod_damper.study.measured_damping import Identified, IdentifiedMode
from pentapod_damper.study.records import (
    BendingComparison,
    DampingRun,
    FloatArray,
    FrfRun,
    PmaRequirements,
    PositionModel,
    ScenarioAnalytic,
    StepRun,
)
from pentapod_damper.study.runs import damping_excitation, run_on_testbed, RunResult
from pentapod_damper.study.strut_laws import StrutLaws


def build_model(cfg: StudyConfig, out_dir: Path, position: str,
                fe_model: Path | None = None) -> PositionModel:
    """The reduced plant of a position (saved for the plant node) and its check model."""
    notes: list[str] = []
    model = pipeline.prepare_model(position, out_dir, notes.append, cfg, fe_model)
    model.origin = notes[-1] if notes else ''
    return model


def analyse_scenario(cfg: StudyConfig, freq: FloatArray, model: PositionModel, scenario: str,
                     damping_run: bool) -> ScenarioAnalytic:
    """
    Analytic FRFs, truncation check and the dominant modes of one scenario's loop.

    One computation of the loop's poles serves the table of dominant modes and, if the
    scenario has a ``damping_run``, the modes that set its settling time. The loop is the one
    the scenario's nodes close: on the plant its plant node steps (``ana.plant``, with the
    feed drives' rotors if the scenario has ``drives``).
    """
    ana = pipeline.scenario_analytic(model, scenario, cfg, freq)
    dt = cfg.dt
    poles = damping.loop_poles(ana.plant, ana.laws, dt)
    ana.modes = damping.scenario_rows(ana.plant, model.position, scenario, dt, laws=ana.laws,
                                      poles=poles)
    if damping_run:
        ana.settle_modes = measured_damping.settle_rows(ana.plant, ana.laws, dt,
                                                        cfg.direction, poles)
    return ana


def frf_run(cfg: StudyConfig, out_dir: Path, model: PositionModel,
            analytic: ScenarioAnalytic) -> FrfRun:
    """
    A multisine run from the loop's periodic steady state; its FRF against the sampled loop's.

    The plant starts at the periodic steady state of the linear loop
    (:func:`pipeline.steady_start`), so the run needs no settling and every line, however
    lightly damped its modes, is compared.
    """
    run = run_on_testbed(analytic.name, model.position, model.model_file, model.model_hash,
                         cfg, out_dir, initial_state=pipeline.steady_start(cfg, analytic))
    mes = pipeline.measure(run, cfg)
    dev, peak = pipeline.deviation_db(mes, analytic.discrete, f'tcp_displacement_{cfg.direction}')
    return FrfRun(mes, dev, peak)


def record_damping(cfg: StudyConfig, out_dir: Path, model: PositionModel,
                   analytic: ScenarioAnalytic
                   ) -> tuple[RunResult, dict[str, Any], Identified, list[IdentifiedMode]]:
    """
    A multisine run on the testbed, its modes identified and paired with the loop's poles.

    With ``damping.start: steady`` it starts at the loop's periodic steady state under its
    multisine (:func:`pipeline.steady_start`) and settles ``excitation.settle_periods``
    periods (the laws' own start); from rest it settles
    :attr:`StudyConfig.damping_time_constants` decay times of the slowest of the loop's
    strongest modes (:attr:`ScenarioAnalytic.settle_modes`). Either way the identification
    sees only the periods after that. Returns the run, the exciter's parameters, the
    identification and the identified modes paired with the poles.
    """
    steady = cfg.damping_start == 'steady'
    settle = (cfg.settle_periods * cfg.damping_period if steady else
              damping.settling_time(analytic.settle_modes, cfg.damping_time_constants))
    exciter = damping_excitation(cfg, settle)
    start = pipeline.steady_start(cfg, analytic, exciter) if steady else None
    run = run_on_testbed(analytic.name, model.position, model.model_file, model.model_hash,
                         cfg, out_dir, kind='damping', exciter=exciter, initial_state=start)
    ident = measured_damping.identify_run(run.bag, cfg.direction, cfg.damping_band)
    modes = measured_damping.compare(analytic.modes, ident, analytic.plant, analytic.laws, cfg.dt,
                                     cfg.direction, analytic.sampled)
    return run, exciter, ident, modes


def damping_run(cfg: StudyConfig, out_dir: Path, model: PositionModel,
                analytic: ScenarioAnalytic) -> DampingRun:
    """:func:`record_damping` of one scenario, with the identification's figures."""
    run, exciter, ident, modes = record_damping(cfg, out_dir, model, analytic)
    with FIGURE_LOCK:
        paths = measured_damping.figures(ident, out_dir / 'figures',
                                         f'{model.position}_{analytic.name}')
    return DampingRun(run, int(exciter['settle_periods']), cfg.damping_period,
                      cfg.damping_periods, cfg.damping_time_constants, ident, modes, paths,
                      cfg.damping_start)


def step_run(cfg: StudyConfig, out_dir: Path, model: PositionModel, scenario: str) -> StepRun:
    """A step-response run of a PMA scenario: the PMA's stroke and force over time."""
    run = run_on_testbed(scenario, model.position, model.model_file, model.model_hash, cfg,
                         out_dir, kind='step')
    return StepRun(run, *pipeline.step_series(run, cfg))


def bending_dampers(cfg: StudyConfig, freq: FloatArray,
                    model: PositionModel) -> BendingComparison:
    """Both strut bending damper models: gain sweeps, optimal gains, struts 1+2 shares."""
    band = (float(cfg.band[0]), float(cfg.f_max))
    return bending.compare(model.plant, model.position, cfg.direction, band, freq)


def pma_requirements(cfg: StudyConfig, freq: FloatArray, model: PositionModel,
                     analytic: ScenarioAnalytic) -> PmaRequirements:
    """Stroke and force of a scenario's PMA: as run, and the designs ideal and high-pass."""
    stroke, force = pipeline.pma_curves(model, analytic, cfg, freq)
    return PmaRequirements(analytic.name, stroke, force,
                           *pipeline.pma_designs(model, analytic, cfg))


def damper_table_laws(cfg: StudyConfig, model: PositionModel) -> StrutLaws:
    """
    The damper table's strut laws on the position's plant: reductions, struts 1+2 shares.

    Each law of docs/dampers.md's table as its scenario file ships it and, where the file was
    tuned at another position, with the gains of the table's row at this position
    (:func:`pentapod_damper.study.strut_laws.position_laws`; sampled-loop FRFs, no tuning).
    """
    return strut_laws.position_laws(cfg, model, strut_laws.design_records())
