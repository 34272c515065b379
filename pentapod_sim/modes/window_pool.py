"""
Where the spectrum windows are solved: in this process, or in window processes side by side.

A window is one factorisation of ``K - sigma M`` (its Sturm count included) and one
eigensolver run for the ``k`` modes nearest ``sigma``, mass-normalised with their residuals.
The windows of one slicing run are independent once their shifts are known, and one
window keeps one core busy (SuperLU's solves and ARPACK's loop are single-threaded; BLAS adds
little at one vector per solve), so on a machine with several cores the slicing runs ahead and
solves the next windows in forked processes at the same time. Forking shares ``K`` and ``M``
with the window processes without copying them; each process keeps its last factorisation
for a repeated solve at the same shift.

Measured on 2 cores (docs/modes.md, 'Windows side by side'): two windows of the 788,568-DOF
model took 25.7 s side by side against 45.8 s one after the other.
"""
from __future__ import annotations

from concurrent.futures import Future, ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass
import multiprocessing
import os
import signal
import threading
import time
from typing import Any

import numpy as np
import numpy.typing as npt
import scipy.sparse as sp

from pentapod_sim import shutdown
from pentapod_sim.errors import ModalError
from pentapod_sim.modes.sturm import factor_at, ShiftedFactor
from pentapod_sim.modes.windows import mass_normalise, window_eigs

#: Below this many DOF the windows stay in this process by default: such models (the study's
#: have about 3,000 DOF) solve in seconds either way, often next to other work.
PARALLEL_MIN_DOF = 100_000

#: At most this many window processes by default (each holds one factorisation, 1-2 GB at
#: 800k DOF; and the further the slicing runs ahead, the less its shift guesses fit).
MAX_DEFAULT_WORKERS = 4


@dataclass
class Window:
    """
    One solved window.

    Attributes
    ----------
    sigma : float
        Shift [rad^2/s^2].
    count : int
        Sturm count at the shift: eigenvalues below ``sigma``.
    k : int
        Modes asked for (0: the factorisation was only counted).
    lam : (k,) ndarray
        Eigenvalues [rad^2/s^2], ascending.
    phi : (n, k) ndarray
        Mass-normalised mode shapes (columns).
    residual : (k,) ndarray
        ``||K phi - lam M phi|| / ||K phi||`` per mode.
    factor_seconds, solve_seconds : float
        Busy time of the factorisation (0 when it was reused) and of the eigensolver [s].
    """

    sigma: float
    count: int
    k: int
    lam: npt.NDArray[np.float64]
    phi: npt.NDArray[np.float64]
    residual: npt.NDArray[np.float64]
    factor_seconds: float
    solve_seconds: float


class _Abandoned(Exception):
    """A window no longer needed stopped at its next solve."""


class _Solver:
    """Solves windows in whichever process holds it; keeps the last factorisation."""

    def __init__(self, K: sp.spmatrix, M: sp.spmatrix, method: str, tol: float,
                 stop: Any = None, backend: str = 'auto') -> None:
        self.K, self.M, self.method, self.tol, self.stop = K, M, method, tol, stop
        self.backend = backend
        self._last: ShiftedFactor | None = None

    def _checkpoint(self) -> None:
        if self.stop is not None and self.stop.is_set():
            raise _Abandoned

    def __call__(self, sigma: float, k: int) -> Window:
        reused = self._last is not None and self._last.sigma == sigma
        if not reused:
            self._last = None   # released first: its PARDISO analysis serves the next shift
        factor = self._last if reused else factor_at(self.K, self.M, sigma, self.backend)
        assert factor is not None
        self._last = factor
        n = self.K.shape[0]
        if k == 0:
            empty = np.empty(0)
            return Window(factor.sigma, factor.count, 0, empty, np.empty((n, 0)), empty,
                          factor.seconds, 0.0)
        t0 = time.perf_counter()
        lam, phi = window_eigs(self.K, self.M, factor, k, self.method, self.tol,
                               None if self.stop is None else self._checkpoint)
        residual = mass_normalise(self.K, self.M, lam, phi)
        return Window(factor.sigma, factor.count, k, lam, phi, residual,
                      0.0 if reused else factor.seconds, time.perf_counter() - t0)


