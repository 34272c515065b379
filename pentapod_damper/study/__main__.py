"""
Run the paper's damping study end to end: ``python -m pentapod_damper.study [options]``.

Stages (each prints progress): reduced plant per position, analytic FRFs of every scenario,
one recorded lockstep run per position and scenario, PMA step-response runs, analysis of the
bags, report (out/study/report.md with PNG figures and CSV tables), and a short summary.
"""
from __future__ import annotations

import argparse
import logging
from pathlib import Path
import sys
import time

import numpy as np

from pentapod_damper.study import bending, damping, measured_damping, pipeline, plots
from pentapod_damper.study.analytic import continuous_frf
from pentapod_damper.study.config import load_study_config, StudyConfig
from pentapod_damper.study.report import struts12_share, StudyResults, summary_rows, write_report
from pentapod_damper.study.runs import damping_excitation, run_on_testbed
from pentapod_sim.errors import BagError, ConfigError, RunError

LOG = logging.getLogger('pentapod_damper.study')
#: Gain-sweep figure of each bending damper model (the rotational one keeps its old name).
FIGURE_FILES = {'rotational': 'bending_gain_sweep.png', 'chord': 'chord_gain_sweep.png'}


def _say(msg: str) -> None:
    print(f'[study {time.strftime("%H:%M:%S")}] {msg}', flush=True)


def _analytic(res: StudyResults, cfg: StudyConfig) -> None:
    for pos in cfg.positions:
        t0 = time.perf_counter()
        model = pipeline.prepare_model(pos, res.out_dir, lambda m: _say(f'{pos}: {m}'), cfg)
        res.models[pos] = model
        for scn in cfg.scenarios:
            ana = pipeline.scenario_analytic(model, scn, cfg, res.freq)
            res.analytic[(pos, scn)] = ana
            flag = '' if ana.loop.verdict == 'stable' else '  <-- !!!'
            _say(f'{pos} {scn}: sampled loop {ana.loop.verdict}; margin '
                 f'{ana.loop.plant_margin:.3g} on the plant, {ana.loop.check_margin:.3g} on the '
                 f'check model{flag}')
        _say(f'{pos}: plant with {model.plant.n_modes} modes, check model with '
             f'{model.check_plant.n_modes} modes, analytic FRFs and checks of '
             f'{len(cfg.scenarios)} scenarios in {time.perf_counter() - t0:.1f} s')
    pma_results(res, cfg)
    for model_name, scn in (('rotational', 'strut_damping_all'),
                            ('chord', 'strut_chord_damping_all')):
        if (cfg.positions[0], scn) in res.analytic:
            gains = res.analytic[(cfg.positions[0], scn)].dampers
            res.scenario_gains[model_name] = float(next(iter(gains.values()), float('nan')))
    band = (float(cfg.band[0]), float(cfg.f_max))
    for pos, model in res.models.items():
        t0 = time.perf_counter()
        rows, curves = bending.compare(model.plant, pos, cfg.direction, band, res.freq)
        res.bending_models += rows
        res.bending_curves.update(curves)
        _say(f'{pos}: both bending damper models, gain sweeps and optimal gains in '
             f'{time.perf_counter() - t0:.1f} s')


def pma_results(res: StudyResults, cfg: StudyConfig) -> None:
    """Analytic stroke and force curves and the designs of every PMA scenario."""
    model = res.models[cfg.step_position]
    for scn in cfg.scenarios:
        ana = res.analytic[(cfg.step_position, scn)]
        if ana.pma:
            res.pma[scn] = pipeline.pma_curves(model, ana, cfg, res.freq)
            res.pma_designs[scn] = pipeline.pma_designs(model, ana, cfg)


def _testbed(res: StudyResults, cfg: StudyConfig) -> dict:
    runs = [(pos, scn) for pos in cfg.positions for scn in cfg.scenarios]
    d = cfg.direction
    for i, (pos, scn) in enumerate(runs, 1):
        model = res.models[pos]
        _say(f'run {i}/{len(runs)}: {scn} at {pos} ({cfg.duration:g} s, '
             f'{int(cfg.duration * cfg.sample_rate)} steps, lockstep)')
        run = run_on_testbed(scn, pos, model.model_file, model.model_hash, cfg, res.out_dir)
        mes = pipeline.measure(run, cfg)
        res.measured[(pos, scn)] = mes
        dev = pipeline.deviation_db(mes, res.analytic[(pos, scn)].discrete,
                                    f'tcp_displacement_{d}', cfg, float(cfg.band[0]))
        res.deviation[(pos, scn)] = dev
        _say(f'    {run.steps} steps in {run.wall_time:.1f} s ({run.steps / run.wall_time:.0f}'
             f' steps/s); recorded {mes.n_messages}; measured vs analytic: max '
             f'{dev[0]:.2f} dB over {dev[1]:.0%} of the bins')
    steps = {}
    for scn in [s for s in cfg.scenarios if res.analytic[(cfg.step_position, s)].pma]:
        model = res.models[cfg.step_position]
        _say(f'step-response run: {scn} at {cfg.step_position}')
        run = run_on_testbed(scn, cfg.step_position, model.model_file, model.model_hash, cfg,
                             res.out_dir, kind='step')
        steps[scn] = pipeline.step_series(run, cfg)
    return steps


