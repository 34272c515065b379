"""
Exit codes of the testbed's nodes, of the scenario runner and of a composed run: one table.

docs/interface.md ("Stopping and exit codes") shows :data:`TABLE`; test/test_docs.py checks
that they agree. A process killed by a signal has no exit code of its own: the runner reports
such a plant with the shell's convention, 128 + the signal number (:func:`of_returncode`).
"""
from __future__ import annotations

import signal

FINISHED = 0
ERROR = 1
USAGE = 2
RECORDING_FAILED = 3
PLANT_STALLED = 4
TIMEOUT = 5
#: 128 + N: stopped by (or, for the runner's plant, killed by) signal N.
SIGNAL_BASE = 128

#: (code, meaning) of every end, in the order docs/interface.md lists them.
TABLE = (
    (FINISHED, 'finished: the run ended after its last step (every recorder closed its bag '
               'complete); a source or recorder stopped after the end of the run it served'),
    (ERROR, 'error, named on one line: bad parameters, an unstable plant, a silent force '
            'source, answers rejected until source_timeout, a second writer on a topic, a '
            'refused truncation check, or (runner) a node that failed'),
    (USAGE, 'wrong command line (argparse)'),
    (RECORDING_FAILED, 'a recording failed: a recorder closed its bag with steps missing, '
                       'conflicting duplicates or a foreign writer, or (runner) a recorder '
                       'was killed or stopped and did not close its bag complete; named'),
    (PLANT_STALLED, 'the plant stalled: no message from it for plant_stall_timeout s of wall '
                    'time during its run (a source or recorder noticed; the runner stops the '
                    'plant and names it)'),
    (TIMEOUT, 'runner: the plant did not end within --timeout (a node that failed first '
              'gives 1, named, even if the plant then had to be stopped)'),
    (SIGNAL_BASE, '128 + N: stopped by signal N (130 SIGINT, 143 SIGTERM, 129 SIGHUP) after a '
                  'clean stop; runner: also its plant killed by signal N (137 SIGKILL, '
                  '139 SIGSEGV)'),
)


def of_signal(signum: int) -> int:
    """Exit code of a stop (or death) by signal ``signum``: 128 + its number."""
    return SIGNAL_BASE + int(signum)


def of_returncode(code: int) -> int:
    """A child's return code as an exit code: a death by signal N (-N) becomes 128 + N."""
    return of_signal(-code) if code < 0 else code


def describe(code: int | None) -> str:
    """How a process ended, in words: 'exited with code 1', 'killed by SIGKILL', 'running'."""
    if code is None:
        return 'running'
    if code < 0:
        try:
            return f'killed by {signal.Signals(-code).name}'
        except ValueError:
            return f'killed by signal {-code}'
    return f'exited with code {code}'
