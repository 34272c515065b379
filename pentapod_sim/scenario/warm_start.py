"""
Composed runs started warm: forked from a process that imported the node modules once.

A composed run in a fresh process (``python -m pentapod_sim.nodes.composed``) spends about
3 s on imports (numpy, scipy, python-control with matplotlib, rclpy) before its first step;
the study starts 28 such runs. A :class:`WarmStarter` keeps a :mod:`multiprocessing`
forkserver that imported the modules of every node kind (:data:`PRELOAD`) when it started;
each run is a child forked from it. The child takes the run's environment (ROS domain, log
folder, ...) before rclpy starts, writes its output to the run's log file and then runs the
module as ``python -m`` would (:func:`runpy.run_module`): the same entry point as the fresh
process, so the same nodes, stop signals and exit codes, and bit for bit the same traces and
bags (``test/test_warm_start.py``). bench/RESULTS.md, ``study: composed run started warm``,
has the time it saves.

Each run gets SIGTERM when the process that started it ends, even by SIGKILL, and stops
cleanly (no orphan keeps answering on a domain whose lease died with that process); the
forkserver ends once that process and its runs have. As with every multiprocessing start
method but fork, a script that starts warm runs must keep its main code under
``if __name__ == '__main__':`` (the runs import the script's module).
"""
from __future__ import annotations

import multiprocessing
import os
from pathlib import Path
import runpy
import select
import signal
import subprocess
import sys
import threading

from pentapod_sim import registry, shutdown

#: Modules the forkserver imports once: the composition and every node kind's module.
PRELOAD = ['pentapod_sim.nodes.composed'] + sorted({kind.module for kind in registry.NODES})


def _die_with(pid: int) -> None:
    """
    SIGTERM to this process once process ``pid`` ends (Linux ``pidfd``; elsewhere nothing).

    A forked run's parent is the forkserver, which lives as long as any of its runs does
    (each holds its "alive" pipe), so the kernel's parent-death signal never comes when the
    process that started the run is killed; this watches that process instead.
    """
    try:
        fd = os.pidfd_open(pid)
    except ProcessLookupError:            # already gone
        os.kill(os.getpid(), signal.SIGTERM)
        return
    except (AttributeError, OSError):     # no pidfd here
        return

    def watch() -> None:
        select.select([fd], [], [])
        os.kill(os.getpid(), signal.SIGTERM)
    threading.Thread(target=watch, name='die_with_starter', daemon=True).start()


def _child(module: str, args: list[str], env: dict[str, str], log: str | None,
           starter: int) -> None:
    """The forked run: its environment and log, then ``python -m module args``."""
    shutdown.die_with_parent()            # the parent is the forkserver
    _die_with(starter)                    # and the process that started the run
    os.environ.clear()                    # before rclpy reads ROS_DOMAIN_ID, ROS_LOG_DIR, ...
    os.environ.update(env)
    if log is not None:
        fd = os.open(log, os.O_WRONLY | os.O_APPEND)
        os.dup2(fd, 1)
        os.dup2(fd, 2)
        os.close(fd)
    sys.argv = [module] + args
    sys.modules.pop(module, None)   # run as __main__ (runpy warns of a preloaded copy); its
    try:                            # imports stay loaded
        runpy.run_module(module, run_name='__main__', alter_sys=True)
    finally:
        sys.stdout.flush()
        sys.stderr.flush()


class WarmRun:
    """A run forked by a :class:`WarmStarter`, used like :class:`subprocess.Popen`."""

    def __init__(self, process, args: list[str]):
        self._process = process
        self.args = args
        self.pid = process.pid

    def poll(self) -> int | None:
        """Exit code (negative: killed by that signal), None while running."""
        return self._process.exitcode

    def wait(self, timeout: float | None = None) -> int:
        """Exit code; :class:`subprocess.TimeoutExpired` if still running after ``timeout``."""
        self._process.join(timeout)
        if self._process.exitcode is None:
            raise subprocess.TimeoutExpired(self.args, timeout or 0.0)
        return self._process.exitcode

    def send_signal(self, sig: int) -> None:
        if self._process.exitcode is None:
            os.kill(self.pid, sig)

    def kill(self) -> None:
        self._process.kill()


class WarmStarter:
    """
    Start composed runs as children of a forkserver that preloaded :data:`PRELOAD`.

    The forkserver starts with the first run (with this process's environment and
    ``sys.path``); its imports then take their time once.
    """

    _lock = threading.Lock()

    def __init__(self) -> None:
        self._context = multiprocessing.get_context('forkserver')

    def start(self, command: list[str], env: dict[str, str], log: Path | None = None
              ) -> WarmRun:
        """
        Fork a run of ``python -m MODULE ARGS...``; ``command`` is ``['-m', MODULE, ARGS...]``.

        ``env`` replaces the run's environment; with ``log`` its stdout and stderr go to that
        file (created or emptied), else to this process's.
        """
        if command[:1] != ['-m'] or len(command) < 2:
            raise ValueError(f'not a "-m MODULE ..." command: {command!r}')
        if log is not None:
            Path(log).write_bytes(b'')        # there (and empty) once this returns
        with self._lock:      # the preload list is the context's, set before its server runs
            self._context.set_forkserver_preload(PRELOAD)
            process = self._context.Process(
                target=_child, name=command[1],
                args=(command[1], list(command[2:]), dict(env), None if log is None else str(log),
                      os.getpid()))
            process.start()
        return WarmRun(process, list(command))
