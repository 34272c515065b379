"""
`analyze lobes BAG ...`: stability lobes of a milling operation from measured TCP FRFs.

Each positional argument is one scenario (one curve of the diagram): a bag excited along one
direction of the machine x-y plane, or two bags joined by a comma, excited along two
independent directions (together the full 2x2 TCP FRF). The FRFs follow the excitation each
bag stores (:func:`pentapod_sim.analysis.frf.from_run.frfs_from_bag`, responses
``/pentapod/tcp_state.position.tcp_x`` and ``tcp_y``). With one bag the structure is taken
as flexible along the excitation direction only (cross terms and the other direction rigid).
The operation (material, tool, immersion, feed direction) comes from config/machining.yaml.
Writes ``lobes_<tag>.png``, ``.csv`` and ``_summary.csv`` to ``--out``.
"""
from __future__ import annotations

import argparse
from pathlib import Path
import re

import numpy as np

from pentapod_sim.analysis.bag.excitation_record import excitation_of
from pentapod_sim.analysis.frf.from_run import frfs_from_bag
from pentapod_sim.cli import CommandParser
from pentapod_sim.errors import BagError, ConfigError
from pentapod_sim.interface import TCP_STATE
from pentapod_sim.machining.lobe_plot import lobe_diagram
from pentapod_sim.machining.lobes import milling_limit
from pentapod_sim.machining.materials import load_machining
from pentapod_sim.machining.tcp_frf import TcpFrf

OUTPUTS = [f'{TCP_STATE}.position.tcp_x', f'{TCP_STATE}.position.tcp_y']
DEFAULT_OPERATION = 'aluminium_half_down'


def add_parser(subs: argparse._SubParsersAction[CommandParser]) -> None:
    """Add the ``lobes`` subcommand to the ``analyze`` subparsers."""
    sub = subs.add_parser('lobes', help='stability lobes of a milling operation from TCP FRFs')
    sub.add_argument('scenarios', nargs='+', metavar='BAG[,BAG2]',
                     help='one scenario: a bag, or two bags excited along two directions')
    sub.add_argument('--operation', default=DEFAULT_OPERATION,
                     help=f'operation of config/machining.yaml (default {DEFAULT_OPERATION})')
    sub.add_argument('--machining', default=None,
                     help='machining table (default: config/machining.yaml)')
    sub.add_argument('--speeds', nargs=2, type=float, metavar=('MIN', 'MAX'),
                     help='spindle speed range [rpm] (default: from the table)')
    sub.add_argument('--n-speeds', type=int, default=2000, help='speeds of the diagram')
    sub.add_argument('--source', help='exciter name, if a bag holds several excitations')


def _direction(bag: str, source: str | None) -> np.ndarray:
    found = excitation_of(bag, source)
    if found is None:
        raise BagError(f'{bag} holds no excitation record; lobes need the excitation direction')
    d = np.asarray(found[0].direction, dtype=float)
    d = d / np.linalg.norm(d)
    if np.linalg.norm(d[:2]) < 0.99:
        raise BagError(f'{bag}: excitation direction {d.round(3).tolist()} is not in the '
                       'machine x-y plane (the cutting plane)')
    return d[:2] / np.linalg.norm(d[:2])


def scenario_frf(spec: str, source: str | None = None) -> TcpFrf:
    """
    The TCP FRF matrix of one scenario argument ``BAG`` or ``BAG1,BAG2`` (module docstring).

    Raises
    ------
    BagError
        If a bag lacks the excitation record or the TCP outputs, is excited off the x-y
        plane, has outputs not in m, or two bags have different lines or parallel directions.
    """
    bags = [b for b in spec.split(',') if b]
    if not 1 <= len(bags) <= 2:
        raise BagError(f'{spec!r}: give one bag or two joined by a comma')
    runs = [frfs_from_bag(b, OUTPUTS, None, source) for b in bags]
    for bag, run in zip(bags, runs):
        if run.units != ['m/N', 'm/N']:
            raise BagError(f'{bag}: TCP FRFs in {run.units}, expected m/N')
    dirs = np.array([_direction(b, source) for b in bags])            # (n_bags, 2)
    label = '+'.join(Path(b).name for b in bags)
    cols = [run.H[:, 0, :] for run in runs]                             # each (2, F)
    if len(bags) == 1:
        return TcpFrf.single_direction(runs[0].freq, dirs[0] @ cols[0], dirs[0], label)
    if runs[0].freq.shape != runs[1].freq.shape or not np.allclose(runs[0].freq, runs[1].freq):
        raise BagError(f'{bags[0]} and {bags[1]} have different frequency lines; excite both '
                       'with the same signal settings')
    if abs(np.linalg.det(dirs)) < 0.1:
        raise BagError(f'{bags[0]} and {bags[1]} are excited along (nearly) the same '
                       f'direction {dirs.round(3).tolist()}')
    measured = np.stack(cols, axis=1)                                   # (2 out, 2 dirs, F)
    matrix = np.einsum('idf,dj->ijf', measured, np.linalg.inv(dirs.T))
    return TcpFrf(runs[0].freq, matrix, label)


def cmd_lobes(args: argparse.Namespace) -> int:
    """Lobe diagram of one operation for every scenario; print and write the figures."""
    table = load_machining(args.machining)
    cut = table.milling_cut(args.operation)
    low, high = args.speeds if args.speeds else table.spindle_speeds
    if not 0 < low < high or args.n_speeds < 2:
        raise ConfigError(f'--speeds {low} {high} must satisfy 0 < MIN < MAX and --n-speeds '
                       f'{args.n_speeds} >= 2')
    frfs = [scenario_frf(s, args.source) for s in args.scenarios]
    limits = [milling_limit(frf, cut) for frf in frfs]
    tag = re.sub(r'[^A-Za-z0-9]+', '_', f'{args.operation}_{frfs[0].label}').strip('_')
    title = f'{args.operation}: {table.operation(args.operation).description}'
    diagram = lobe_diagram(limits, np.linspace(low, high, args.n_speeds),
                           Path(args.out) / f'lobes_{tag}', title=title)
    print(f'{args.operation}: {cut.teeth} teeth, K_t {cut.tangential_coefficient:.4g} N/m^2, '
          f'K_r {cut.radial_ratio:.3g}, engaged {np.degrees(cut.entry_angle):.1f}..'
          f'{np.degrees(cut.exit_angle):.1f} deg, zero-order solution')
    for frf, summ in zip(frfs, diagram.summaries):
        print(f'  {summ.label}: minimum stable depth {summ.min_depth * 1e3:.4g} mm '
              f'(chatter at {summ.min_depth_freq:.2f} Hz); in {low:g}..{high:g} rpm lowest '
              f'{summ.lowest_in_range * 1e3:.4g} mm at {summ.lowest_speed:.0f} rpm, best '
              f'pocket {summ.pocket_depth * 1e3:.4g} mm at {summ.pocket_speed:.0f} rpm')
        if not summ.resolved:
            step = float(np.median(np.diff(frf.freq)))
            print(f'  WARNING: {summ.label}: the FRF lines ({step:.3g} Hz apart) do not '
                  f'resolve the resonance at {summ.min_depth_freq:.2f} Hz; the minimum stable '
                  'depth may be lower (record longer or with a finer line spacing)')
    for path in (diagram.png, diagram.csv, diagram.summary_csv):
        print(f'wrote {path}')
    return 0
