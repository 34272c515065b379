"""
"Which damper to build": every law at P1 and P2, tuned under the machine's limits.

Builds each position's models (:func:`pentapod_sim.sim.design_models.load_design_model`),
runs :func:`pentapod_damper.design.table.damper_table` and writes ``dampers.csv``,
``dampers.md`` (tables, the issue's verdict and the strain-energy shares of the dominant
modes), ``dampers_<position>_<machine>_d<delay>.png`` and ``tables.pkl`` (the records, to
redraw) to ``--out``::

    python -m pentapod_damper.design [--positions P1,P2] [--machine locked|drives|both]
                                     [--sample-rate 5000] [--delay 1] [--grid 3]
                                     [--gain-points 8] [--refine 25] [--check-below HZ]
                                     [--quick] [--record FOLDER [--record-laws L1;L2]]
                                     [--records CSV] [--out out/design]

The full run tunes six families at two positions with the check model (about an hour on two
busy cores); ``--quick`` uses small grids and no check model (a few minutes).
"""
from __future__ import annotations

import argparse
import logging
from pathlib import Path
import pickle
import shutil
import sys

from pentapod_damper.design import recorded
from pentapod_damper.design.report import (
    energy_lines,
    fill,
    markdown,
    markdown_records,
    plot,
    read_csv,
    verdict,
    write_csv,
    write_energy_csv,
)
from pentapod_damper.design.report import records as table_records
from pentapod_damper.design.scenarios import write_scenarios
from pentapod_damper.design.table import add_strokes, damper_table, DamperTable, with_lowband
from pentapod_damper.design.verify import remeasure, verify_best
from pentapod_sim.cli import CommandParser, configure_logging, run_command
from pentapod_sim.sim.design_models import load_design_model
from pentapod_sim.sim.law_models import Dynamics
from pentapod_sim.sim.tuning import TuneSettings

LOG = logging.getLogger('design')
#: The recorded runs' CSV beside the docs page (docs/results/), read by test_damper_docs.
RECORDED_DOCS_CSV = Path('results') / 'dampers_recorded.csv'


def _tables(args: argparse.Namespace) -> list[DamperTable]:
    """The tables: computed, or read from a ``tables.pkl`` of an earlier run."""
    if args.from_tables:
        tables = []
        for path in args.from_tables.split(','):
            with open(path, 'rb') as stream:
                tables += list(pickle.load(stream))
        tables = [_with_strokes(with_lowband(table)) for table in tables]
        names = [n.strip() for n in args.remeasure.split(';') if n.strip()]
        if names:
            tables = [remeasure(table, load_design_model(
                table.position, table.settings.sample_rate, check=False, corners=False),
                names, progress=lambda msg: LOG.info('%s', msg)) for table in tables]
        return tables
    machines = ('locked', 'drives') if args.machine == 'both' else (args.machine,)
    tables = []
    for position in [p for p in args.positions.split(',') if p]:
        model = load_design_model(position, args.sample_rate, check=not args.quick,
                                  progress=lambda msg: LOG.info('%s', msg),
                                  check_subset_hz=args.check_below or None)
        for machine in machines:
            settings = TuneSettings(sample_rate=args.sample_rate, machine=machine,
                                    dynamics=Dynamics(delay_steps=args.delay),
                                    grid_points=2 if args.quick else args.grid,
                                    gain_points=4 if args.quick else args.gain_points,
                                    refine_iterations=2 if args.quick else args.refine)
            table = damper_table(model, settings, progress=lambda msg: LOG.info('%s', msg))
            tables.append(verify_best(table, model, progress=lambda msg: LOG.info('%s', msg)))
    return tables


def _with_strokes(table: DamperTable) -> DamperTable:
    """A table of a run before the strokes were measured, with them (design plant only)."""
    if all(row.stroke_unit is not None for row in table.rows):
        return table
    model = load_design_model(table.position, table.settings.sample_rate, check=False,
                              corners=False)
    return add_strokes(table, model)


def run(args: argparse.Namespace) -> int:
    """Build the tables (or read them) and write them."""
    if args.records:
        return _run_from_csv(args)
    tables = _tables(args)
    args.out.mkdir(parents=True, exist_ok=True)
    for table in tables:
        png = plot(table, args.out / f'dampers_{table.position}_{table.machine}_'
                               f'd{table.settings.dynamics.delay_steps}.png')
        print(f'wrote {png}')
    text = ['# Which damper to build', '']
    for table in tables:
        text += [markdown(table), '']
    records = [r for table in tables for r in table_records(table)]
    energy = write_energy_csv(tables, args.out / 'dampers_energy.csv')
    text += ['## Verdict', '', verdict(records), '', '## Strain energy of the modes that '
             'dominate the TCP (per stiffness group)', '', energy_lines(energy)]
    (args.out / 'dampers.md').write_text('\n'.join(text) + '\n')
    with open(args.out / 'tables.pkl', 'wb') as stream:      # to redraw without recomputing
        pickle.dump(tables, stream)
    print(f'wrote {write_csv(tables, args.out / "dampers.csv")} and {args.out / "dampers.md"}')
    print(verdict(records))
    if args.scenarios:
        position = tables[0].position
        model = load_design_model(position, tables[0].settings.sample_rate, check=False,
                                  corners=False)
        for path in write_scenarios(records, model.stiffness, position, args.scenarios):
            print(f'wrote {path}')
    _docs(args, records, _record(args, records), energy)
    return 0


def _run_from_csv(args: argparse.Namespace) -> int:
    """
    ``--records``: record (``--record``) and fill the docs from the table's CSVs, no tables.

    The records are the rows of a ``dampers.csv`` (docs/results/dampers.csv), the strain
    energy that of ``dampers_energy.csv`` beside it: what the docs blocks are generated from.
    """
    records = read_csv(args.records)
    recorded_csv = _record(args, records)
    _docs(args, records, recorded_csv, Path(args.records).parent / 'dampers_energy.csv')
    return 0


