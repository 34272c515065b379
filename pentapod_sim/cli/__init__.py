"""
Command-line entry points of the testbed (ROS-free).

The helpers below give every command the same model options (machine file, positions file,
position name, mesh size), the same logging setup and the same handling of a user's mistake
(:func:`run_command`: one line ``<prog>: error: <message>`` on stderr, exit code 1, no
traceback; argparse's usage errors keep exit code 2). Ctrl-C ends a command with one line
``<prog>: stopped by SIGINT`` and exit code 130, as the nodes do (:mod:`pentapod_sim.shutdown`).
Every command parses its options with :class:`CommandParser`, which refuses abbreviated options.
"""
from __future__ import annotations

import argparse
import logging
import signal
import sys
from typing import Any, Callable, Iterable, overload, TYPE_CHECKING, TypeVar

from pentapod_sim.errors import (
    BagError,
    ConfigError,
    ModelFileError,
    PortError,
    UnreachablePoseError,
)

if TYPE_CHECKING:       # built only by the commands that need a model
    from pentapod_sim.fe.model import FEModel

#: Errors that come from the user's input (files, options); shown without a traceback.
USER_ERRORS = (ConfigError, UnreachablePoseError, PortError, ModelFileError, BagError, OSError)
#: Exit code of a command stopped by a user error (argparse uses 2 for a bad command line).
EXIT_USER_ERROR = 1
#: Exit code of a command stopped by Ctrl-C (128 + SIGINT, the shell's convention).
EXIT_SIGINT = 128 + signal.SIGINT
_N = TypeVar('_N')


class CommandParser(argparse.ArgumentParser):
    """
    An ``ArgumentParser`` that refuses abbreviated options, also in its sub-commands.

    argparse takes a unique prefix of a long option for the option (``--out`` for
    ``--output``), so an option misplaced after a sub-command silently became another one; with
    ``allow_abbrev=False`` (the default here; sub-command parsers are of this class too) only
    whole option names count. An option of the main command given after the sub-command is
    refused with a line saying where it belongs.
    """

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        kwargs.setdefault('allow_abbrev', False)
        super().__init__(*args, **kwargs)

    # the overloads of argparse's own (typeshed): the namespace given is the one returned
    @overload
    def parse_args(self, args: Iterable[str] | None = None,
                   namespace: None = None) -> argparse.Namespace: ...
    @overload
    def parse_args(self, args: Iterable[str] | None, namespace: _N) -> _N: ...
    @overload
    def parse_args(self, *, namespace: _N) -> _N: ...

    def parse_args(self, args: Iterable[str] | None = None, namespace: object = None) -> object:
        """Parse like argparse; name a main-command option found after the sub-command."""
        parsed, extra = self.parse_known_args(args, namespace)
        if extra:
            own = [a for a in extra if a.split('=')[0] in self._option_string_actions]
            if own:
                command = getattr(parsed, 'command', None) or 'the sub-command'
                self.error(f'{own[0]} is an option of {self.prog} itself: give it before '
                           f'{command} ({self.prog} {own[0].split("=")[0]} ... {command} ...)')
            self.error(f'unrecognized arguments: {" ".join(extra)}')
        return parsed


def run_command(prog: str, func: Callable[[argparse.Namespace], int],
                args: argparse.Namespace, errors: tuple[type[BaseException], ...] = ()) -> int:
    """
    Run ``func(args)``; a user error is printed once, on one line, and gives exit code 1.

    Parameters
    ----------
    prog : str
        Command name that starts the error line.
    func : callable
        The command; returns its exit code.
    args : argparse.Namespace
        Parsed options.
    errors : tuple of exception types
        Further errors to treat as the user's (besides :data:`USER_ERRORS`).
    """
    try:
        return func(args)
    except USER_ERRORS + tuple(errors) as err:
        text = ' '.join(str(err).split('\n')) or type(err).__name__
        print(f'{prog}: error: {text}', file=sys.stderr, flush=True)
        return EXIT_USER_ERROR
    except KeyboardInterrupt:
        print(f'{prog}: stopped by SIGINT', file=sys.stderr, flush=True)
        return EXIT_SIGINT


def add_model_arguments(parser: argparse.ArgumentParser, position: str = 'P1') -> None:
    """
    Add the shared options that select and mesh the FE model.

    ``--machine PATH``, ``--positions PATH``, ``--position NAME``, and either
    ``--element-size H`` [m] or ``--refine N`` (element size of the machine file divided by N);
    or ``--fe-model FILE.yaml``, an FE model of another code (docs/own_machine.md).
    """
    group = parser.add_argument_group('model')
    group.add_argument('--fe-model', dest='fe_model_file', default=None, metavar='FILE.yaml',
                       help='imported FE model description (matrix files of another FE code) '
                       'instead of the machine file')
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


def model_from_args(args: argparse.Namespace) -> FEModel:
    """
    Build the FE model the shared options describe.

    Returns
    -------
    FEModel
        The model at ``args.position``.

    Raises
    ------
    ConfigError
        If a file or value is invalid, the position name is unknown or the position cannot
        be reached (the message names the positions file).
    """
    if getattr(args, 'fe_model_file', None):
        from pentapod_sim.fe.imported.build import load_fe_model
        return load_fe_model(args.fe_model_file)
    from pentapod_sim.fe import machine_data  # heavy imports only when a model is built
    from pentapod_sim.modes import frame_reduction
    from pentapod_sim.schema import closest

    machine = machine_data.load_machine(args.machine)
    path = machine_data.positions_path(args.positions)
    positions = machine_data.load_positions(path)
    if args.position not in positions:
        near = closest(args.position, positions)
        raise ConfigError(f'{path}: no position {args.position!r}'
                          f'{f"; did you mean {near!r}?" if near else ""} (known: '
                          f'{", ".join(positions)})')
    element_size = args.element_size
    if args.refine is not None:
        if not args.refine > 0:
            raise ConfigError(f'--refine must be > 0, got {args.refine}')
        element_size = machine.mesh.element_size / args.refine
    try:
        return frame_reduction.build_model(machine, positions[args.position],
                                           element_size=element_size)
    except UnreachablePoseError as err:
        raise ConfigError(f'{path}: position {args.position!r} cannot be reached with '
                          f'{machine.source}: {err}') from None


def model_label(args: argparse.Namespace) -> str:
    """Name of the model in outputs: the imported description's stem, else the position."""
    from pathlib import Path
    if getattr(args, 'fe_model_file', None):
        return Path(args.fe_model_file).stem
    return args.position


def configure_logging(verbose: bool = False) -> None:
    """Log INFO lines (progress) to stderr, DEBUG with ``verbose``."""
    logging.basicConfig(level=logging.DEBUG if verbose else logging.INFO,
                        format='%(asctime)s %(name)s: %(message)s', datefmt='%H:%M:%S')
