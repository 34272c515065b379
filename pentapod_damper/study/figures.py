"""
The study's figures from its results (PNG files under ``<out>/figures``), one group at a time.

Each function draws one group and returns it as :class:`~pentapod_damper.study.records.Figures`
(caption -> file); the report shows the groups in the order the schedule lists them. pyplot is
not thread-safe and the stages run on threads: every function here draws while it holds
:data:`FIGURE_LOCK` (so do the damping runs' figures, :mod:`pentapod_damper.study.stages`).
"""
from __future__ import annotations

import math
from pathlib import Path
import threading
from typing import Mapping

import numpy as np

from pentapod_damper.study import bending, plots
from pentapod_damper.study.analytic import continuous_frf
from pentapod_damper.study.config import StudyConfig
from pentapod_damper.study.records import (
    BendingComparison,
    Figures,
    FloatArray,
    FrfRun,
    PmaRequirements,
    PositionModel,
    ScenarioAnalytic,
    StepRun,
)

#: Held while pyplot draws (it is not thread-safe).
FIGURE_LOCK = threading.Lock()
#: Gain-sweep figure of each bending damper model (the rotational one keeps its old name).
FIGURE_FILES = {'rotational': 'bending_gain_sweep.png', 'chord': 'chord_gain_sweep.png'}
#: Scenarios compared in each damping figure of a position.
GROUPS = {'strut bending damping': ('baseline', 'strut_damping_all', 'strut_damping_12'),
          'strut chord damping': ('baseline', 'strut_chord_damping_all',
                                  'strut_chord_damping_12'),
          'axial and TCP damping': ('baseline', 'axial_damping', 'tcp_damping'),
          'proof-mass actuators': ('baseline', 'tcp_damping', 'pma_5kg', 'pma_1kg')}
#: The gain-sweep figures mark the gain of each bending model's all-struts scenario.
SWEEP_SCENARIOS = {'rotational': 'strut_damping_all', 'chord': 'strut_chord_damping_all'}


def position_figures(cfg: StudyConfig, out_dir: Path, freq: FloatArray, model: PositionModel,
                     analytic: Mapping[str, ScenarioAnalytic],
                     runs: Mapping[str, FrfRun]) -> Figures:
    """Baseline TCP FRFs and the analytic and measured FRFs of each scenario group."""
    pos, fig_dir, d = model.position, out_dir / 'figures', cfg.direction
    out = Figures(f'figures of {pos}')
    with FIGURE_LOCK:
        curves = {f'TCP {a}{a}': continuous_frf(model.plant, {}, freq, f'tcp_displacement_{a}',
                                                f'tcp_force_{a}') for a in 'xyz'}
        out.paths[f'Baseline FRFs at the TCP, {pos}'] = plots.baseline_frf_plot(
            freq, curves, model.plant.frequencies_hz, f'TCP compliance at {pos} (no added '
            'damping)', fig_dir / f'baseline_frf_{pos}.png')
        for title, group in GROUPS.items():
            names = [n for n in group if n in analytic]
            measured = {n: (runs[n].measured.freq, runs[n].measured.h)
                        for n in names if n in runs}
            key = title.split()[0]
            out.paths[f'{title.capitalize()}, TCP {d}{d}, {pos}'] = plots.damping_plot(
                freq, {n: analytic[n].continuous for n in names}, measured,
                f'{title}: TCP {d}{d} at {pos}', fig_dir / f'damping_{key}_{pos}.png')
    return out


def sweep_figures(cfg: StudyConfig, out_dir: Path, comparisons: Mapping[str, BendingComparison],
                  analytic: Mapping[str, ScenarioAnalytic]) -> Figures:
    """
    Exact peak reduction over the gain of both bending damper models (all, struts 1-2).

    ``analytic``: the scenarios of the first position, whose all-struts gains are marked.
    """
    d, out = cfg.direction, Figures('gain-sweep figures')
    curves = {k: v for c in comparisons.values() for k, v in c.curves.items()}
    rows = [m for c in comparisons.values() for m in c.models]
    with FIGURE_LOCK:
        for model, (_, unit, gains) in bending.MODELS.items():
            ratios = {k.replace(f', {model}', ''): v for k, v in curves.items()
                      if f', {model}, ' in k}
            marks = {f'optimum {r.position}: {r.optimal_gain:.3g}': r.optimal_gain
                     for r in rows if r.model == model}
            marks[f'paper b = {bending.PAPER_GAIN:g}'] = bending.PAPER_GAIN
            scenario = analytic.get(SWEEP_SCENARIOS[model])
            chosen = (float(next(iter(scenario.dampers.values()), math.nan))
                      if scenario is not None else math.nan)
            out.paths[f'Strut damper gain sweep, {model} model'] = plots.gain_sweep_plot(
                gains, ratios, chosen,
                f'Strut damping, {model} model: TCP {d}{d} exact peak reduction over the gain',
                out_dir / 'figures' / FIGURE_FILES[model], unit, marks)
    return out


def pma_figure(cfg: StudyConfig, out_dir: Path, freq: FloatArray,
               pma: Mapping[str, PmaRequirements], runs: Mapping[str, FrfRun]) -> Figures:
    """Analytic and measured PMA stroke and force (and the high-pass variants)."""
    out = Figures('PMA requirements figure')
    if not pma:
        return out
    measured = {}
    amp = cfg.pma_force_amplitude
    for scn in pma:
        run = runs.get(scn)
        if run is not None:
            mes = run.measured
            if mes.pma_stroke is not None and mes.pma_force is not None:
                keep = (mes.freq >= cfg.band[0]) & (mes.freq <= cfg.f_max)
                measured[scn] = (mes.freq[keep], np.abs(mes.pma_stroke[keep]) * amp,
                                 np.abs(mes.pma_force[keep]) * amp)
    variants = {f'{scn} high-pass {cfg.pma_highpass_hz:g} Hz':
                req.highpass.stroke_force(freq, amp) for scn, req in pma.items()}
    with FIGURE_LOCK:
        out.paths[f'PMA stroke and force, {cfg.step_position}'] = plots.pma_requirements_plot(
            freq, {scn: (req.stroke, req.force) for scn, req in pma.items()}, measured, amp,
            out_dir / 'figures' / 'pma_requirements.png', variants, cfg.pma_band,
            cfg.pma_frequencies)
    return out


def step_figure(cfg: StudyConfig, out_dir: Path, steps: Mapping[str, StepRun]) -> Figures:
    """Stroke and force of the PMA step-response runs."""
    out = Figures('PMA step-response figure')
    if not steps:
        return out
    series = {s: (run.time, run.stroke, run.force) for s, run in steps.items()}
    with FIGURE_LOCK:
        out.paths[f'PMA step response, {cfg.step_position}'] = plots.step_response_plot(
            series, cfg.step_amplitude, out_dir / 'figures' / 'pma_step_response.png')
    return out
