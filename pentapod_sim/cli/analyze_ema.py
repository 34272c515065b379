"""
`analyze modes BAG`: natural frequencies, damping ratios and modal constants of a recorded run.

The FRF estimator follows the excitation stored in the bag
(:mod:`pentapod_sim.analysis.frf.from_run`); modes come from pLSCF, automatic pole selection and
LSFD (:mod:`pentapod_sim.analysis.ema.identify`). Writes ``<bag>_modes.csv``, ``<bag>_frf.csv``,
``<bag>_stability.png`` and ``<bag>_synthesis.png`` to ``--out``.
"""
from __future__ import annotations

import argparse
from pathlib import Path
import re

import numpy as np

from pentapod_sim.analysis.ema import plots as ema_plots
from pentapod_sim.analysis.ema.identify import DEFAULT_MAX_ORDER, identify_modes
from pentapod_sim.analysis.ema.poles import Tolerances
from pentapod_sim.analysis.ema.tables import mode_table, write_frf_csv, write_modes_csv
from pentapod_sim.analysis.frf.from_run import frfs_from_bag, RunFrfs
from pentapod_sim.cli import CommandParser
from pentapod_sim.errors import BagError


def add_parser(subs: argparse._SubParsersAction[CommandParser]) -> None:
    """Add the ``modes`` subcommand to the ``analyze`` subparsers."""
    sub = subs.add_parser('modes', help='modal identification (pLSCF + LSFD) of a recorded run')
    sub.add_argument('bag', help='bag folder or .mcap file (with its excitation record)')
    sub.add_argument('--band', nargs=2, type=float, metavar=('F1', 'F2'),
                     help='band to identify [Hz] (default: the excited band)')
    sub.add_argument('--outputs', nargs='+', metavar='TOPIC.FIELD',
                     help='responses (default: /pentapod/tcp_state.position.tcp_x/y/z)')
    sub.add_argument('--input', metavar='TOPIC.FIELD',
                     help='input force [N] (default: excitation force along its direction)')
    sub.add_argument('--source', help='exciter name, if the bag holds several excitations')
    sub.add_argument('--max-order', type=int, default=DEFAULT_MAX_ORDER,
                     help=f'highest model order of the stability diagram '
                          f'(default {DEFAULT_MAX_ORDER})')
    sub.add_argument('--min-stable', type=int, default=Tolerances.min_stable,
                     help='orders a pole must be stable over to count as a mode '
                          f'(default {Tolerances.min_stable})')
    sub.add_argument('--refine', action='store_true',
                     help='refine each pole by nonlinear least squares on the lines around it '
                          '(noisy FRFs with lines sparser than the half-power bands)')


def cmd_modes(args: argparse.Namespace) -> int:
    """Identify modes from a bag; print the table; write CSV and PNG files."""
    if args.max_order < 2 or args.min_stable < 1:
        raise BagError(f'--max-order {args.max_order} must be >= 2 and --min-stable '
                       f'{args.min_stable} >= 1')
    run = frfs_from_bag(args.bag, args.outputs, args.input, args.source)
    band = tuple(args.band) if args.band else run.band
    if len(set(run.units)) > 1:
        raise BagError(f'outputs of different units {sorted(set(run.units))}; identify them '
                       'one unit at a time (--outputs)')
    unit = run.units[0]
    tol = Tolerances(min_stable=args.min_stable)
    _warn_transient(run, band)
    try:
        model = identify_modes(run.freq, run.H, band=band, orders=range(1, args.max_order + 1),
                               sigma=run.sigma, frf_form=run.frf_form, tol=tol,
                               refine=args.refine)
    except ValueError as err:
        raise BagError(f'{args.bag}: {err}') from None
    print(f'{args.bag}: {run.kind} excitation, {run.estimator}, {len(run.freq)} lines; '
          f'band {model.band[0]:g} .. {model.band[1]:g} Hz, orders '
          f'{model.diagram[0].order}..{model.diagram[-1].order}, '
          f'{len(model.freq_hz)} modes ({run.frf_form} {unit})')
    for line in mode_table(model, run.labels, unit):
        print(line)
    out = Path(args.out)
    tag = re.sub(r'[^A-Za-z0-9]+', '_', Path(args.bag).name).strip('_')
    synth = model.synthesise(run.freq)
    written = [
        write_modes_csv(out / f'{tag}_modes.csv', model, run.labels, unit),
        write_frf_csv(out / f'{tag}_frf.csv', run.freq, run.H, synth, run.labels, unit,
                      run.sigma, run.transient),
        ema_plots.stability_plot(model, run.freq, run.H, out / f'{tag}_stability.png',
                                   title=f'{tag}: stability diagram ({run.estimator})'),
        ema_plots.synthesis_plot(model, run.freq, run.H, run.labels, unit,
                                   out / f'{tag}_synthesis.png',
                                   title=f'{tag}: measured and synthesised FRFs')]
    for path in written:
        print(f'wrote {path}')
    return 0


def _warn_transient(run: RunFrfs, band: tuple[float, float]) -> None:
    """
    Print a warning if the transient error dominates in the band (line estimators only).

    With noise alone, transient error / noise error per line is Rayleigh distributed with
    median 2 sqrt(ln 2) = 1.67; a decaying transient spreads over all lines and lifts the
    median above 2.5 (about 3 with 4 periods, more with more). Noise-free records compare with
    1e-3 |H| instead of a vanishing noise error. With 2 or 3 periods the ratio is about 2
    whatever the cause, so nothing is said.
    """
    if run.transient is None or run.sigma is None or run.n_averages < 4:
        return
    inside = (run.freq >= band[0]) & (run.freq <= band[1])
    if not np.any(inside):
        return
    floor = np.maximum(run.sigma[..., inside], 1e-3 * np.abs(run.H[..., inside]))
    ratio = float(np.median(run.transient[..., inside] / np.maximum(floor, 1e-300)))
    if ratio > 2.5:
        print(f'WARNING: transient error / noise error is {ratio:.2f} (median over the lines; '
              '1.67 for noise alone): the record has not settled; settle longer '
              '(settle_periods / settle_time)')
