"""Options the ``statespace`` sub-commands share: reduction config, output folder, positions."""
from __future__ import annotations

import argparse
from pathlib import Path

#: Output folder of the ``statespace`` sub-commands.
DEFAULT_OUT = Path('out') / 'statespace'
#: Help of a ``--position`` that takes a list.
POSITIONS_HELP = 'comma-separated positions (default: positions in the config)'


def add_config_and_out(parser: argparse.ArgumentParser) -> None:
    """``--config`` (reduction.yaml) and ``--out`` (output folder) of a sub-command."""
    parser.add_argument('--config', default=None, help='reduction config (default: '
                        'config/reduction.yaml)')
    parser.add_argument('--out', type=Path, default=DEFAULT_OUT, help='output directory')