def _docs(args: argparse.Namespace, records: list[dict[str, str]], recorded_csv: Path | None,
          energy: Path) -> None:
    """With ``--docs``: the recorded runs' CSV kept beside the page, its blocks filled."""
    if not args.docs:
        return
    path = Path(args.docs)
    kept = path.parent / RECORDED_DOCS_CSV
    if recorded_csv is not None and recorded_csv.resolve() != kept.resolve():
        shutil.copyfile(recorded_csv, kept)
    runs = recorded.read_csv(kept) if kept.is_file() else []
    doc = fill(path.read_text(), 'dampers-table', markdown_records(records, runs))
    doc = fill(doc, 'dampers-energy', energy_lines(energy))
    doc = fill(doc, 'dampers-recorded', recorded.markdown(runs))
    path.write_text(fill(doc, 'dampers-verdict', verdict(records)))
    print(f'updated {path}')


def _record(args: argparse.Namespace, records: list[dict[str, str]]) -> Path | None:
    """Record the laws' damping runs (``--record``) or name an earlier run's CSV."""
    if args.recorded:
        return recorded.merge_csv([Path(p) for p in args.recorded.split(',')],
                                  args.out / 'recorded.csv')
    if not args.record:
        return None
    names = [n.strip() for n in args.record_laws.split(';') if n.strip()]
    rows = []
    wanted = args.positions.split(',')
    for position in dict.fromkeys(r['position'] for r in records if r['position'] in wanted):
        rows += recorded.record_position(records, position, args.record, print, names,
                                         args.record_period, build=not args.record_no_build)
    path = recorded.write_csv(rows, args.record / 'recorded.csv')
    print(f'wrote {path}')
    return path


def main(argv: list[str] | None = None) -> int:
    """Command line of the damper table."""
    parser = CommandParser(prog='python -m pentapod_damper.design', description=__doc__,
                           formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--positions', default='P1,P2',
                        help='comma-separated positions (computed, or recorded with --record)')
    parser.add_argument('--machine', choices=('locked', 'drives', 'both'), default='locked',
                        help='locked: the FE model as the study (drives infinitely stiff); '
                             'drives: with the feed drives of config/drives.yaml; both')
    parser.add_argument('--sample-rate', type=float, default=5000.0, metavar='HZ')
    parser.add_argument('--delay', type=int, default=1, metavar='SAMPLES',
                        help="the laws' computational delay (default 1)")
    parser.add_argument('--grid', type=int, default=3, metavar='N',
                        help="grid points of each family's secondary parameters (default 3)")
    parser.add_argument('--gain-points', type=int, default=8, metavar='N',
                        help='grid points of the main gain (default 8)')
    parser.add_argument('--refine', type=int, default=25, metavar='N',
                        help='Nelder-Mead iterations after the grid (default 25, 0: none)')
    parser.add_argument('--check-below', type=float, default=0.0, metavar='HZ',
                        help='the tuner checks on the check modes below HZ (static correction '
                             'of the others); the laws the verdict names are then checked on '
                             'the full check model (default 0: the full one throughout)')
    parser.add_argument('--quick', action='store_true',
                        help='small grids and no check model (a smoke run)')
    parser.add_argument('--out', type=Path, default=Path('out') / 'design')
    parser.add_argument('--from-tables', default='', metavar='PKL[,PKL]',
                        help='draw and write the tables of earlier runs (their tables.pkl, '
                             'comma-separated) instead of computing them')
    parser.add_argument('--remeasure', default='', metavar='LAW[;LAW]',
                        help='with --from-tables: measure these rows again at their tuned gains '
                             "(';'-separated table row names; check margins kept)")
    parser.add_argument('--scenarios', default='', metavar='FOLDER',
                        help='also write the scenario files of the tuned laws of the first '
                             'position (config/scenarios)')
    parser.add_argument('--docs', default='', metavar='FILE',
                        help='also rewrite the dampers-table and dampers-verdict blocks of FILE '
                             '(docs/dampers.md)')
    parser.add_argument('--record', type=Path, default=None, metavar='FOLDER',
                        help="record a multisine damping run of the table's strut laws at each "
                             'position on the testbed (lockstep, the damper node) and compare '
                             "the identified damping with the sampled loop's poles; writes "
                             'FOLDER/recorded.csv (and, with --docs, the dampers-recorded '
                             'block)')
    parser.add_argument('--record-laws', default='; '.join(recorded.DEFAULT_LAWS),
                        metavar='LAW[;LAW]',
                        help='the laws recorded besides the law to build (table row names, '
                             f"';'-separated; default {'; '.join(recorded.DEFAULT_LAWS)})")
    parser.add_argument('--record-no-build', action='store_true',
                        help="record only --record-laws, not also the verdict's law to build")
    parser.add_argument('--records', default='', metavar='CSV',
                        help="the table's records from its CSV (docs/results/dampers.csv; its "
                             'dampers_energy.csv beside it) instead of computing or reading '
                             'tables: to --record and to fill the --docs blocks')
    parser.add_argument('--record-period', type=float, default=None, metavar='S',
                        help="the recorded runs' multisine period [s] (default: the study's, "
                             'config/study.yaml damping.period)')
    parser.add_argument('--recorded', default='', metavar='CSV',
                        help='the recorded.csv of earlier --record runs (comma-separated), '
                             'for --docs')
    parser.add_argument('-v', '--verbose', action='store_true')
    args = parser.parse_args(argv)
    configure_logging(args.verbose)
    return run_command('design', run, args)


if __name__ == '__main__':
    sys.exit(main())
