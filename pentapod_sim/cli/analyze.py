r"""
`analyze`: inspect recorded bags, estimate FRFs, identify peaks, export PNG/CSV/UFF58.

Examples::

    analyze info BAG
    analyze frf BAG --input /pentapod/excitation.force.x \\
        --output /pentapod/tcp_state.position.tcp_x [--compare BAG2] [--out DIR]
    analyze peaks BAG --input ... --output ... [--compare BAG2]
    analyze time BAG /pentapod/tcp_state.position.tcp_x /pentapod/excitation.force.x
    analyze amplitudes BAG [--topic /pentapod/pma/state]
    analyze modes BAG [--band F1 F2] [--outputs TOPIC.FIELD ...]
    analyze recover BAG [--to DIR | --in-place]
    analyze lobes BAG[,BAG2] [BAG[,BAG2] ...] [--operation NAME] [--speeds MIN MAX]
    analyze chatter BAG [BAG ...] [--settle S]
"""
import argparse
import csv
import logging
from pathlib import Path
import re
import sys
import warnings

import numpy as np

from pentapod_sim.analysis.bag.file_content import BagDamageWarning, UnreadableBagError
from pentapod_sim.analysis.bag.reader import Bag, open_bag
from pentapod_sim.analysis.frf import plots
from pentapod_sim.analysis.frf.estimation import (
    amplitude_spectrum,
    EXCITATIONS,
    frf_from_series,
    FrfResult,
)
from pentapod_sim.analysis.frf.export import write_csv, write_uff58
from pentapod_sim.analysis.frf.peaks import find_resonances, peak_reductions, Resonance
from pentapod_sim.cli import CommandParser, run_command
from pentapod_sim.cli.analyze_chatter import add_parser as add_chatter_parser
from pentapod_sim.cli.analyze_chatter import cmd_chatter
from pentapod_sim.cli.analyze_ema import add_parser as add_modes_parser
from pentapod_sim.cli.analyze_ema import cmd_modes
from pentapod_sim.cli.analyze_lobes import add_parser as add_lobes_parser
from pentapod_sim.cli.analyze_lobes import cmd_lobes
from pentapod_sim.cli.analyze_recover import add_parser as add_recover_parser
from pentapod_sim.cli.analyze_recover import cmd_recover
from pentapod_sim.errors import BagError
from pentapod_sim.interface import PMA_STATE

LOGGER = logging.getLogger('analyze')
DEFAULT_OUT = Path('out') / 'analysis'


def _slug(text: str) -> str:
    return re.sub(r'[^A-Za-z0-9]+', '_', text).strip('_')


