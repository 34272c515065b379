"""
The study as pieces (:mod:`pentapod_damper.study.schedule`): what each does and what it needs.

Per position: its models; per position and scenario: analytic FRFs, truncation check and
loop poles (one computation of the poles serves the damping table and the settling time),
a random-excitation FRF run and, for the damping scenarios, a multisine damping run; per
position the bending damper comparison; the PMA curves and step runs; the figures. Testbed
runs go first among the ready pieces (the long damping runs before the short FRF runs), so
the two cores stay busy to the end. Each piece's result is stored by its ``done`` in the main
thread; :func:`in_order` then puts every table in the order of the study file, whatever order
the pieces finished in.
"""
from __future__ import annotations

from functools import partial

from pentapod_damper.study import bending, damping, figures, measured_damping, pipeline
from pentapod_damper.study.config import StudyConfig
from pentapod_damper.study.report import StudyResults
from pentapod_damper.study.runs import damping_excitation, run_on_testbed
from pentapod_damper.study.schedule import FIGURE_LOCK, Piece

#: Stages the pieces' times are counted in (report: Timings).
MODELS, ANALYTIC, BENDING = 'models', 'analytic FRFs, checks and poles', 'bending dampers'
FRF_RUNS, DAMPING_RUNS, FIGURES = 'FRF and step runs', 'damping runs', 'figures'
#: Priorities (lower first): the long damping runs as early as possible (their scenarios'
#: analytic pieces first), so the last pieces are short ones.
PRIORITY = {MODELS: 0, 'damping analytic': 1, DAMPING_RUNS: 2, ANALYTIC: 3, FRF_RUNS: 4,
            BENDING: 5, FIGURES: 6}
#: Lane of the pieces that start ROS nodes (limited to one at a time on a user-chosen domain).
ROS_LANE = 'ros'


def damping_todo(cfg: StudyConfig, runs: bool) -> list[tuple[str, str]]:
    """(position, scenario) of every damping run, in the study's order."""
    if not runs:
        return []
    return [(pos, scn) for pos in cfg.positions for scn in cfg.damping_scenarios
            if scn in cfg.scenarios]


def study_pieces(res: StudyResults, cfg: StudyConfig, runs: bool,
                 extra: dict) -> list[Piece]:
    """
    Every piece of the study; ``extra`` collects what is not in ``res`` (steps, settle, ...).

    ``runs`` False: analytic pieces and figures only (no ROS).
    """
    todo = damping_todo(cfg, runs)
    extra.setdefault('steps', {})
    extra.setdefault('bending', {})
    extra.setdefault('figures', {})
    pieces = []
    for pos in cfg.positions:
        model = ('model', pos)
        pieces.append(Piece(model, partial(_model, res, cfg, pos), MODELS,
                            priority=PRIORITY[MODELS],
                            done=partial(_model_done, res, pos)))
        for scn in cfg.scenarios:
            key = (pos, scn)
            pieces.append(Piece(('analytic',) + key,
                                partial(_analytic, res, cfg, pos, scn, key in todo), ANALYTIC,
                                after=(model,),
                                priority=PRIORITY['damping analytic' if key in todo
                                                  else ANALYTIC],
                                done=partial(_analytic_done, res, cfg, extra, pos, scn, runs)))
            if runs:
                pieces.append(Piece(('run',) + key, partial(_frf_run, res, cfg, pos, scn),
                                    FRF_RUNS, after=(('analytic',) + key,),
                                    priority=PRIORITY[FRF_RUNS], lane=ROS_LANE,
                                    done=partial(_frf_run_done, res, key)))
            if key in todo:
                pieces.append(Piece(('damping run',) + key,
                                    partial(_damping_run, res, cfg, extra, pos, scn),
                                    DAMPING_RUNS, after=(('analytic',) + key,),
                                    priority=PRIORITY[DAMPING_RUNS], lane=ROS_LANE,
                                    done=partial(_damping_run_done, res, key)))
        pieces.append(Piece(('bending', pos), partial(_bending, res, cfg, pos), BENDING,
                            after=(model,), priority=PRIORITY[BENDING],
                            done=partial(_bending_done, extra, pos)))
    return pieces + _figure_pieces(res, cfg, runs, extra, todo)


def _model(res: StudyResults, cfg: StudyConfig, pos: str):
    notes: list[str] = []
    return pipeline.prepare_model(pos, res.out_dir, notes.append, cfg), notes


def _model_done(res: StudyResults, pos: str, result) -> str:
    model, notes = result
    res.models[pos] = model
    meta = model.plant.meta
    return (f'{pos}: FE model {meta.get("n_dof")} DOF, plant with {model.plant.n_modes} of '
            f'{meta.get("n_modes_computed")} modes below {meta.get("modes_f_max_hz", 0):g} Hz; '
            f'{notes[-1] if notes else ""}')


