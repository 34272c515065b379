"""
Stopping on signals the same way everywhere: nodes, the scenario runner and the study.

SIGINT (Ctrl-C), SIGTERM (``timeout``, supervisors, ``kill``) and SIGHUP (a closed terminal)
do not interrupt what a process is doing: the handler only records the signal, and the work
loops ask :func:`requested` between steps. So a plant ends its current step, writes its trace
and summary, a recorder finalises its bag and a runner stops its nodes and removes its temporary
files before the process exits with :func:`exit_code` (128 + signal number, the shell's
convention: 130 for SIGINT, 143 for SIGTERM, 129 for SIGHUP).

A second signal of the same kind while stopping changes nothing; stopping never waits without a
time limit, so a process cannot hang on a signal. Work abandoned on a stop (seconds of LAPACK in
a thread, :func:`unless_requested`) is waited for at the end (:func:`finish`) for at most
:data:`ABANDONED_WAIT`; a process whose work is still running then exits without Python's
finalisation, which would tear down the libraries under that thread (a composed run stopped
during its truncation check ended "killed by SIGSEGV").
"""
from __future__ import annotations

import ctypes
import logging
import os
from pathlib import Path
import signal
import sys
import threading
import time
from types import FrameType
from typing import Any, Callable, TypeVar

T = TypeVar('T')

#: The signals that request a clean stop.
STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)
_PR_SET_PDEATHSIG = 1

#: Wall time [s] the end of a process waits for work abandoned on a stop (:func:`finish`).
ABANDONED_WAIT = 0.5

_received: list[int] = []
#: threads of :func:`unless_requested` given up on a stop, perhaps still running
_abandoned: list[threading.Thread] = []


def _handler(signum: int, frame: FrameType | None) -> None:
    if not _received:
        _received.append(signum)


def install() -> None:
    """Record SIGINT, SIGTERM and SIGHUP instead of dying on them (main thread only)."""
    _received.clear()
    for sig in STOP_SIGNALS:
        signal.signal(sig, _handler)


def ignore_from_now() -> None:
    """
    Ignore stop signals from now on: for a process whose stop is complete, about to exit.

    Python's finalisation puts the default action back for every signal with a Python handler,
    so a second signal in the last milliseconds (the runner forwarding the Ctrl-C its process
    group already got) killed a node that had stopped cleanly: "killed by SIGINT". Ignored
    signals stay ignored through finalisation.
    """
    for sig in STOP_SIGNALS:
        signal.signal(sig, signal.SIG_IGN)


def requested() -> bool:
    """True once a stop signal arrived."""
    return bool(_received)


def deliver() -> None:
    """
    Let a stop signal that a thread other than Python's main one took reach :func:`requested`.

    The kernel gives a signal sent to a process to any of its threads, and the SIGINT or
    SIGTERM that comes with the SIGCONT of a stopped process to whichever thread runs first,
    often one of DDS's. CPython runs the handler in the main thread only once that thread next
    takes the GIL, so a main thread busy in Python code does not see the request (for as long
    as it does not wait; test/test_shutdown.py makes that happen). ``os.sched_yield`` releases
    and takes the GIL (about 0.2 us). Call this before an error that a stop request would
    override, such as a timeout that ran out while the process was stopped.
    """
    if not _received:
        os.sched_yield()


def signal_name() -> str:
    """Name of the signal that requested the stop ('' if none)."""
    return signal.Signals(_received[0]).name if _received else ''


def exit_code() -> int:
    """128 + number of the signal that requested the stop (0 if none)."""
    return 128 + _received[0] if _received else 0


def request(signum: int = signal.SIGTERM) -> None:
    """Request a stop from code, as if ``signum`` had arrived."""
    _handler(signum, None)


def die_with_parent() -> None:
    """
    Ask the kernel to send SIGTERM to this process when its parent dies (Linux).

    Meant as ``preexec_fn`` of :class:`subprocess.Popen`: a node started by the runner then
    stops cleanly even if the runner is killed with SIGKILL, and no orphan keeps answering a
    later run on the same ROS domain.
    """
    parent = os.getppid()
    try:
        libc = ctypes.CDLL('libc.so.6', use_errno=True)
        libc.prctl(_PR_SET_PDEATHSIG, signal.SIGTERM)
    except OSError:        # not Linux: nothing to ask for
        return
    if os.getppid() != parent:      # the parent died before the request took effect
        os.kill(os.getpid(), signal.SIGTERM)