def cmd_info(args: argparse.Namespace) -> int:
    """Print topics, types, counts, duration, run information and damage of a bag."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter('ignore', BagDamageWarning)  # printed below instead
            bag = open_bag(args.bag)
    except UnreadableBagError as err:
        print(f'analyze: error: {err}', file=sys.stderr)
        return 1
    print(f'bag: {bag.path}{"  (TRUNCATED: readable part only)" if bag.truncated else ""}')
    for name, data in sorted(bag.topics.items()):
        times = bag.times_ns(name) if data.count else np.zeros(1, dtype=np.int64)
        span = (times.max() - times.min()) * 1e-9
        print(f'  {name:40s} {data.msg_type:34s} {data.count:9d} msgs  {span:10.3f} s')
        for field in bag.fields(name):
            print(f'      {name}.{field}')
    for key, value in sorted(bag.custom_data.items()):
        print(f'  run: {key} = {value}')
    print_damage(bag)
    if bag.damage and bag.message_count == 0:
        print(f'analyze: error: no intact message in {bag.path}', file=sys.stderr)
        return 1
    return 0


def print_damage(bag: Bag) -> None:
    """Print the damage report of a bag (nothing if it is intact)."""
    if not bag.damage:
        return
    known = [d.messages_lost for d in bag.damage if d.messages_lost is not None]
    unknown = any(d.messages_lost is None for d in bag.damage)
    total = f'{sum(known)}' if not unknown else (
        f'{sum(known)} + an unknown number of' if sum(known) else 'an unknown number of')
    print(f'DAMAGE: {len(bag.damage)} damaged or missing part(s), {total} messages lost; '
          'everything listed above was read intact (chunk CRCs checked)')
    for damage in bag.damage:
        print(f'  {damage.describe()}')


def _frfs(bag_path: str, args: argparse.Namespace) -> list[FrfResult]:
    topics = [spec.partition('.')[0] for spec in [args.input] + args.output]
    bag = open_bag(bag_path, topics)
    u = bag.series(args.input)
    return [frf_from_series(u, bag.series(out), args.excitation, args.nperseg)
            for out in args.output]


def _peak_rows(res: FrfResult, args: argparse.Namespace) -> list[Resonance]:
    return find_resonances(res, args.fmin, args.fmax, args.prominence_db)


def _write_peaks(path: Path, peaks: list[Resonance], unit: str) -> None:
    with open(path, 'w', newline='', encoding='utf-8') as handle:
        writer = csv.writer(handle)
        writer.writerow(['freq_Hz', f'magnitude_{unit}', 'damping_ratio', 'coherence'])
        writer.writerows([[p.freq, p.magnitude, p.damping_ratio, p.coherence] for p in peaks])


def uff_direction(spec: str) -> int:
    """
    UFF direction code of a ``TOPIC.FIELD``: 1-3 for x/y/z, 4-6 for torque/rotation, 0 else.

    Examples: ``/pentapod/excitation.force.x`` -> 1, ``/pentapod/tcp_state.position.tcp_z``
    -> 3, ``...torque.y`` -> 5.
    """
    parts = [p for p in spec.partition('.')[2].split('.')
             if p not in ('position', 'velocity', 'effort', 'wrench')]
    name = parts[-1] if parts else ''
    rotational = 'torque' in parts or name[-3:] in ('_rx', '_ry', '_rz')
    if name in ('x', 'y', 'z'):
        axis = name
    elif name[-2:] in ('_x', '_y', '_z', 'rx', 'ry', 'rz'):
        axis = name[-1]
    else:
        return 0
    return 'xyz'.index(axis) + (4 if rotational else 1)


def _analytic(args: argparse.Namespace) -> tuple[np.ndarray, np.ndarray, str] | None:
    """Read ``--analytic`` CSV (columns freq_Hz, re, im; header line) as (freq, H, label)."""
    if not args.analytic:
        return None
    table = np.loadtxt(args.analytic, delimiter=',', skiprows=1, ndmin=2)
    if table.shape[1] < 3:
        raise BagError(f'{args.analytic}: need columns freq_Hz, re, im; got {table.shape[1]}')
    return table[:, 0], table[:, 1] + 1j * table[:, 2], f'analytic ({Path(args.analytic).name})'


def cmd_frf(args: argparse.Namespace, plot: bool = True) -> int:
    """Estimate FRFs (and peaks, and reductions with --compare); write PNG, CSV, UFF58."""
    out_dir = Path(args.out)
    out_dir.mkdir(parents=True, exist_ok=True)
    results = _frfs(args.bag, args)
    compared = _frfs(args.compare, args) if args.compare else [None] * len(results)
    for out_spec, res, cmp in zip(args.output, results, compared):
        tag = _slug(f'{Path(args.bag).name}_{res.label}')
        peaks = _peak_rows(res, args)
        print(f'FRF {res.label} [{res.unit}], {res.n_averages} averages')
        for p in peaks:
            print(f'  peak {p.freq:9.3f} Hz  |H| {p.magnitude:.4g} {res.unit}  '
                  f'zeta {p.damping_ratio:.4%}  coherence {p.coherence:.3f}')
        _write_peaks(out_dir / f'{tag}_peaks.csv', peaks, res.unit)
        shown = [res]
        if cmp is not None:
            cmp.label = f'{Path(args.compare).name}: {cmp.label}'
            res.label = f'{Path(args.bag).name}: {res.label}'
            shown.append(cmp)
            for row in peak_reductions(peaks, _peak_rows(cmp, args)):
                print(f'  reduction {row.freq_ref:9.3f} Hz -> {row.freq_cmp:9.3f} Hz: '
                      f'{row.reduction_db:6.2f} dB  (zeta {row.damping_ref:.3%} -> '
                      f'{row.damping_cmp:.3%})')
        if plot:
            png = plots.frf_plot(shown, out_dir / f'{tag}.png', analytic=_analytic(args),
                                 resonances=peaks, fmin=args.fmin, fmax=args.fmax, title=tag)
            print(f'  wrote {png}')
        write_csv(out_dir / f'{tag}.csv', [res])
        write_uff58(out_dir / f'{tag}.uff', shown, response_dir=uff_direction(out_spec),
                    reference_dir=uff_direction(args.input))
    return 0


def cmd_time(args: argparse.Namespace) -> int:
    """Plot recorded series over time."""
    bag = open_bag(args.bag, [spec.partition('.')[0] for spec in args.specs])
    png = plots.time_plot([bag.series(s) for s in args.specs],
                          Path(args.out) / f'{_slug(Path(args.bag).name)}_time.png',
                          title=str(args.bag))
    print(f'wrote {png}')
    return 0


def cmd_amplitudes(args: argparse.Namespace) -> int:
    """Stroke [m] and force [N] amplitude spectra of every axis of a PMA state topic."""
    bag = open_bag(args.bag, [args.topic])
    amps: dict[str, np.ndarray] = {}
    units: dict[str, str] = {}
    freq: np.ndarray | None = None
    for spec in bag.fields(args.topic):
        field, _, name = spec.partition('.')
        if field == 'velocity':
            continue
        ser = bag.series(f'{args.topic}.{spec}')
        fs = 1e9 / np.median(np.diff(ser.time_ns))
        freq, amp = amplitude_spectrum(ser.values, fs, args.nperseg)
        label = f'{name} {"stroke" if field == "position" else "force"}'
        amps[label], units[label] = amp, ser.unit
    if not amps or freq is None:
        raise BagError(f'{args.topic} carries no position/effort fields')
    tag = _slug(f'{Path(args.bag).name}_{args.topic}')
    out_dir = Path(args.out)
    out_dir.mkdir(parents=True, exist_ok=True)
    png = plots.amplitude_plot(freq, amps, units, out_dir / f'{tag}_amplitudes.png', tag)
    with open(out_dir / f'{tag}_amplitudes.csv', 'w', newline='', encoding='utf-8') as handle:
        writer = csv.writer(handle)
        writer.writerow(['freq_Hz'] + [f'{k} [{units[k]}]' for k in amps])
        writer.writerows(np.column_stack([freq] + list(amps.values())).tolist())
    for label, amp in amps.items():
        k = int(np.argmax(amp[1:])) + 1
        print(f'  {label}: largest amplitude {amp[k]:.4g} {units[label]} at {freq[k]:.2f} Hz')
    print(f'wrote {png}')
    return 0


def _frf_arguments(sub: argparse.ArgumentParser) -> None:
    sub.add_argument('bag', help='bag folder or .mcap file')
    sub.add_argument('--input', required=True, help='TOPIC.FIELD of the excitation [N]')
    sub.add_argument('--output', required=True, action='append', help='TOPIC.FIELD (repeat)')
    sub.add_argument('--compare', help='second bag (e.g. with damping) for peak reductions')
    sub.add_argument('--excitation', choices=EXCITATIONS, default='random')
    sub.add_argument('--nperseg', type=int, default=None, help='segment length [samples]')
    sub.add_argument('--fmin', type=float, default=1.0, help='lowest frequency [Hz]')
    sub.add_argument('--fmax', type=float, default=None, help='highest frequency [Hz]')
    sub.add_argument('--prominence-db', type=float, default=6.0, help='peak prominence [dB]')
    sub.add_argument('--analytic', help='CSV freq_Hz,re,im of an analytic FRF to overlay')


def build_parser() -> argparse.ArgumentParser:
    """Return the command-line parser."""
    parser = CommandParser(prog='analyze', description=__doc__.split('\n')[1])
    parser.add_argument('--out', default=str(DEFAULT_OUT), help='output folder')
    parser.add_argument('-v', '--verbose', action='store_true')
    subs = parser.add_subparsers(dest='command', required=True)
    subs.add_parser('info', help='topics, counts, run info').add_argument('bag')
    _frf_arguments(subs.add_parser('frf', help='FRF estimation, plots, CSV, UFF58'))
    _frf_arguments(subs.add_parser('peaks', help='resonance table (no plot)'))
    time_parser = subs.add_parser('time', help='time plot of TOPIC.FIELD series')
    time_parser.add_argument('bag')
    time_parser.add_argument('specs', nargs='+')
    amp = subs.add_parser('amplitudes', help='actuator stroke/force amplitude spectra')
    amp.add_argument('bag')
    amp.add_argument('--topic', default=PMA_STATE)
    amp.add_argument('--nperseg', type=int, default=None)
    add_modes_parser(subs)
    add_recover_parser(subs)
    add_lobes_parser(subs)
    add_chatter_parser(subs)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run the `analyze` command line; return the exit code."""
    args = build_parser().parse_args(argv)
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING,
                        format='%(levelname)s %(name)s: %(message)s')
    commands = {'info': cmd_info, 'frf': cmd_frf, 'time': cmd_time,
                'amplitudes': cmd_amplitudes, 'modes': cmd_modes, 'recover': cmd_recover,
                'lobes': cmd_lobes, 'chatter': cmd_chatter,
                'peaks': lambda a: cmd_frf(a, plot=False)}
    return run_command('analyze', commands[args.command], args, errors=(ValueError,))


if __name__ == '__main__':
    sys.exit(main())
