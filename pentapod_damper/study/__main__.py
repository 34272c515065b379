"""
The paper's damping study and its parts: ``python -m pentapod_damper.study [COMMAND] ...``.

Commands (``COMMAND --help`` for the options of each):

* ``run`` (the default): every stage of the study (:mod:`pentapod_damper.study.schedule`),
  ``--jobs`` at a time, one progress line per finished stage; then the report (report.md
  with PNG figures and CSV tables in ``--out``) and a short summary.
* ``scenario POSITION SCENARIO``: one position and scenario alone: its model, analytic FRFs,
  loop poles, its testbed run and (if the study file lists it) its damping run, printed.
* ``report``: report.md of a finished run again, from the CSV tables in its folder.
* ``docs``: copy a run's tables to docs/results and rewrite the study sections of
  docs/results.md and the README from them (:mod:`pentapod_damper.study.readme`).
* ``damping``: the modes that dominate the TCP and their damping, per scenario.
* ``dynamics``: what the dampers' dynamics buy and cost (table of docs/statespace.md).

A failed stage stops the study with a one-line error (exit 1); Ctrl-C stops the running runs
and exits with 130.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import logging
import os
from pathlib import Path
import signal
import sys
import time
from typing import Any, Callable

import numpy as np

from pentapod_damper.laws import Dynamics
from pentapod_damper.study import bending, damping, dynamics, readme, report, tables
from pentapod_damper.study.config import load_study_config, StudyConfig
from pentapod_damper.study.pipeline import CHECK_CACHE
from pentapod_damper.study.records import StudyResults
from pentapod_damper.study.schedule import compute, Interrupted, run_study, study_graph
from pentapod_sim import shutdown
from pentapod_sim.cli import CommandParser
from pentapod_sim.errors import BagError, ConfigError, RunError
from pentapod_sim.scenario.domain import DOMAIN_VAR, user_domain

COMMANDS = ('run', 'scenario', 'report', 'docs', 'damping', 'dynamics')
#: The settings a run used (StudyConfig as JSON), read back by ``report``.
SETTINGS = 'study_settings.json'
#: Start and end of every stage [s after the study's start].
TIMELINE = 'timeline.csv'


def _say(msg: str) -> None:
    print(f'[study {time.strftime("%H:%M:%S")}] {msg}', flush=True)


def default_jobs() -> int:
    """Stages run at once by default: one per CPU this process may use."""
    return max(1, len(os.sched_getaffinity(0)))


def _settings(args: argparse.Namespace, positions: tuple[str, ...] | None,
              **overrides: object) -> StudyConfig:
    """The study file with the command line's settings; one imported model as the position."""
    if args.fe_model and positions:
        raise ConfigError('--positions and --fe-model exclude each other: an imported model '
                          'is the one position of the study')
    cfg = load_study_config(args.config, period=args.period, positions=positions,
                            **overrides)
    if args.fe_model:           # named after its file, like the outputs of `modes --fe-model`
        name = Path(args.fe_model).stem
        cfg = dataclasses.replace(cfg, positions=(name,), step_position=name)
    if cfg.step_position not in cfg.positions:
        raise ConfigError(f'step_response.position = {cfg.step_position} is not among the '
                          f'positions {", ".join(cfg.positions)}: add it (--positions) or '
                          'set step_response.position in the study file')
    return cfg


def _results(cfg: StudyConfig, out: str) -> StudyResults:
    res = StudyResults(cfg, np.linspace(*cfg.freq_grid[:2], int(cfg.freq_grid[2])),
                       Path(out))
    res.out_dir.mkdir(parents=True, exist_ok=True)
    return res


def _lane(runs: bool, jobs: int) -> bool:
    """One testbed run at a time: the user chose one ROS domain (ROS_DOMAIN_ID)."""
    lane = runs and user_domain(os.environ) is not None
    if lane and jobs > 1:
        _say(f'{DOMAIN_VAR} is set: the testbed runs go one at a time on domain '
             f'{os.environ[DOMAIN_VAR]} (unset it to run them side by side)')
    return lane


