r"""
`statespace lobes`: stability lobes of the machine with the laws of scenarios, analytic.

For each position and scenario the plant (config/reduction.yaml, as ``statespace build`` makes
it) is closed with the scenario's laws as its nodes run them (filters, delays and sampling
included: :func:`pentapod_sim.scenario.laws.scenario_loop_laws`) at the scenario's sample rate
(``--sample-rate`` for all), and the sampled loop's TCP FRF
(:mod:`pentapod_sim.machining.sampled_tcp`) gives the zero-order lobes of each operation of
config/machining.yaml (:mod:`pentapod_sim.machining.loop_lobes`). Per position and operation
it writes ``lobes_<position>_<operation>.png`` (one curve per scenario), ``.csv`` and
``_summary.csv``; over all, ``min_depths.csv`` (minimum stable depth, its chatter frequency,
best pocket and the stable depth gain over the first scenario). ``--depth-table FILE`` puts
the table of minimum stable depths between the ``machining-depths`` markers of FILE
(docs/machining.md). ``--check`` also prints the cutting runs that check each limit in the
time domain (speed, depths at 0.8x and 1.2x, durations); ``--record DIR`` runs them on the
testbed (composed, recorded to DIR) and prints each verdict of ``analyze chatter`` next to the
prediction, also into DIR/checks.csv. Examples::

    statespace lobes --position P1,P2 --scenario baseline,tcp_damping
    statespace lobes --scenario all --operation aluminium_half_down,steel_half_down \
        --depth-table docs/machining.md
    statespace lobes --position P1,P2 --scenario baseline,tcp_damping --record out/cutting
"""
from __future__ import annotations

import argparse
import csv
import logging
import math
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from pentapod_sim.cli.statespace_options import add_config_and_out, POSITIONS_HELP
from pentapod_sim.errors import ConfigError
from pentapod_sim.machining.lobe_plot import lobe_diagram
from pentapod_sim.machining.loop_lobes import check_runs, CuttingRun, loop_lobes, LoopLobes
from pentapod_sim.machining.materials import load_machining, MachiningTable
from pentapod_sim.parameters import sample_time
from pentapod_sim.reference import replace_section

LOGGER = logging.getLogger('statespace')
#: Scenarios of the default diagram: the machine without and with the TCP damper.
DEFAULT_SCENARIOS = 'baseline,tcp_damping'
DEFAULT_OPERATIONS = 'aluminium_half_down'
#: Marker name of the table of minimum stable depths in docs/machining.md.
DEPTH_SECTION = 'machining-depths'
#: Marker name of the table of recorded check runs in docs/machining.md.
RUNS_SECTION = 'machining-runs'
MIN_DEPTH_COLUMNS = ('position', 'scenario', 'operation', 'sample_rate_Hz', 'min_depth_m',
                     'min_depth_chatter_Hz', 'min_depth_resolved', 'best_pocket_m',
                     'best_pocket_rpm', 'stable_depth_gain')


