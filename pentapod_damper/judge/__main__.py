"""
Judge a damping controller in one command: recorded lockstep runs, the battery, the verdict.

    judge my_lab.controllers:LabDamper --params lab.yaml      # a class of your package
    judge my_lab.yaml                                         # a scenario naming your class
    judge --command 'python -m my_lab.node' --source lab      # a command, started every run
    judge --node lab                                          # a node that already runs
    judge --compare my_lab.controllers:LabDamper tcp_damping  # two side by side

(``python -m pentapod_damper.judge`` is the same.) Every run is recorded; the report of each
judged controller (summary table first; Markdown with PNGs, self-contained HTML, CSV of every
number) goes to ``<out>/<controller>/``. Settings and thresholds: config/judge.yaml
(``--config`` for your copy). Exit code 0 if every criterion passed, 3 if one failed, 1 on an
error (one line), 130 after Ctrl-C. docs/nodes.md, "Writing your own controller".
"""
from __future__ import annotations

import argparse
import logging
from pathlib import Path
import sys
import time

from pentapod_damper.judge import controller as controllers
from pentapod_damper.judge.battery import plan, run_position, SECTIONS
from pentapod_damper.judge.config import load_judge_config
from pentapod_damper.judge.controller import Controller
from pentapod_damper.judge.models import position_model
from pentapod_damper.judge.report import write_page
from pentapod_damper.judge.runs import Runner
from pentapod_damper.judge.verdict import FAIL
from pentapod_sim import shutdown
from pentapod_sim.cli import CommandParser, run_command
from pentapod_sim.errors import ConfigError, RunError
from pentapod_sim.fe.machine_data import load_positions, positions_path

#: Exit code of a judgement whose verdict failed.
EXIT_FAILED = 3


def _say(msg: str) -> None:
    print(f'[judge {time.strftime("%H:%M:%S")}] {msg}', flush=True)


def _names(text: str | None) -> tuple[str, ...]:
    return tuple(p.strip() for p in text.split(',') if p.strip()) if text else ()


def parser() -> CommandParser:
    """The command line (module docstring)."""
    p = CommandParser(prog='judge', description=__doc__.split('\n\n')[0],
                      formatter_class=argparse.RawDescriptionHelpFormatter,
                      epilog=__doc__.split('\n\n', 1)[1])
    p.add_argument('controller', nargs='?', help='module:Class, or a scenario (shipped name or '
                   'file) whose force sources other than the exciter are the controller')
    how = p.add_mutually_exclusive_group()
    how.add_argument('--command', help='command line started for every run (separate '
                     "processes, in the run's ROS domain)")
    how.add_argument('--node', help='name of a node that already runs (on ROS_DOMAIN_ID, 0 if '
                     'unset)')
    how.add_argument('--compare', nargs=2, metavar=('A', 'B'), help='judge A with B in the '
                     'reference column (and B with A); each module:Class or a scenario')
    p.add_argument('--params', help='parameter file of a class or command (one ROS 2 section, '
                   'or a plain mapping)')
    p.add_argument('--source', help='source name of its answers (/pentapod/forces/<source>)')
    p.add_argument('--ports', help='input ports it answers, comma-separated (default: from '
                   'its first recording; with --compare, of both)')
    p.add_argument('--sensors', help='output ports it reads, comma-separated (default: its '
                   'published model, else the velocities collocated with its ports)')
    p.add_argument('--config', help='settings and thresholds (default config/judge.yaml)')
    p.add_argument('--positions', help="positions, comma-separated (default: the config's)")
    p.add_argument('--sample-rate', type=float, help='plant sample rate [Hz]')
    p.add_argument('--directions', help='TCP directions, e.g. xyz or x')
    p.add_argument('--reference', help='scenario of the reference law (none: no reference)')
    p.add_argument('--model-file', help='a saved plant model instead of the positions')
    p.add_argument('--check-model', help='its check model (saved PlantModel)')
    p.add_argument('--sections', help=f'sections to run, comma-separated (default all: '
                   f'{",".join(SECTIONS)})')
    p.add_argument('--out', default='out/judge', help='output folder (default out/judge)')
    p.add_argument('--fresh', action='store_true', help='run the baseline and shipped laws '
                   'again instead of reusing their earlier runs')
    p.add_argument('-v', '--verbose', action='store_true', help='log the analysis steps')
    return p