def cmd_run(args: argparse.Namespace) -> int:
    t_start = time.perf_counter()
    cfg = _settings(args, tuple(args.positions.split(',')) if args.positions else None)
    res = _results(cfg, args.out)
    runs = not args.analytic_only
    fe_model = Path(args.fe_model) if args.fe_model else None
    progress = run_study(res, args.jobs, _say, runs, _lane(runs, args.jobs), fe_model)
    for stage, (span, busy, count) in progress.timings().items():
        # busy: summed time of the stages (what they took one at a time); span: first start
        # to last end (the stages of others ran in between)
        res.timings[f'{stage}: {count} tasks, busy'] = busy
        res.timings[f'{stage}: first start to last end'] = span
        _say(f'{stage}: {count} tasks, {busy:.1f} s busy, {span:.1f} s from first start to '
             'last end')
    share = progress.busy_share(args.jobs)
    _say(f'{args.jobs} threads busy {share:.0%} of the time from the first stage to the last '
         f'(each stage, start and end: {TIMELINE})')
    res.timings[f'{args.jobs} threads busy [%]'] = 100.0 * share
    res.timings['total'] = time.perf_counter() - t_start
    report.write_csv(progress.timeline(t_start), res.out_dir / TIMELINE)
    (res.out_dir / SETTINGS).write_text(json.dumps(dataclasses.asdict(cfg), indent=1))
    path = report.write_report(res, res.out_dir)
    _print_summary(res, path)
    _say(f'done in {time.perf_counter() - t_start:.0f} s')
    return 0


def cmd_scenario(args: argparse.Namespace) -> int:
    scenarios = tuple(dict.fromkeys(('baseline', args.scenario)))
    own = {} if args.fe_model else {'step_position': args.position}
    cfg = _settings(args, None if args.fe_model else (args.position,), scenarios=scenarios,
                    **own)
    res = _results(cfg, args.out)
    runs = not args.analytic_only
    fe_model = Path(args.fe_model) if args.fe_model else None
    g = study_graph(cfg, res.out_dir, res.freq, runs, _lane(runs, args.jobs), fe_model)
    pos = cfg.positions[0]
    # the scenario's stages and what they need (dask leaves the rest of the graph out)
    wanted = {'models': g.models, 'analytic': g.analytic, 'lobes': g.lobes,
              **{name: {k: v for k, v in getattr(g, name).items() if k[1] == args.scenario}
                 for name in ('frf_runs', 'damping_runs')}}
    values, _ = compute(wanted, g.graph.stage_of, args.jobs, _say)
    for name, value in values.items():
        setattr(res, name, value)
    row = next(r for r in tables.summary_rows(res) if r.scenario == args.scenario)
    _print_rows([row])
    run = res.damping_runs.get((pos, args.scenario))
    modes = [m.analytic for m in run.modes] if run else res.analytic[pos, args.scenario].modes
    print(damping.format_table(modes))
    return 0


def cmd_report(args: argparse.Namespace) -> int:
    out = Path(args.out)
    missing = report.missing_tables(out) + ([] if (out / SETTINGS).is_file() else [SETTINGS])
    if missing:
        raise ConfigError(f'{out} is not the folder of a finished study run: it lacks '
                          f'{", ".join(missing)}')
    try:
        values = json.loads((out / SETTINGS).read_text())
        settings: dict[str, Any] = {k: tuple(v) if isinstance(v, list) else v
                                    for k, v in values.items()}
        cfg = StudyConfig(**settings)
    except (ValueError, TypeError) as err:
        raise ConfigError(f'{out / SETTINGS}: not the settings of a study run ({err})') from None
    print(f'report: {report.rewrite_report(out, cfg)}')
    return 0


def cmd_docs(args: argparse.Namespace) -> int:
    if args.study_out is not None:
        readme.copy_results(args.study_out, args.results, args.figures)
    readme.update_docs(args.readme, args.results_md, args.results)
    return 0