def add_lobes_parser(sub: Any) -> None:
    """Register the ``lobes`` sub-command on the ``statespace`` sub-parsers."""
    p = sub.add_parser('lobes', help='stability lobes of the machine with the laws of '
                       'scenarios (sampled closed loop), minimum stable depths')
    p.set_defaults(func=cmd_lobes)
    add_config_and_out(p)
    p.add_argument('--position', default=None, help=POSITIONS_HELP)
    p.add_argument('--scenario', default=DEFAULT_SCENARIOS,
                   help='comma-separated scenarios (names of config/scenarios or files; '
                        f'"all": every shipped one; default {DEFAULT_SCENARIOS}); the first '
                        'is the reference of the stable depth gain')
    p.add_argument('--operation', default=DEFAULT_OPERATIONS,
                   help='comma-separated operations of the machining table '
                        f'(default {DEFAULT_OPERATIONS})')
    p.add_argument('--machining', default=None,
                   help='machining table (default: config/machining.yaml)')
    p.add_argument('--sample-rate', type=float, default=None, metavar='HZ',
                   help="sample rate of every loop [Hz] (default: each scenario's)")
    p.add_argument('--speeds', nargs=2, type=float, metavar=('MIN', 'MAX'),
                   help='spindle speed range [rpm] (default: from the table)')
    p.add_argument('--n-speeds', type=int, default=2000, help='speeds of the diagram')
    p.add_argument('--band', nargs=2, type=float, default=(1.0, 1000.0),
                   metavar=('F1', 'F2'), help='chatter frequencies considered [Hz] '
                   '(default 1 1000)')
    p.add_argument('--depth-table', type=Path, default=None, metavar='FILE',
                   help=f'write the table of minimum stable depths between the {DEPTH_SECTION} '
                        'markers of FILE')
    p.add_argument('--check', action='store_true',
                   help='also print the time-domain check of each limit: speed, depths at '
                        '0.8x and 1.2x of the limit, run durations')
    p.add_argument('--record', type=Path, default=None, metavar='DIR',
                   help='run the checks on the testbed (composed, recorded to DIR) and print '
                        'the verdict of each recording (implies --check)')
    p.add_argument('--runs-table', type=Path, default=None, metavar='FILE',
                   help=f'write the recorded checks (needs --record) between the {RUNS_SECTION} '
                        'markers of FILE')


def scenario_names(text: str) -> list[str]:
    """The scenarios of ``--scenario`` (``all``: every shipped scenario)."""
    from pentapod_sim.scenario.files import scenario_names as shipped
    names = shipped() if text == 'all' else [s for s in text.split(',') if s]
    if not names:
        raise ConfigError(f'--scenario {text!r} names no scenario')
    if 'baseline' in names:           # the reference of the gains first
        names.remove('baseline')
        names.insert(0, 'baseline')
    return names


def position_lobes(plant: Any, position: str, scenarios: Sequence[str], table: MachiningTable,
                   operations: Sequence[str], speeds: np.ndarray,
                   sample_rate: float | None = None,
                   band: tuple[float, float] = (1.0, 1000.0)) -> list[LoopLobes]:
    """
    The lobes of every scenario at one position (the study's machining section calls this).

    Each scenario's laws are built as its nodes run them, at ``sample_rate`` [Hz] or the
    scenario's own, on ``plant`` as its plant node steps it (with the feed drives' rotors if
    it has ``drives``); ConfigError names a scenario whose loop is unstable.
    """
    from pentapod_sim.scenario.laws import scenario_dt, scenario_loop_laws, scenario_plant
    out = []
    for scenario in scenarios:
        dt = sample_time(sample_rate) if sample_rate else scenario_dt(scenario)
        laws = scenario_loop_laws(scenario, dt)
        label = Path(scenario).stem
        out.append(loop_lobes(scenario_plant(scenario, plant), laws, dt, table, operations,
                              speeds, label, position, band))
        LOGGER.info('%s %s: lobes at %g Hz, %d frequencies', position, label, 1 / dt,
                    out[-1].loop.frf.freq.size)
    return out


def depth_rows(records: Sequence[LoopLobes], operations: Sequence[str]) -> list[list[Any]]:
    """Rows of ``min_depths.csv`` (:data:`MIN_DEPTH_COLUMNS`); the gain over the first."""
    rows = []
    for rec in records:
        base = next(r for r in records if r.position == rec.position)
        for op in operations:
            s = rec.operations[op].summary
            rows.append([rec.position, rec.label, op, 1.0 / rec.loop.dt, s.min_depth,
                         s.min_depth_freq, s.resolved, s.pocket_depth, s.pocket_speed,
                         rec.gain_over(base, op)])
    return rows


def depth_table(records: Sequence[LoopLobes], operations: Sequence[str]) -> str:
    """Markdown: minimum stable depth [mm] and its gain over the first scenario, per row."""
    heads = [f'{op} [mm]' for op in operations]
    lines = ['| position | scenario | ' + ' | '.join(heads) + ' | stable depth gain |',
             '|---|---|' + '---|' * len(heads) + '---|']
    for rec in records:
        base = next(r for r in records if r.position == rec.position)
        depths = [f'{rec.min_depth(op) * 1e3:.4g}' for op in operations]
        gains = ' / '.join(f'{rec.gain_over(base, op):.3g}x' for op in operations)
        lines.append(f'| {rec.position} | {rec.label} | ' + ' | '.join(depths) +
                     f' | {gains} |')
    return '\n'.join(lines)


