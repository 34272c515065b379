"""
The study's figures from its results (PNG files under ``<out>/figures``), one group at a time.

Each function draws one group and returns ``{caption: path}``; the report shows them in the
order :mod:`pentapod_damper.study.pieces` lists the groups. pyplot is not thread-safe: the
callers hold :data:`pentapod_damper.study.schedule.FIGURE_LOCK`.
"""
from __future__ import annotations

import numpy as np

from pentapod_damper.study import bending, plots
from pentapod_damper.study.analytic import continuous_frf
from pentapod_damper.study.config import StudyConfig
from pentapod_damper.study.report import StudyResults

#: Gain-sweep figure of each bending damper model (the rotational one keeps its old name).
FIGURE_FILES = {'rotational': 'bending_gain_sweep.png', 'chord': 'chord_gain_sweep.png'}
#: Scenarios compared in each damping figure of a position.
GROUPS = {'strut bending damping': ('baseline', 'strut_damping_all', 'strut_damping_12'),
          'strut chord damping': ('baseline', 'strut_chord_damping_all',
                                  'strut_chord_damping_12'),
          'axial and TCP damping': ('baseline', 'axial_damping', 'tcp_damping'),
          'proof-mass actuators': ('baseline', 'tcp_damping', 'pma_5kg', 'pma_1kg')}


def position_figures(res: StudyResults, cfg: StudyConfig, pos: str) -> dict:
    """Baseline TCP FRFs and the analytic and measured FRFs of each scenario group at ``pos``."""
    fig_dir, d, freq = res.out_dir / 'figures', cfg.direction, res.freq
    model = res.models[pos]
    out = {}
    curves = {f'TCP {a}{a}': continuous_frf(model.plant, {}, freq, f'tcp_displacement_{a}',
                                            f'tcp_force_{a}') for a in 'xyz'}
    out[f'Baseline FRFs at the TCP, {pos}'] = plots.baseline_frf_plot(
        freq, curves, model.plant.frequencies_hz, f'TCP compliance at {pos} (no added '
        'damping)', fig_dir / f'baseline_frf_{pos}.png')
    for title, names in GROUPS.items():
        names = [n for n in names if (pos, n) in res.analytic]
        measured = {n: (res.measured[(pos, n)].freq, res.measured[(pos, n)].h)
                    for n in names if (pos, n) in res.measured}
        key = title.split()[0]
        out[f'{title.capitalize()}, TCP {d}{d}, {pos}'] = plots.damping_plot(
            freq, {n: res.analytic[(pos, n)].continuous for n in names}, measured,
            f'{title}: TCP {d}{d} at {pos}', fig_dir / f'damping_{key}_{pos}.png')
    return out


def sweep_figures(res: StudyResults, cfg: StudyConfig) -> dict:
    """Exact peak reduction over the gain of both bending damper models (all, struts 1-2)."""
    d, out = cfg.direction, {}
    for model, (_, unit, gains) in bending.MODELS.items():
        ratios = {k.replace(f', {model}', ''): v for k, v in res.bending_curves.items()
                  if f', {model}, ' in k}
        marks = {f'optimum {r["position"]}: {r["optimal_gain"]:.3g}': r['optimal_gain']
                 for r in res.bending_models if r['model'] == model}
        marks[f'paper b = {bending.PAPER_GAIN:g}'] = bending.PAPER_GAIN
        out[f'Strut damper gain sweep, {model} model'] = plots.gain_sweep_plot(
            gains, ratios, res.scenario_gains.get(model, float('nan')),
            f'Strut damping, {model} model: TCP {d}{d} exact peak reduction over the gain',
            res.out_dir / 'figures' / FIGURE_FILES[model], unit, marks)
    return out


def pma_figure(res: StudyResults, cfg: StudyConfig) -> dict:
    """Analytic and measured PMA stroke and force (and the high-pass variants)."""
    if not res.pma:
        return {}
    pos, freq = cfg.step_position, res.freq
    measured = {}
    for scn in res.pma:
        mes = res.measured.get((pos, scn))
        if mes is not None and mes.pma_stroke is not None:
            amp = cfg.pma_force_amplitude
            keep = (mes.freq >= cfg.band[0]) & (mes.freq <= cfg.f_max)
            measured[scn] = (mes.freq[keep], np.abs(mes.pma_stroke[keep]) * amp,
                             np.abs(mes.pma_force[keep]) * amp)
    variants = {f'{scn} high-pass {cfg.pma_highpass_hz:g} Hz':
                designs['highpass'].stroke_force(freq, cfg.pma_force_amplitude)
                for scn, designs in res.pma_designs.items()}
    return {f'PMA stroke and force, {pos}': plots.pma_requirements_plot(
        freq, res.pma, measured, cfg.pma_force_amplitude,
        res.out_dir / 'figures' / 'pma_requirements.png', variants, cfg.pma_band,
        cfg.pma_frequencies)}


def step_figure(res: StudyResults, cfg: StudyConfig, steps: dict) -> dict:
    """Stroke and force of the PMA step-response runs."""
    if not steps:
        return {}
    steps = {s: steps[s] for s in cfg.scenarios if s in steps}     # the study file's order
    return {f'PMA step response, {cfg.step_position}': plots.step_response_plot(
        steps, cfg.step_amplitude, res.out_dir / 'figures' / 'pma_step_response.png')}