def cmd_damping(args: argparse.Namespace) -> int:
    lo, hi = (float(v) for v in args.band.split(','))
    table = damping.rows(args.positions.split(','), args.scenarios.split(','), CHECK_CACHE,
                         band=(lo, hi), count=args.count, directions=args.directions)
    print(damping.markdown_table(table) if args.markdown else damping.format_table(table))
    return 0


def cmd_dynamics(args: argparse.Namespace) -> int:
    candidate = None
    if args.candidate:
        order, bw, delay = args.candidate.split(',')
        candidate = Dynamics(int(order), float(bw), delay_steps=int(delay))
    table = dynamics.rows(args.positions.split(','), args.scenarios.split(','), CHECK_CACHE,
                          candidate)
    print(dynamics.markdown_table(table) if args.markdown else dynamics.format_table(table))
    return 0


def _print_rows(rows: list[tables.SummaryRow]) -> None:
    print(f'{"pos":4} {"scenario":18} {"peak um/N":>10} {"peak red.":>9} {"rms red.":>8} '
          f'{"depth gain":>10} {"meas. dev dB":>12} {"steps/s":>8}')
    for r in rows:
        dev = r.deviation_db if r.deviation_db is not None else float('nan')
        print(f'{r.position:4} {r.scenario:18} {r.peak_um_per_N:10.4f} {r.peak_reduction:9.2f} '
              f'{r.rms_reduction:8.2f} {r.stable_depth_gain:10.2f} {dev:12.2g} '
              f'{r.steps_per_s or 0:8.0f}')


def _print_summary(res: StudyResults, path: Path) -> None:
    print('\nSummary (analytic peak reduction; testbed check against the sampled loop)')
    _print_rows(tables.summary_rows(res))
    for s in tables.struts12_share(res):
        print(f'struts 1-2 achieve {s.peak_share:.0%} (peak) / {s.rms_share:.0%} (RMS) '
              f'of the all-struts improvement at {s.position}')
    for comparison in res.bending.values():
        for m in comparison.models:
            print(f'{m.position} {m.model:10} optimum {m.optimal_gain:9.4g} {m.gain_unit}: '
                  f'{m.reduction_all_opt:.2f}x, struts 1-2 {m.peak_share_12_opt:.0%} / '
                  f'{m.rms_share_12_opt:.0%}; at b = {bending.PAPER_GAIN:g}: '
                  f'{m.reduction_all_paper:.2f}x, struts 1-2 {m.peak_share_12_paper:.0%} / '
                  f'{m.rms_share_12_paper:.0%}')
    print(f'report: {path}')


def _study_options(parser: argparse.ArgumentParser, one_position: bool = False) -> None:
    parser.add_argument('--config', help='study YAML (default config/study.yaml)')
    parser.add_argument('--out', default='out/study', help='output folder')
    parser.add_argument('--period', type=float, help='multisine period of the FRF runs [s] '
                        '(line spacing 1 / period)')
    if not one_position:
        parser.add_argument('--positions', help='comma-separated positions, e.g. P1,P2')
    parser.add_argument('--fe-model', metavar='FILE.yaml', help='an imported FE model '
                        '(docs/own_machine.md) as the one position, named after the file')
    parser.add_argument('--analytic-only', action='store_true',
                        help='skip the testbed runs (no ROS): analytic results only')
    parser.add_argument('--jobs', type=int, default=default_jobs(),
                        help='stages (model builds, analytic FRFs, testbed runs) run at once '
                        '(default: one per CPU, here %(default)s)')