def _analytic(res: StudyResults, cfg: StudyConfig, pos: str, scn: str, settle: bool):
    model = res.models[pos]
    ana = pipeline.scenario_analytic(model, scn, cfg, res.freq)
    dt = 1.0 / cfg.sample_rate
    poles = damping.loop_poles(model.plant, ana.laws, dt)
    rows = damping.scenario_rows(model.plant, pos, scn, dt, laws=ana.laws, poles=poles)
    settle_rows = (measured_damping.settle_rows(model.plant, ana.laws, dt, cfg.direction, poles)
                   if settle else None)
    return ana, rows, settle_rows


def _analytic_done(res: StudyResults, cfg: StudyConfig, extra: dict, pos: str, scn: str,
                   runs: bool, result):
    ana, rows, settle_rows = result
    res.analytic[(pos, scn)] = ana
    res.damping[(pos, scn)] = rows
    extra.setdefault('settle', {})[(pos, scn)] = settle_rows
    flag = '' if ana.loop.verdict == 'stable' else '  <-- !!!'
    line = (f'{pos} {scn}: analytic FRFs and poles; sampled loop {ana.loop.verdict}, margin '
            f'{ana.loop.plant_margin:.3g} on the plant, {ana.loop.check_margin:.3g} on the '
            f'check model{flag}')
    new = []
    if (runs and pos == cfg.step_position
            and all((pos, s) in res.analytic for s in cfg.scenarios)):
        # the step position's analytic pieces tell which scenarios have a PMA
        pma = [s for s in cfg.scenarios if res.analytic[(pos, s)].pma]
        new = [Piece(('step run', s), partial(_step_run, res, cfg, s), FRF_RUNS,
                     priority=PRIORITY[FRF_RUNS], lane=ROS_LANE,
                     done=partial(_step_done, extra, s))
               for s in pma]
        draw = partial(figures.step_figure, res, cfg, extra['steps'])
        new.append(_figure_piece(len(cfg.positions) + 2, extra,
                                 tuple(('step run', s) for s in pma), draw,
                                 'PMA step-response figure'))
    return line, new


def _frf_run(res: StudyResults, cfg: StudyConfig, pos: str, scn: str):
    model = res.models[pos]
    run = run_on_testbed(scn, pos, model.model_file, model.model_hash, cfg, res.out_dir)
    mes = pipeline.measure(run, cfg)
    dev = pipeline.deviation_db(mes, res.analytic[(pos, scn)].discrete,
                                f'tcp_displacement_{cfg.direction}', cfg, float(cfg.band[0]))
    return mes, dev


def _frf_run_done(res: StudyResults, key: tuple, result) -> str:
    mes, dev = result
    res.measured[key], res.deviation[key] = mes, dev
    run = mes.run
    recorded = ', '.join(f'{n} {t}' for t, n in mes.n_messages.items())
    return (f'run {key[1]} at {key[0]}: {run.steps} steps in {run.wall_time:.1f} s '
            f'({run.steps / run.wall_time:.0f} steps/s, lockstep); recorded {recorded}; '
            f'measured vs analytic: max {dev[0]:.2f} dB over {dev[1]:.0%} of the bins')


def _step_run(res: StudyResults, cfg: StudyConfig, scn: str):
    model = res.models[cfg.step_position]
    run = run_on_testbed(scn, cfg.step_position, model.model_file, model.model_hash, cfg,
                         res.out_dir, kind='step')
    return run, pipeline.step_series(run, cfg)


def _step_done(extra: dict, scn: str, result) -> str:
    run, series = result
    extra['steps'][scn] = series
    return (f'step-response run {scn} at {run.position}: {run.steps} steps in '
            f'{run.wall_time:.1f} s')


def _damping_run(res: StudyResults, cfg: StudyConfig, extra: dict, pos: str, scn: str):
    model, ana, d = res.models[pos], res.analytic[(pos, scn)], cfg.direction
    dt = 1.0 / cfg.sample_rate
    settle = damping.settling_time(extra['settle'][(pos, scn)], cfg.damping_time_constants)
    exciter = damping_excitation(cfg, settle)
    run = run_on_testbed(scn, pos, model.model_file, model.model_hash, cfg, res.out_dir,
                         kind='damping', exciter=exciter)
    ident = measured_damping.identify_run(run.bag, d, cfg.damping_band)
    rows = measured_damping.compare(res.damping[(pos, scn)], ident, model.plant, ana.laws, dt,
                                    d, ana.sampled)
    with FIGURE_LOCK:
        paths = measured_damping.figures(ident, res.out_dir / 'figures', f'{pos}_{scn}')
    return run, exciter, ident, rows, paths