def _damping(res: StudyResults, cfg: StudyConfig, runs: bool) -> None:
    """Damping per mode: analytic poles of every loop, identified modes of the damping runs."""
    dt, d = 1.0 / cfg.sample_rate, cfg.direction
    todo = [(pos, scn) for pos in cfg.positions for scn in cfg.damping_scenarios
            if scn in cfg.scenarios] if runs else []
    for pos in cfg.positions:
        for scn in cfg.scenarios:
            res.damping[(pos, scn)] = damping.scenario_rows(res.models[pos].plant, pos, scn, dt)
    for i, (pos, scn) in enumerate(todo, 1):
        model, rows = res.models[pos], res.damping[(pos, scn)]
        laws = res.analytic[(pos, scn)].laws
        settle = damping.settling_time(measured_damping.settle_rows(model.plant, laws, dt, d),
                                       cfg.damping_time_constants)
        exciter = damping_excitation(cfg, settle)
        _say(f'damping run {i}/{len(todo)}: {scn} at {pos} (multisine, settle '
             f'{exciter["settle_periods"] * cfg.damping_period:g} s = '
             f'{cfg.damping_time_constants:g} decay times of the slowest of the '
             f'{measured_damping.SETTLE_MODES} strongest modes, then '
             f'{cfg.damping_periods} periods of {cfg.damping_period:g} s; '
             f'{int(exciter["duration"] * cfg.sample_rate)} steps)')
        run = run_on_testbed(scn, pos, model.model_file, model.model_hash, cfg, res.out_dir,
                             kind='damping', exciter=exciter)
        ident = measured_damping.identify_run(run.bag, d, cfg.damping_band)
        rows = measured_damping.compare(rows, ident, model.plant, laws, dt, d)
        res.damping_measured[(pos, scn)] = rows
        tag = f'{pos}_{scn}'
        res.damping_figures[tag] = measured_damping.figures(ident, res.out_dir / 'figures', tag)
        worst = max((abs(r['zeta_error']) for r in rows), default=float('nan'))
        _say(f'    {run.steps} steps in {run.wall_time:.1f} s ({run.steps / run.wall_time:.0f} '
             f'steps/s); {len(ident.model.freq_hz)} modes identified; dominant modes: damping '
             f'ratio within {worst:.1%} of the sampled-loop poles')


def _figures(res: StudyResults, cfg: StudyConfig, steps: dict) -> None:
    fig_dir, d, freq = res.out_dir / 'figures', cfg.direction, res.freq
    for pos, model in res.models.items():
        curves = {f'TCP {a}{a}': continuous_frf(model.plant, {}, freq, f'tcp_displacement_{a}',
                                                f'tcp_force_{a}') for a in 'xyz'}
        res.figures[f'Baseline FRFs at the TCP, {pos}'] = plots.baseline_frf_plot(
            freq, curves, model.plant.frequencies_hz, f'TCP compliance at {pos} (no added '
            'damping)', fig_dir / f'baseline_frf_{pos}.png')
        groups = {'strut bending damping': ('baseline', 'strut_damping_all', 'strut_damping_12'),
                  'strut chord damping': ('baseline', 'strut_chord_damping_all',
                                          'strut_chord_damping_12'),
                  'axial and TCP damping': ('baseline', 'axial_damping', 'tcp_damping'),
                  'proof-mass actuators': ('baseline', 'tcp_damping', 'pma_5kg', 'pma_1kg')}
        for title, names in groups.items():
            names = [n for n in names if (pos, n) in res.analytic]
            measured = {n: (res.measured[(pos, n)].freq, res.measured[(pos, n)].h)
                        for n in names if (pos, n) in res.measured}
            key = title.split()[0]
            res.figures[f'{title.capitalize()}, TCP {d}{d}, {pos}'] = plots.damping_plot(
                freq, {n: res.analytic[(pos, n)].continuous for n in names}, measured,
                f'{title}: TCP {d}{d} at {pos}', fig_dir / f'damping_{key}_{pos}.png')
    _sweep_figure(res, cfg)
    if res.pma:
        pos = cfg.step_position
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
        res.figures[f'PMA stroke and force, {pos}'] = plots.pma_requirements_plot(
            freq, res.pma, measured, cfg.pma_force_amplitude, fig_dir / 'pma_requirements.png',
            variants, cfg.pma_band, cfg.pma_frequencies)
    if steps:
        res.figures[f'PMA step response, {cfg.step_position}'] = plots.step_response_plot(
            steps, cfg.step_amplitude, fig_dir / 'pma_step_response.png')


