"""
Workspace sweep on Dask: ``python -m pentapod_damper.sweep [poses] [options]``.

Poses: a grid (``--x lo:hi:n --y ... --z ... --a-deg ... --b-deg ...``, each one value or
``lo:hi:n``), ``--pose x,y,z,a_deg,b_deg`` (repeatable), ``--positions P1,P2`` or
``--csv FILE``. Results go to ``<out>/results/*.parquet`` (one file per finished task; a rerun
skips the poses already done), figures to ``<out>/figures``. Usage and cluster set-up:
docs/sweep.md.
"""
from __future__ import annotations

import argparse
import logging
from pathlib import Path
import sys
import time

import numpy as np

from pentapod_damper.sweep import poses as pose_input
from pentapod_damper.sweep.compute import columns
from pentapod_damper.sweep.runner import DEFAULT_WORKERS, run_sweep, SweepReport
from pentapod_damper.sweep.settings import make_settings
from pentapod_damper.sweep.store import ResultStore
from pentapod_sim.cli import CommandParser
from pentapod_sim.errors import ConfigError

#: Exit status after Ctrl-C (the finished tasks are stored).
INTERRUPTED = 130


def _parser() -> argparse.ArgumentParser:
    parser = CommandParser(prog='sweep', description=__doc__.split('\n\n')[0])
    grid = parser.add_argument_group('grid (SI units, tilts in degrees)')
    for axis, default in (('x', '0'), ('y', '0'), ('z', '0.85'), ('a-deg', '0'),
                          ('b-deg', '0')):
        grid.add_argument(f'--{axis}', default=None, metavar='V|LO:HI:N',
                          help=f'{axis} values (default {default} when a grid is given)')
    parser.add_argument('--pose', action='append', default=[], metavar='X,Y,Z,A_DEG,B_DEG',
                        help='one pose [m, m, m, deg, deg]; repeatable')
    parser.add_argument('--positions', help='named positions of config/positions.yaml')
    parser.add_argument('--csv', help='CSV with columns x, y, z [m] and a, b [rad] or a_deg, '
                                      'b_deg [deg]')
    parser.add_argument('--scenarios', help="damped scenarios (default: the study's)")
    parser.add_argument('--gain-factors', default='1', help="factors on the scenarios' gains, "
                                                            'e.g. 0.5,1,2')
    parser.add_argument('--n-points', type=int, help='points of the FRF grid (default the '
                                                     "study's)")
    parser.add_argument('--out', default='out/sweep', help='output folder')
    parser.add_argument('--scheduler', help='address (tcp://host:8786) or scheduler file '
                                            '(*.json) of a running Dask scheduler (default: '
                                            'start a LocalCluster)')
    parser.add_argument('--workers', type=int, default=DEFAULT_WORKERS,
                        help='LocalCluster worker processes (1 thread each)')
    parser.add_argument('--batch', type=int, default=1, help='poses per Dask task')
    parser.add_argument('--serial', action='store_true', help='plain loop in this process')
    parser.add_argument('--no-progress', action='store_true', help='no progress bar')
    parser.add_argument('--no-plots', action='store_true', help='skip the figures')
    parser.add_argument('--plot-only', action='store_true',
                        help='compute nothing; draw the figures of the stored results')
    return parser


def poses_of(args: argparse.Namespace) -> np.ndarray:
    """The poses the arguments ask for (grid, list, named positions and CSV together)."""
    parts = []
    if any(getattr(args, a) is not None for a in ('x', 'y', 'z', 'a_deg', 'b_deg')):
        parts.append(pose_input.grid(args.x or '0', args.y or '0', args.z or '0.85',
                                     args.a_deg or '0', args.b_deg or '0'))
    if args.pose:
        parts.append(np.array([pose_input.parse_pose(p) for p in args.pose]))
    if args.positions:
        parts.append(pose_input.named_poses([p for p in args.positions.split(',') if p]))
    if args.csv:
        parts.append(pose_input.read_csv(args.csv))
    if not parts:
        raise ConfigError('no poses: give a grid (--x/--y/--z/--a-deg/--b-deg), --pose, '
                          '--positions or --csv')
    return pose_input.unique(np.concatenate(parts))


def _print_report(report: SweepReport) -> None:
    counts = ', '.join(f'{n} {s}' for s, n in sorted(report.counts.items())) or 'none'
    print(f'{report.poses} poses: {report.skipped} already done, {report.computed} computed '
          f'now ({counts}) in {report.seconds:.1f} s on {report.workers} worker(s)'
          + (f', {report.poses_per_minute:.1f} poses/min' if report.computed else ''))
    for pose, error in report.errors[:5]:
        print(f'  failed at {np.round(pose, 4).tolist()}: {error}')
    if len(report.errors) > 5:
        print(f'  ... and {len(report.errors) - 5} more failed poses (status failed in the '
              'results)')


def _plots(store: ResultStore, out_dir: Path) -> None:
    from pentapod_damper.sweep import sweep_plot
    table = store.load()
    paths = sweep_plot.all_figures(table, store.schema, out_dir / 'figures')
    for path in paths:
        print(f'figure: {path}')
    for line in sweep_plot.claim_lines(table):
        print(line)


def main(argv: list[str] | None = None) -> int:
    """Run the sweep; 0 on success, 1 with a message for bad input, 130 when interrupted."""
    args = _parser().parse_args(argv)
    logging.basicConfig(level=logging.WARNING, format='%(levelname)s %(name)s: %(message)s')
    t0 = time.perf_counter()
    try:
        scenarios = [s for s in args.scenarios.split(',') if s] if args.scenarios else None
        factors = [float(f) for f in args.gain_factors.split(',') if f]
        settings = make_settings(scenarios, factors, n_points=args.n_points)
        store = ResultStore(args.out, columns(settings), settings.digest)
        if not args.plot_only:
            poses = poses_of(args)
            report = run_sweep(poses, settings, args.out, scheduler=args.scheduler,
                               n_workers=args.workers, batch=args.batch, serial=args.serial,
                               progress=not args.no_progress)
            _print_report(report)
            if report.interrupted:
                print(f'interrupted: {report.computed} poses stored under {args.out}; run the '
                      'same command again to resume', file=sys.stderr)
                return INTERRUPTED
        if not args.no_plots:
            _plots(store, store.out_dir)        # --plot-only: whatever the folder holds
    except ValueError as err:          # ConfigError and bad numbers on the command line
        print(f'sweep: {err}', file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print('interrupted', file=sys.stderr)
        return INTERRUPTED
    print(f'[sweep] done in {time.perf_counter() - t0:.1f} s; results in {args.out}/results')
    return 0


if __name__ == '__main__':
    sys.exit(main())