def _damping_run_done(res: StudyResults, key: tuple, result) -> str:
    run, exciter, ident, rows, paths = result
    cfg = res.cfg
    res.damping_measured[key] = rows
    res.damping_figures[f'{key[0]}_{key[1]}'] = paths
    worst = max((abs(r['zeta_error']) for r in rows), default=float('nan'))
    return (f'damping run {key[1]} at {key[0]}: multisine, settle '
            f'{exciter["settle_periods"] * cfg.damping_period:g} s ({cfg.damping_time_constants:g}'
            f' decay times of the slowest of the {measured_damping.SETTLE_MODES} strongest '
            f'modes) + {cfg.damping_periods} periods of {cfg.damping_period:g} s; {run.steps} '
            f'steps in {run.wall_time:.1f} s ({run.steps / run.wall_time:.0f} steps/s); '
            f'{len(ident.model.freq_hz)} modes identified; dominant modes: damping ratio within '
            f'{worst:.1%} of the sampled-loop poles')


def _bending(res: StudyResults, cfg: StudyConfig, pos: str):
    band = (float(cfg.band[0]), float(cfg.f_max))
    return bending.compare(res.models[pos].plant, pos, cfg.direction, band, res.freq)


def _bending_done(extra: dict, pos: str, result) -> str:
    extra['bending'][pos] = result
    return f'{pos}: both bending damper models, gain sweeps and optimal gains'


def _figure_pieces(res: StudyResults, cfg: StudyConfig, runs: bool, extra: dict,
                   todo: list) -> list[Piece]:
    """Figure pieces, each after the pieces whose results it draws (one at a time)."""
    out = []
    analytic = tuple(('analytic', p, s) for p in cfg.positions for s in cfg.scenarios)
    for i, pos in enumerate(cfg.positions):
        after = tuple(k for k in analytic if k[1] == pos)
        if runs:
            after += tuple(('run', pos, s) for s in cfg.scenarios)
        out.append(_figure_piece(i, extra, after, partial(figures.position_figures, res, cfg,
                                                           pos), f'figures of {pos}'))
    n = len(cfg.positions)
    out.append(_figure_piece(n, extra, tuple(('bending', p) for p in cfg.positions),
                             partial(_sweeps, res, cfg, extra), 'gain-sweep figures'))
    pma_after = analytic + (tuple(('run', cfg.step_position, s) for s in cfg.scenarios)
                            if runs else ())
    out.append(_figure_piece(n + 1, extra, pma_after, partial(_pma, res, cfg),
                             'PMA requirements figure'))
    return out


def _figure_piece(index: int, extra: dict, after: tuple, draw, label: str) -> Piece:
    def work():
        with FIGURE_LOCK:
            return draw()

    def done(result):
        extra['figures'][index] = result
        return label if result else None
    return Piece(('figures', index), work, FIGURES, after=after, priority=PRIORITY[FIGURES],
                 done=done)


def _sweeps(res: StudyResults, cfg: StudyConfig, extra: dict) -> dict:
    for pos in cfg.positions:
        rows, curves = extra['bending'][pos]
        res.bending_models += rows
        res.bending_curves.update(curves)
    for model_name, scn in (('rotational', 'strut_damping_all'),
                            ('chord', 'strut_chord_damping_all')):
        if (cfg.positions[0], scn) in res.analytic:
            gains = res.analytic[(cfg.positions[0], scn)].dampers
            res.scenario_gains[model_name] = float(next(iter(gains.values()), float('nan')))
    return figures.sweep_figures(res, cfg)


def _pma(res: StudyResults, cfg: StudyConfig) -> dict:
    pma_results(res, cfg)
    return figures.pma_figure(res, cfg)


def pma_results(res: StudyResults, cfg: StudyConfig) -> None:
    """Analytic stroke and force curves and the designs of every PMA scenario."""
    model = res.models[cfg.step_position]
    for scn in cfg.scenarios:
        ana = res.analytic[(cfg.step_position, scn)]
        if ana.pma:
            res.pma[scn] = pipeline.pma_curves(model, ana, cfg, res.freq)
            res.pma_designs[scn] = pipeline.pma_designs(model, ana, cfg)


def in_order(res: StudyResults, cfg: StudyConfig, extra: dict) -> None:
    """Put every table of ``res`` in the study file's order of positions and scenarios."""
    pairs = [(p, s) for p in cfg.positions for s in cfg.scenarios]
    for name in ('analytic', 'measured', 'deviation', 'damping', 'damping_measured'):
        table = getattr(res, name)
        setattr(res, name, {k: table[k] for k in pairs if k in table})
    res.models = {p: res.models[p] for p in cfg.positions if p in res.models}
    res.damping_figures = {f'{p}_{s}': res.damping_figures[f'{p}_{s}'] for p, s in pairs
                           if f'{p}_{s}' in res.damping_figures}
    for index in sorted(extra['figures']):
        res.figures.update(extra['figures'][index])