def _sweep_figure(res: StudyResults, cfg: StudyConfig) -> None:
    """Exact peak reduction over the gain of both bending damper models (all, struts 1-2)."""
    d = cfg.direction
    for model, (_, unit, gains) in bending.MODELS.items():
        ratios = {k.replace(f', {model}', ''): v for k, v in res.bending_curves.items()
                  if f', {model}, ' in k}
        marks = {f'optimum {r["position"]}: {r["optimal_gain"]:.3g}': r['optimal_gain']
                 for r in res.bending_models if r['model'] == model}
        marks[f'paper b = {bending.PAPER_GAIN:g}'] = bending.PAPER_GAIN
        res.figures[f'Strut damper gain sweep, {model} model'] = plots.gain_sweep_plot(
            gains, ratios, res.scenario_gains.get(model, float('nan')),
            f'Strut damping, {model} model: TCP {d}{d} exact peak reduction over the gain',
            res.out_dir / 'figures' / FIGURE_FILES[model], unit, marks)


def _print_summary(res: StudyResults, report: Path) -> None:
    print('\nSummary (analytic peak reduction; testbed check against the sampled loop)')
    print(f'{"pos":4} {"scenario":18} {"peak um/N":>10} {"peak red.":>9} {"rms red.":>8} '
          f'{"meas. dev dB":>12} {"steps/s":>8}')
    for r in summary_rows(res):
        print(f'{r["position"]:4} {r["scenario"]:18} {r["peak_um_per_N"]:10.4f} '
              f'{r["peak_reduction"]:9.2f} {r["rms_reduction"]:8.2f} '
              f'{r.get("deviation_db", float("nan")):12.2f} {r.get("steps_per_s", 0):8.0f}')
    for r in struts12_share(res):
        print(f'struts 1-2 achieve {r["peak_share"]:.0%} (peak) / {r["rms_share"]:.0%} (RMS) '
              f'of the all-struts improvement at {r["position"]}')
    for r in res.bending_models:
        print(f'{r["position"]} {r["model"]:10} optimum {r["optimal_gain"]:9.4g} '
              f'{r["gain_unit"]}: {r["reduction_all_opt"]:.2f}x, struts 1-2 '
              f'{r["peak_share_12_opt"]:.0%} / {r["rms_share_12_opt"]:.0%}; at b = '
              f'{bending.PAPER_GAIN:g}: {r["reduction_all_paper"]:.2f}x, struts 1-2 '
              f'{r["peak_share_12_paper"]:.0%} / {r["rms_share_12_paper"]:.0%}')
    print(f'report: {report}')


def main(argv: list[str] | None = None) -> int:
    """Run the study; return 0 on success, 1 with a clear message on a failed stage."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--config', help='study YAML (default config/study.yaml)')
    parser.add_argument('--out', default='out/study', help='output folder')
    parser.add_argument('--duration', type=float, help='excited time per run [s]')
    parser.add_argument('--positions', help='comma-separated positions, e.g. P1,P2')
    parser.add_argument('--analytic-only', action='store_true',
                        help='skip the testbed runs (no ROS): analytic figures only')
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.WARNING, format='%(levelname)s %(name)s: %(message)s')
    t_start = time.perf_counter()
    try:
        positions = tuple(args.positions.split(',')) if args.positions else None
        cfg = load_study_config(args.config, duration=args.duration, positions=positions)
        if cfg.step_position not in cfg.positions:
            raise ConfigError(f'step_response.position = {cfg.step_position} is not among the '
                              f'positions {", ".join(cfg.positions)}: add it (--positions) or '
                              'set step_response.position in the study file')
        res = StudyResults(cfg, np.linspace(*cfg.freq_grid[:2], int(cfg.freq_grid[2])))
        res.out_dir = Path(args.out)
        res.out_dir.mkdir(parents=True, exist_ok=True)
        t0 = time.perf_counter()
        _analytic(res, cfg)
        res.timings['models and analytic FRFs'] = time.perf_counter() - t0
        steps = {}
        if not args.analytic_only:
            t0 = time.perf_counter()
            steps = _testbed(res, cfg)
            res.timings['testbed runs and bag analysis'] = time.perf_counter() - t0
        t0 = time.perf_counter()
        _damping(res, cfg, runs=not args.analytic_only)
        res.timings['damping per mode (poles, runs, identification)'] = time.perf_counter() - t0
        t0 = time.perf_counter()
        _figures(res, cfg, steps)
        res.timings['figures'] = time.perf_counter() - t0
        res.timings['total'] = time.perf_counter() - t_start
        report = write_report(res, res.out_dir)
    except (ConfigError, RunError, BagError) as err:
        print(f'study failed: {err}', file=sys.stderr)
        return 1
    _print_summary(res, report)
    _say(f'done in {time.perf_counter() - t_start:.0f} s')
    return 0


if __name__ == '__main__':
    sys.exit(main())