def judged_controllers(args: argparse.Namespace, reference: str) -> list[Controller]:
    """The controller under judgement and its reference column, from the command line."""
    ports, sensors = _names(args.ports), _names(args.sensors)
    if args.compare:
        pair = [controllers.parse(spec, ports=ports, sensors=sensors) for spec in args.compare]
        if pair[0].label == pair[1].label or set(pair[0].sources) & set(pair[1].sources):
            raise ConfigError(f'--compare {" ".join(args.compare)}: the two controllers need '
                              'distinct names and source names')
        return pair
    if sum(bool(v) for v in (args.controller, args.command, args.node)) != 1:
        raise ConfigError('name one controller: module:Class, a scenario, --command, --node '
                          'or --compare A B')
    if args.command:
        main = controllers.from_command(args.command, args.source, ports, sensors)
    elif args.node:
        main = controllers.from_node(args.node, args.source, ports, sensors)
    else:
        main = controllers.parse(args.controller, args.params, args.source, ports, sensors)
    out = [main]
    if reference:
        ref = controllers.from_scenario(reference)
        if ref.label != main.label:
            out.append(ref)
    return out


def run(args: argparse.Namespace) -> int:
    """Plan, run, analyse, write the pages; return the exit code."""
    reference = args.reference
    if reference is not None and reference.lower() in ('none', ''):
        reference = ''
    directions = tuple(args.directions) if args.directions else None
    cfg = load_judge_config(args.config, positions=list(_names(args.positions)) or None,
                            sample_rate=args.sample_rate, reference=reference,
                            directions=list(directions) if directions else None)
    sections = _names(args.sections) or SECTIONS
    for name in sections:
        if name not in SECTIONS:
            raise ConfigError(f'--sections: unknown section {name!r} (known: '
                              f'{", ".join(SECTIONS)})')
    judged = judged_controllers(args, '' if args.compare else cfg.reference)
    out = Path(args.out)
    check = 'robustness' in sections
    if args.model_file:
        positions = [position_model('', cfg.sample_rate, cfg.robustness.check_f_min,
                                    out / 'models', args.model_file, args.check_model, check)]
    else:
        known = list(load_positions(positions_path(None)))
        for name in cfg.positions:
            if name not in known:
                raise ConfigError(f'no position {name!r} in config/positions.yaml (known: '
                                  f'{", ".join(known)})')
        _say(f'models of {", ".join(cfg.positions)} (built once, then cached in out/models)')
        positions = [position_model(name, cfg.sample_rate, cfg.robustness.check_f_min,
                                    Path('out/models'), with_check=check)
                     for name in cfg.positions]
    specs, settle = plan(cfg, positions, judged, sections)
    runner = Runner(out, specs, args.fresh, _say)
    _say(f'judging {" and ".join(c.label for c in judged)} at '
         f'{", ".join(p.name for p in positions)}: {len(specs)} runs planned, {runner.left()}')
    t0 = time.perf_counter()
    results = []
    for pos in positions:
        results.append(run_position(cfg, pos, judged, specs, settle[pos.name], runner,
                                    sections, _say))
        _say(f'{pos.name}: runs and analysis in {results[-1].seconds:.0f} s')
    code = 0
    for ctrl in judged:
        others = [c.label for c in judged if c is not ctrl]
        path, verdict, _ = write_page(cfg, ctrl, others[0] if others else None, results,
                                      out / ctrl.slug)
        _say(f'{ctrl.label}: {verdict}; report {path} (and report.html, numbers.csv)')
        if ctrl is judged[0] and verdict == FAIL:
            code = EXIT_FAILED
    _say(f'battery done in {time.perf_counter() - t0:.0f} s')
    return code


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``judge`` (``python -m pentapod_damper.judge``)."""
    args = parser().parse_args(argv)
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING,
                        format='%(levelname)s %(name)s: %(message)s')
    shutdown.install()
    code = run_command('judge', run, args, errors=(RunError,))
    if shutdown.requested():
        print(f'judge: stopped by {shutdown.signal_name()}', file=sys.stderr)
        return shutdown.exit_code()
    return code


if __name__ == '__main__':
    sys.exit(main())
