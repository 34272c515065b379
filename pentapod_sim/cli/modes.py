"""
`modes`: modal analysis of the pentapod at a named position, with the cause of every mode.

Examples::

    modes --position P1                       # all modes below 750 Hz, default mesh
    modes --position P2 --rows 40 --out out/modes/P2
    modes --position P1 --refine 260 --n-modes 500 --no-neuber   # paper scale (~800k DOF)
    modes --fe-model machine.yaml --f-max 400     # an imported FE model (docs/own_machine.md)

Prints the mode table (no., frequency [Hz], dominant TCP direction, cause by strain energy,
cause by one-elasticity-at-a-time models, strain-energy shares [%]) and the totals (DOF
count, solve time [s], modes below 750 Hz by Sturm count); writes ``modes.csv``,
``energy_shares.png`` and ``mode_distribution.png`` to ``--out``
(default ``out/modes/<position>``, ``out/modes/<description stem>`` for ``--fe-model``).
"""
from __future__ import annotations

import argparse
import logging
import math
from pathlib import Path
import sys
import time
from typing import Any

from pentapod_sim.cli import (
    add_model_arguments,
    CommandParser,
    configure_logging,
    model_from_args,
    model_label,
    run_command,
)
from pentapod_sim.errors import ModalError
from pentapod_sim.fe.model import FEModel
from pentapod_sim.modes.cause_plots import plot_energy_shares, plot_mode_distribution
from pentapod_sim.modes.causes import (
    analyse_causes,
    DEFAULT_ALPHA,
    DEFAULT_ROTATION_LENGTH,
)
from pentapod_sim.modes.solver import ModalResult, solve_modes
from pentapod_sim.modes.sturm import sturm_count
from pentapod_sim.modes.window_pool import PARALLEL_MIN_DOF

LOGGER = logging.getLogger('modes')
#: Frequency band of the paper's mode count [Hz].
PAPER_BAND_HZ = 750.0


def _parser() -> argparse.ArgumentParser:
    parser = CommandParser(prog='modes', description=__doc__.split('\n\n')[0])
    add_model_arguments(parser)
    parser.add_argument('--n-modes', type=int, default=None,
                        help='number of lowest modes (with --f-max: at most this many)')
    parser.add_argument('--f-max', type=float, default=None,
                        help=f'all modes below this frequency [Hz] (default {PAPER_BAND_HZ:g} '
                        'when --n-modes is not given)')
    parser.add_argument('--rows', type=int, default=30, help='table rows to print')
    parser.add_argument('--out', type=Path, default=None,
                        help='output directory (default out/modes/<position>)')
    parser.add_argument('--no-neuber', action='store_true',
                        help='skip the one-elasticity-at-a-time models (one solve per group)')
    parser.add_argument('--alpha', type=float, default=DEFAULT_ALPHA,
                        help='stiffness factor of the groups made rigid [-]')
    parser.add_argument('--rotation-length', type=float, default=DEFAULT_ROTATION_LENGTH,
                        help='lever arm [m] weighing TCP rotations against translations when '
                        'naming the dominant TCP direction')
    parser.add_argument('--modes-per-window', type=int, default=None,
                        help='modes per spectrum slice of the eigen solver')
    parser.add_argument('--workers', type=int, default=None,
                        help='processes solving spectrum slices side by side (default: one per '
                        f'core from {PARALLEL_MIN_DOF:,} DOF, else 1)')
    parser.add_argument('-v', '--verbose', action='store_true', help='debug log lines')
    return parser


def _solve(model: FEModel, args: argparse.Namespace) -> ModalResult:
    kwargs: dict[str, Any] = {'n_modes': args.n_modes, 'f_max': args.f_max}
    if args.n_modes is None and args.f_max is None:
        kwargs['f_max'] = PAPER_BAND_HZ
    if args.modes_per_window:
        kwargs['modes_per_window'] = args.modes_per_window
    if args.workers is not None:
        kwargs['workers'] = args.workers
    return solve_modes(model.K, model.M, **kwargs)


def _band_count(model: FEModel, modes: ModalResult) -> int:
    """Modes below 750 Hz: the solver's Sturm count if it used that limit, else a new one."""
    if modes.f_max == PAPER_BAND_HZ and modes.sturm_count is not None:
        return modes.sturm_count
    return sturm_count(model.K, model.M, (2.0 * math.pi * PAPER_BAND_HZ) ** 2)


def run(args: argparse.Namespace) -> int:
    """Build, solve, analyse and write the outputs; return the exit code."""
    t0 = time.perf_counter()
    model = model_from_args(args)
    t_build = time.perf_counter() - t0
    label = model_label(args)
    LOGGER.info('model %s: %d DOF, built in %.2f s', label, model.n_dof, t_build)
    if args.fe_model_file:
        mass = model.meta['rigid_body_mass_kg']
        print(f'imported {args.fe_model_file} ({model.meta["format"]}): {model.n_dof} DOF '
              f'({model.meta["dropped_dofs"]} dropped), rigid-body mass x/y/z '
              f'{mass[0]:.6g}/{mass[1]:.6g}/{mass[2]:.6g} kg, stiffness groups '
              f'{", ".join(model.stiffness_groups)}, points {len(model.points)}')
    modes = _solve(model, args)
    t_solve = modes.stats['solve_time_s']
    table = analyse_causes(model, modes, neuber=not args.no_neuber, alpha=args.alpha,
                           rotation_length=args.rotation_length)
    t_causes = time.perf_counter() - t0 - t_build - t_solve
    out = args.out if args.out is not None else Path('out') / 'modes' / label
    out.mkdir(parents=True, exist_ok=True)
    table.to_csv(out / 'modes.csv')
    title = f'{label}, {model.n_dof} DOF'
    plot_energy_shares(table, out / 'energy_shares.png', n_modes=max(args.rows, 60),
                       title=f'strain energy per group, {title}')
    plot_mode_distribution(modes.frequencies, out / 'mode_distribution.png',
                           f_max=modes.f_max, title=f'mode distribution, {title}')
    print(table.format_table(args.rows))
    print(f'\n{label}: {model.n_dof} DOF, {modes.n_modes} modes '
          f'{modes.frequencies[0]:.2f}-{modes.frequencies[-1]:.2f} Hz')
    print(f'modes below {PAPER_BAND_HZ:g} Hz (Sturm count): {_band_count(model, modes)}')
    print(f'build {t_build:.2f} s, modal solve {t_solve:.2f} s '
          f'({modes.stats["windows"]} windows, {modes.stats["method"]}, '
          f'{modes.stats.get("window_processes", 1)} window process(es)), '
          f'cause analysis {t_causes:.2f} s')
    print(f'written: {out / "modes.csv"}, {out / "energy_shares.png"}, '
          f'{out / "mode_distribution.png"}')
    return 0


def main(argv: list[str] | None = None) -> int:
    """Entry point of the `modes` executable; returns the exit code."""
    args = _parser().parse_args(argv)
    if args.n_modes is not None and args.n_modes < 1:
        print(f'modes: error: --n-modes must be >= 1, got {args.n_modes}', file=sys.stderr)
        return 2
    if args.workers is not None and args.workers < 1:
        print(f'modes: error: --workers must be >= 1, got {args.workers}', file=sys.stderr)
        return 2
    configure_logging(args.verbose)
    return run_command('modes', run, args, errors=(ModalError,))


if __name__ == '__main__':
    sys.exit(main())
