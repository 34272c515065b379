"""
`analyze chatter BAG ...`: did a recorded cut chatter? The verdict from the cutting node's record.

A bag of a run with a cutting node (/pentapod/cutting/spec, /pentapod/cutting/state) and the
TCP state (/pentapod/tcp_state) is read step by step
(:func:`pentapod_sim.analysis.bag.cutting_record.cut_record`); after the entry transient
(``--settle``, default a quarter of the record) the TCP displacement is sampled once per tooth
period (the Poincare section), the growth rate of its spread and the share of the power off
the tooth-passing harmonics are measured and the verdict given: stable, chatter (with its
frequency) or tool left the cut (:func:`pentapod_sim.machining.chatter.detect_chatter`).
Writes ``chatter_<bag>.png`` (record, section, spectrum), ``_poincare.csv`` and
``_summary.csv`` to ``--out``. The exit code is 0 whatever the verdict.
"""
from __future__ import annotations

import argparse
from pathlib import Path
import re

from pentapod_sim.analysis.bag.cutting_record import chatter_of, cut_record, settle_time
from pentapod_sim.cli import CommandParser
from pentapod_sim.machining.chatter_plot import chatter_figure, write_chatter_csv


def add_parser(subs: argparse._SubParsersAction[CommandParser]) -> None:
    """Add the ``chatter`` subcommand to the ``analyze`` subparsers."""
    sub = subs.add_parser('chatter', help='chatter verdict of recorded cutting runs')
    sub.add_argument('bags', nargs='+', metavar='BAG', help='bag(s) of cutting runs')
    sub.add_argument('--settle', type=float, default=None, metavar='S',
                     help='time [s] from the start left out as the entry transient (default: '
                          'a quarter of the record)')


def cmd_chatter(args: argparse.Namespace) -> int:
    """Print the verdict of every bag and write its figure and tables."""
    for bag in args.bags:
        record = cut_record(bag)
        verdict = chatter_of(record, args.settle)
        cond, spec = record.spec.conditions, record.spec
        start = float(record.time[0]) + settle_time(record, args.settle)
        tag = re.sub(r'[^A-Za-z0-9]+', '_', Path(bag).resolve().name).strip('_')
        stem = Path(args.out) / f'chatter_{tag}'
        depth_mm = cond.axial_depth * 1e3
        title = (f'{Path(bag).name}: {spec.operation}, {cond.spindle_speed:g} rpm, '
                 f'{depth_mm:.4g} mm deep, {cond.cut.teeth} teeth: {verdict.verdict}')
        png = chatter_figure(record.time, record.displacement, verdict, start,
                             stem.with_name(stem.name + '.png'), title)
        extra: dict[str, float | str] = {
            'bag': str(bag), 'operation': spec.operation,
            'spindle_speed_rpm': cond.spindle_speed, 'axial_depth_m': cond.axial_depth,
            'teeth': cond.cut.teeth, 'judged_from_s': start}
        section, summary = write_chatter_csv(verdict, start, stem, extra)
        freq = (f' at {verdict.chatter_freq:.2f} Hz' if verdict.verdict != 'stable' else '')
        print(f'{bag}: {spec.operation}, {cond.spindle_speed:g} rpm, {depth_mm:.4g} mm deep, '
              f'{cond.cut.teeth} teeth (tooth passing {verdict.tooth_freq:.2f} Hz): '
              f'{verdict.verdict.upper()}{freq}; growth rate of the once-per-tooth spread '
              f'{verdict.growth_rate:+.4g} 1/s, {verdict.off_harmonic_share:.1%} of the power '
              f'off the tooth harmonics, {verdict.left_cut_share:.2%} of the engaged tooth '
              f'samples without chip; judged over {record.time[-1] - start:.4g} s from '
              f'{start:.4g} s')
        for path in (png, section, summary):
            print(f'wrote {path}')
    return 0