#: The window solver of a window process (set once when the process starts).
_PROCESS_SOLVER: _Solver | None = None


def _start_process(K: sp.spmatrix, M: sp.spmatrix, method: str, tol: float,
                   stop: Any, backend: str) -> None:
    """
    Set up a window process: its solver, and signals that end it.

    A fork inherits the caller's signal handlers, which may only record a stop request
    (:mod:`pentapod_sim.shutdown`); a window process has nothing to save, so SIGTERM and
    SIGHUP end it, and it is sent SIGTERM when the caller dies, even by SIGKILL, instead of
    solving on as an orphan. Ctrl-C reaches the whole process group: a window process ignores
    it and leaves the decision to the caller, which stops its windows when it stops.
    """
    global _PROCESS_SOLVER
    for sig in (signal.SIGTERM, signal.SIGHUP):
        signal.signal(sig, signal.SIG_DFL)
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    shutdown.die_with_parent()
    _PROCESS_SOLVER = _Solver(K, M, method, tol, stop, backend)


def _solve_in_process(sigma: float, k: int) -> Window | None:
    assert _PROCESS_SOLVER is not None
    try:
        return _PROCESS_SOLVER(sigma, k)
    except _Abandoned:
        return None


def default_workers(n_dof: int) -> int:
    """
    Window processes used unless told: one per core this process may run on.

    At most :data:`MAX_DEFAULT_WORKERS`; and 1 (no window processes) for problems under
    :data:`PARALLEL_MIN_DOF` DOF, inside daemonic processes (a process pool's workers may not
    start processes of their own) and while other Python threads run (a fork copies only the
    calling thread, and a lock another thread holds would stay locked in the copy).
    """
    if (n_dof < PARALLEL_MIN_DOF or multiprocessing.current_process().daemon
            or threading.active_count() > 1):
        return 1
    return max(1, min(len(os.sched_getaffinity(0)), MAX_DEFAULT_WORKERS))


class WindowPool:
    """
    Solves windows: ``submit(sigma, k)`` returns a future of a :class:`Window`.

    With ``workers=1`` every window is solved in this process when it is submitted, so the
    slicing is the sequential one. With more, windows go to as many forked processes; use the
    pool as a context manager, which stops and ends them on leaving.
    """

    def __init__(self, K: sp.spmatrix, M: sp.spmatrix, method: str, tol: float,
                 workers: int, backend: str = 'auto') -> None:
        if workers < 1:
            raise ValueError(f'workers={workers} must be at least 1')
        self.K, self.M, self.workers = K, M, workers
        self._inline: _Solver | None = None
        self._executor: ProcessPoolExecutor | None = None
        if workers == 1:
            self._inline = _Solver(K, M, method, tol, backend=backend)
            return
        # fork: the processes share K and M with this one instead of receiving copies
        ctx = multiprocessing.get_context('fork')
        self._stop = ctx.Event()
        self._executor = ProcessPoolExecutor(workers, mp_context=ctx,
                                             initializer=_start_process,
                                             initargs=(K, M, method, tol, self._stop, backend))

    def submit(self, sigma: float, k: int) -> Future[Window | None]:
        """Solve the window at shift ``sigma`` [rad^2/s^2] for ``k`` modes (0: count only)."""
        if self._executor is None:
            assert self._inline is not None
            done: Future[Window | None] = Future()
            done.set_result(self._inline(sigma, k))
            return done
        return self._executor.submit(_solve_in_process, float(sigma), int(k))

    def result(self, future: Future[Window | None]) -> Window:
        """The window of ``future``, waiting for it; a lost window process is a ModalError."""
        try:
            window = future.result()
        except BrokenProcessPool:
            raise ModalError('a window process ended without a result (killed, or out of '
                             'memory?); workers=1 solves the windows in this process') from None
        if window is None:
            raise ModalError('a window was abandoned before it was needed')
        return window

    def __enter__(self) -> 'WindowPool':
        return self

    def __exit__(self, *exc: object) -> None:
        if self._executor is not None:
            self._stop.set()   # windows solved ahead and not needed stop at their next solve
            self._executor.shutdown(wait=True, cancel_futures=True)