def cmd_lobes(args: argparse.Namespace) -> int:
    """Lobe diagrams per position and operation; the table of minimum stable depths."""
    from pentapod_sim.plant.build import build_plant
    table = load_machining(args.machining)
    operations = [op for op in args.operation.split(',') if op]
    for op in operations:
        table.operation(op)                      # a misspelt name before any computation
    scenarios = scenario_names(args.scenario)
    low, high = args.speeds if args.speeds else table.spindle_speeds
    if not 0 < low < high or args.n_speeds < 2:
        raise ConfigError(f'--speeds {low} {high} must satisfy 0 < MIN < MAX and --n-speeds '
                          f'{args.n_speeds} >= 2')
    speeds = np.linspace(low, high, args.n_speeds)
    if args.runs_table is not None and args.record is None:
        raise ConfigError('--runs-table needs --record DIR (the runs it tabulates)')
    positions = [p for p in (args.position or ','.join(args.cfg.positions)).split(',') if p]
    records: list[LoopLobes] = []
    checks: list[list[Any]] = []
    for position in positions:
        plant = build_plant(position, reduction_cfg=args.cfg)
        found = position_lobes(plant, position, scenarios, table, operations, speeds,
                               args.sample_rate, tuple(args.band))
        records += found
        for op in operations:
            diagram = lobe_diagram([r.operations[op].limit for r in found], speeds,
                                   args.out / f'lobes_{position}_{op}',
                                   title=f'{position}, {op}: sampled loop with each '
                                         "scenario's laws (stable below)")
            for summ in diagram.summaries:
                print(f'{position} {summ.label} {op}: minimum stable depth '
                      f'{summ.min_depth * 1e3:.4g} mm (chatter at {summ.min_depth_freq:.2f} '
                      f'Hz); best pocket {summ.pocket_depth * 1e3:.4g} mm at '
                      f'{summ.pocket_speed:.0f} rpm')
            print(f'wrote {diagram.png}')
            if args.check or args.record:
                for rec in found:
                    checks += _check(plant, rec, op, table, args.record)
    path = args.out / 'min_depths.csv'
    with open(path, 'w', newline='', encoding='utf-8') as stream:
        writer = csv.writer(stream)
        writer.writerow(MIN_DEPTH_COLUMNS)
        writer.writerows(depth_rows(records, operations))
    print(f'wrote {path}')
    if args.record:
        path = args.record / 'checks.csv'
        with open(path, 'w', newline='', encoding='utf-8') as stream:
            writer = csv.writer(stream)
            writer.writerow(CHECK_COLUMNS)
            writer.writerows(checks)
        print(f'wrote {path}')
    if args.depth_table is not None:
        _write_section(args.depth_table, DEPTH_SECTION, depth_table(records, operations))
        print(f'wrote the table of minimum stable depths into {args.depth_table}')
    if args.runs_table is not None:
        _write_section(args.runs_table, RUNS_SECTION, runs_table(checks))
        print(f'wrote the table of recorded checks into {args.runs_table}')
    return 0


def _write_section(doc: Path, name: str, body: str) -> None:
    text = doc.read_text(encoding='utf-8')
    try:
        doc.write_text(replace_section(text, name, body), encoding='utf-8')
    except ValueError as err:
        raise ConfigError(f'{doc}: {err}') from None


