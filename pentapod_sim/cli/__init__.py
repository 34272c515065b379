"""
Command-line entry points of the testbed (ROS-free).

The helpers below give every command the same model options (machine file, positions file,
position name, mesh size) and the same logging setup.
"""
from __future__ import annotations

import argparse
import logging


def add_model_arguments(parser: argparse.ArgumentParser, position: str = 'P1') -> None:
    """
    Add the shared options that select and mesh the FE model.

    ``--machine PATH``, ``--positions PATH``, ``--position NAME``, and either
    ``--element-size H`` [m] or ``--refine N`` (element size of the machine file divided by N).
    """
    group = parser.add_argument_group('model')
    group.add_argument('--machine', default=None,
                       help='machine parameter file (default: config/machine.yaml)')
    group.add_argument('--positions', default=None,
                       help='named positions file (default: config/positions.yaml)')
    group.add_argument('--position', default=position,
                       help=f'named machine position (default: {position})')
    mesh = group.add_mutually_exclusive_group()
    mesh.add_argument('--element-size', type=float, default=None, metavar='H',
                      help='beam element length [m] (default: from the machine file)')
    mesh.add_argument('--refine', type=float, default=None, metavar='N',
                      help='divide the default element length by N (about 260: paper scale)')


def model_from_args(args: argparse.Namespace):
    """
    Build the FE model the shared options describe.

    Returns
    -------
    FEModel
        The model at ``args.position``.

    Raises
    ------
    ConfigError
        If a file or value is invalid, or the position name is unknown.
    """
    from pentapod_sim.errors import ConfigError
    from pentapod_sim.fe import (
        assembly,
        params,  # heavy imports only when a model is built
    )

    machine = params.load_machine(args.machine)
    positions = params.load_positions(args.positions)
    if args.position not in positions:
        raise ConfigError(f'unknown position {args.position!r}; known: '
                          f'{", ".join(sorted(positions))}')
    element_size = args.element_size
    if args.refine is not None:
        if not args.refine > 0:
            raise ConfigError(f'--refine must be > 0, got {args.refine}')
        element_size = machine.mesh.element_size / args.refine
    return assembly.build_model(machine, positions[args.position], element_size=element_size)


def configure_logging(verbose: bool = False) -> None:
    """Log INFO lines (progress) to stderr, DEBUG with ``verbose``."""
    logging.basicConfig(level=logging.DEBUG if verbose else logging.INFO,
                        format='%(asctime)s %(name)s: %(message)s', datefmt='%H:%M:%S')