def unless_requested(work: Callable[[], T], poll: float = 0.05, name: str = 'work') -> T | None:
    """
    ``work()``, or None as soon as a stop is requested while it runs.

    For seconds of numerics that release the GIL (LAPACK): ``work`` runs in a daemon thread
    and this (main) thread waits in slices of ``poll`` s, so the stop is noticed within one
    slice. An abandoned ``work`` goes on until it ends or the process exits; it must not touch
    what the caller goes on to use (:func:`finish` waits for it at the end; ``name`` names it
    there). An exception of ``work`` is raised here.
    """
    if requested():
        return None
    out: dict[str, Any] = {}

    def run() -> None:
        try:
            out['value'] = work()
        except BaseException as err:      # handed to the caller
            out['error'] = err
    worker = threading.Thread(target=run, name=name, daemon=True)
    worker.start()
    while worker.is_alive():
        worker.join(poll)
        if requested():
            _abandoned.append(worker)
            return None
    if 'error' in out:
        raise out['error']
    return out['value']


def abandoned_work() -> list[str]:
    """Names of the threads :func:`unless_requested` gave up on that are still running."""
    return [t.name for t in _abandoned if t.is_alive()]


def finish(code: int, wait: float = ABANDONED_WAIT) -> int:
    """
    ``code``, once the work abandoned on a stop has ended; or exit with ``code`` at once.

    The end of a process's main, after its nodes, files and ROS context are closed. Work given
    up by :func:`unless_requested` is waited for at most ``wait`` s. If some is still running,
    the process exits now with ``code`` (standard streams and logging flushed) instead of
    returning: Python's finalisation, and the libraries' exit handlers after it, would run
    while that thread is inside LAPACK, and the process died of SIGSEGV.
    """
    end = time.monotonic() + wait
    for thread in list(_abandoned):
        thread.join(max(0.0, end - time.monotonic()))
    if not abandoned_work():
        _abandoned.clear()
        return code
    print(f'exiting with {", ".join(abandoned_work())} still running (given up on the stop)',
          file=sys.stderr)
    logging.shutdown()
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):       # closed or gone: nothing left to flush
            pass
    os._exit(code)


def started_by_ros2_run(pid: int | None = None) -> bool:
    """True if process ``pid`` (default: the parent) is ``ros2 run`` (``ros2 run ...``)."""
    try:
        argv = Path(f'/proc/{os.getppid() if pid is None else pid}/cmdline').read_bytes()
    except OSError:
        return False
    words = [Path(a.decode(errors='replace')).name for a in argv.split(b'\0') if a]
    # ``ros2 run`` or ``python .../ros2 run`` (the entry point run by an interpreter)
    return any(w == 'ros2' and words[i + 1:i + 2] == ['run'] for i, w in enumerate(words[:3]))


# the parent as it was when this module was imported: a node that takes seconds to start may
# see its ``ros2 run`` die before :func:`follow_ros2_run` runs
_PARENT = os.getppid()
_PARENT_IS_ROS2_RUN = started_by_ros2_run(_PARENT)


def follow_ros2_run() -> None:
    """
    Stop with the ``ros2 run`` that started this node.

    ``ros2 run`` forwards Ctrl-C (SIGINT) to its node but not SIGTERM: a supervisor's SIGTERM
    ends ``ros2 run`` alone and left the node running with parent 1. A node whose parent is
    ``ros2 run`` therefore asks the kernel for SIGTERM when that parent dies, and sends it to
    itself if the parent died while the node was starting: it stops cleanly with exit code 143.
    """
    if not _PARENT_IS_ROS2_RUN:
        return
    try:
        libc = ctypes.CDLL('libc.so.6', use_errno=True)
        libc.prctl(_PR_SET_PDEATHSIG, signal.SIGTERM)
    except OSError:        # not Linux: nothing to ask for
        return
    if os.getppid() != _PARENT:
        os.kill(os.getpid(), signal.SIGTERM)