def runs_table(checks: Sequence[Sequence[Any]]) -> str:
    """Markdown of the recorded checks (rows of :data:`CHECK_COLUMNS`)."""
    lines = ['| position | scenario | operation | speed [rpm] | limit [mm] | predicted chatter '
             '[Hz] | run | depth [mm] | simulated [s] | expected | verdict of the recording | '
             'chatter [Hz] | growth [1/s] | off harmonics | predicted growth [1/s] | averaged '
             'loop [1/s] | critical multiplier | wall [s] |',
             '|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|']
    for row in checks:
        r = dict(zip(CHECK_COLUMNS, row))
        lines.append(f"| {r['position']} | {r['scenario']} | {r['operation']} | "
                     f"{r['speed_rpm']:.1f} | {r['limit_m'] * 1e3:.4g} | {r['chatter_Hz']:.1f} | "
                     f"{r['factor']:g}x | {r['depth_m'] * 1e3:.4g} | {r['duration_s']:.3g} | "
                     f"{r['expected']} | {r['verdict']} | {r['measured_chatter_Hz']:.1f} | "
                     f"{r['growth_rate_per_s']:+.3g} | {r['off_harmonic_share']:.1%} | "
                     f"{r['predicted_rate_per_s']:+.3g} | {r['averaged_rate_per_s']:+.3g} | "
                     f"{r['multiplier']} | {r['wall_time_s']:.0f} |")
    return '\n'.join(lines)


#: Columns of checks.csv (``--record``).
CHECK_COLUMNS = ('position', 'scenario', 'operation', 'speed_rpm', 'limit_m', 'chatter_Hz',
                 'factor', 'depth_m', 'duration_s', 'predicted_rate_per_s', 'expected',
                 'verdict', 'measured_chatter_Hz', 'growth_rate_per_s', 'off_harmonic_share',
                 'left_cut_share', 'wall_time_s', 'bag', 'averaged_rate_per_s', 'multiplier')


def _check(plant: Any, rec: LoopLobes, op: str, table: MachiningTable,
           record: Path | None) -> list[list[Any]]:
    """Print the cutting runs that check one limit; with ``record`` run and judge them."""
    from pentapod_sim.scenario.laws import scenario_loop_laws, scenario_plant
    laws = scenario_loop_laws(rec.label, rec.loop.dt)
    point = check_runs(scenario_plant(rec.label, plant), laws, rec.loop.dt, table,
                       rec.operations[op])
    runs = '; '.join(f'{r.factor:g}x = {r.params["axial_depth"] * 1e3:.4g} mm for '
                     f'{r.duration:.3g} s (rate {r.growth_rate:+.3g} 1/s, {_multiplier(r)}; '
                     f'averaged loop {r.averaged_rate:+.3g} 1/s; expect {r.expected})'
                     for r in point.runs)
    print(f'  check {rec.position} {rec.label} {op}: at {point.speed:.1f} rpm the limit is '
          f'{point.depth * 1e3:.4g} mm (chatter {point.chatter_freq:.1f} Hz): {runs}')
    if record is None:
        return []
    from pentapod_sim.scenario.cutting import record_cut
    record.mkdir(parents=True, exist_ok=True)
    model = record / f'plant_{rec.position}.npz'
    if not model.is_file():
        plant.save(model)
    rows = []
    for run in point.runs:
        name = f'{rec.position}_{rec.label}_{op}_{run.factor:g}x'.replace('.', '_')
        done = record_cut(rec.label, run, record / name, model_file=str(model))
        v = done.verdict
        print(f'    {run.factor:g}x: {v.verdict} (expected {run.expected}'
              f'{"" if done.as_expected else ", NOT AS PREDICTED"}); chatter '
              f'{v.chatter_freq:.2f} Hz, growth {v.growth_rate:+.3g} 1/s, '
              f'{v.off_harmonic_share:.1%} off the harmonics, {v.left_cut_share:.2%} without '
              f'chip; {done.wall_time:.0f} s wall; bag {done.bag}')
        rows.append([rec.position, rec.label, op, point.speed, point.depth, point.chatter_freq,
                     run.factor, run.params['axial_depth'], run.duration, run.growth_rate,
                     run.expected, v.verdict, v.chatter_freq, v.growth_rate,
                     v.off_harmonic_share, v.left_cut_share, done.wall_time, str(done.bag),
                     run.averaged_rate, _multiplier(run)])
    return rows


def _multiplier(run: CuttingRun) -> str:
    """The critical Floquet multiplier as modulus, angle [deg] and kind."""
    mu = run.multiplier
    return f'{abs(mu):.5f} at {math.degrees(math.atan2(mu.imag, mu.real)):+.1f} deg ({run.kind})'
