"""
`analyze recover BAG`: rewrite a bag whose writer died into one every reader opens.

A recorder killed (SIGKILL, a crash) or stopped by a full disk leaves MCAP files without
summary and footer; rosbags and the mcap library's indexed reader refuse them. This command
writes the intact part as a valid bag (summary, footer, metadata.yaml) with
:func:`pentapod_sim.recording.recover.recover_bag` and prints what was kept and lost per topic
(messages, damaged byte ranges, steps missing). The original is never changed, except with
``--in-place``, which moves it into the bag's ``before-recovery/`` folder.
"""
from __future__ import annotations

import argparse
import sys
import time

from pentapod_sim.cli import CommandParser
from pentapod_sim.recording.recover import recover_bag, SUFFIX

#: Progress lines on stderr: the first after this long [s], then at most one per period.
PROGRESS_PERIOD = 1.0


def add_parser(subs: argparse._SubParsersAction[CommandParser]) -> None:
    """Add the ``recover`` subcommand to the ``analyze`` subparsers."""
    sub = subs.add_parser('recover', help='rewrite a bag cut by a crash into a valid bag, '
                                          'reporting what was lost')
    sub.add_argument('bag', help='bag folder or .mcap file')
    where = sub.add_mutually_exclusive_group()
    where.add_argument('--to', metavar='DIR', default=None,
                       help=f'folder of the recovered bag (default: BAG{SUFFIX} next to BAG)')
    where.add_argument('--in-place', action='store_true',
                       help='replace the bag by the recovered one; the originals go to '
                            'BAG/before-recovery/')
    sub.add_argument('--expected-steps', type=int, default=None, metavar='N',
                     help='steps the run had (default: from the run status in the bag)')
    sub.add_argument('--drop-unverified', action='store_true',
                     help='drop the complete records of a chunk cut by the end of the file '
                          '(kept by default; they cannot be CRC-checked)')
    sub.add_argument('--dry-run', action='store_true', help='report only; write nothing')


def cmd_recover(args: argparse.Namespace) -> int:
    """Recover one bag and print the report."""
    recovery = recover_bag(args.bag, args.to, in_place=args.in_place,
                           expected_steps=args.expected_steps,
                           keep_unverified=not args.drop_unverified, dry_run=args.dry_run,
                           progress=Progress())
    print(recovery.describe())
    return 0


class Progress:
    """Print ``analyze recover: <phase> <percent> %`` to stderr once a second, after a second."""

    def __init__(self) -> None:
        self.next = time.monotonic() + PROGRESS_PERIOD

    def __call__(self, phase: str, done: int, total: int) -> None:
        now = time.monotonic()
        if now >= self.next:
            self.next = now + PROGRESS_PERIOD
            print(f'analyze recover: {phase} {100 * done / max(total, 1):.0f} %',
                  file=sys.stderr, flush=True)