def build_parser() -> CommandParser:
    """The command line: one sub-command per part of the study (``run`` by default)."""
    parser = CommandParser(prog='python -m pentapod_damper.study',
                           description=__doc__.split('\n\n')[0],
                           formatter_class=argparse.RawDescriptionHelpFormatter,
                           epilog='\n\n'.join(__doc__.split('\n\n')[1:3]))
    sub = parser.add_subparsers(dest='command', metavar='COMMAND')
    _study_options(sub.add_parser('run', help='the whole study (default)'))
    one = sub.add_parser('scenario', help='one position and scenario alone')
    one.add_argument('position', help='position of config/positions.yaml (ignored with '
                     '--fe-model)')
    one.add_argument('scenario', help='scenario of config/scenarios')
    _study_options(one, one_position=True)
    again = sub.add_parser('report', help="a finished run's report.md again, from its tables")
    again.add_argument('--out', default='out/study', help='output folder of the run')
    docs = sub.add_parser('docs', help='docs/results and the study sections of '
                          'docs/results.md and the README, from a run')
    docs.add_argument('--from', dest='study_out', type=Path,
                      help='output folder of a study run, e.g. out/study')
    docs.add_argument('--readme', type=Path, default=Path('README.md'))
    docs.add_argument('--results-md', type=Path, default=Path('docs/results.md'))
    docs.add_argument('--results', type=Path, default=Path('docs/results'))
    docs.add_argument('--figures', type=Path, default=Path('docs/figures'))
    modes = sub.add_parser('damping', help='dominant TCP modes and their damping')
    modes.add_argument('--positions', default='P1,P2')
    modes.add_argument('--scenarios', default=','.join(damping.SCENARIOS))
    modes.add_argument('--count', type=int, default=damping.COUNT,
                       help='dominant modes per direction')
    modes.add_argument('--band', default=f'{damping.BAND[0]:g},{damping.BAND[1]:g}',
                       help='LOW,HIGH [Hz]')
    modes.add_argument('--directions', default='xyz', help='TCP directions, e.g. xyz or x')
    modes.add_argument('--markdown', action='store_true', help='print a Markdown table')
    dyn = sub.add_parser('dynamics', help="what the dampers' dynamics buy and cost")
    dyn.add_argument('--positions', default='P1,P2')
    dyn.add_argument('--scenarios', default=','.join(dynamics.SCENARIOS))
    dyn.add_argument('--try', dest='candidate', help='order,bandwidth_hz,delay_steps')
    dyn.add_argument('--markdown', action='store_true',
                     help='print the table of docs/statespace.md instead')
    return parser


#: Command -> what it does, and the errors that are the user's (one line, exit 1).
HANDLERS: dict[str, tuple[Callable[[argparse.Namespace], int], tuple[type[Exception], ...]]] = {
    'run': (cmd_run, (ConfigError, RunError, BagError)),
    'scenario': (cmd_scenario, (ConfigError, RunError, BagError)),
    'report': (cmd_report, (ConfigError, OSError)),
    'docs': (cmd_docs, (OSError, ValueError)),
    'damping': (cmd_damping, (ConfigError, ValueError)),
    'dynamics': (cmd_dynamics, (ConfigError, ValueError))}


def main(argv: list[str] | None = None) -> int:
    """Run a command: 0 on success, 1 with a one-line error, 128 + n on signal n."""
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or (argv[0] not in COMMANDS and argv[0] not in ('-h', '--help')):
        argv.insert(0, 'run')
    parser = build_parser()
    args = parser.parse_args(argv)
    if getattr(args, 'jobs', 1) < 1:
        parser.error(f'--jobs must be >= 1, got {args.jobs}')
    logging.basicConfig(level=logging.WARNING, format='%(levelname)s %(name)s: %(message)s')
    handler, user_errors = HANDLERS[args.command]
    previous = {sig: signal.getsignal(sig) for sig in shutdown.STOP_SIGNALS}
    shutdown.install()
    try:
        return handler(args)
    except user_errors as err:
        print(f'study {"failed" if args.command in ("run", "scenario") else args.command}: '
              f'{err}', file=sys.stderr)
        return 1
    except Interrupted as err:
        print(f'study stopped: {err}', file=sys.stderr)
        return err.code
    finally:
        for sig, before in previous.items():
            signal.signal(sig, before)


if __name__ == '__main__':
    sys.exit(main())
