"""
The study's pieces side by side: a graph of pieces run on a few threads, in priority order.

A :class:`Piece` is one model build, one scenario's analytic FRFs, one testbed run, ...; it
names the pieces it needs (``after``) and a ``priority`` (lower first among the pieces that
are ready). :func:`run_pieces` keeps ``workers`` pieces running on a
:class:`concurrent.futures.ThreadPoolExecutor` and hands each result to the piece's ``done``
in the calling (main) thread, which stores it, returns the progress line printed for the piece
and may add pieces. Threads suffice on two cores: a testbed run is a child process (one core),
and the analytic pieces spend their time in LAPACK, which releases the GIL.

Stopping: a failed piece or a stop signal (:mod:`pentapod_sim.shutdown`: SIGINT, SIGTERM,
SIGHUP, recorded by the handler the study installs) starts no further piece; the running
testbed runs stop their nodes (the scenario runner sees the same request), and once every
running piece has returned the first error is raised again, or :class:`Interrupted` for a
signal.
"""
from __future__ import annotations

from concurrent.futures import FIRST_COMPLETED, Future, ThreadPoolExecutor, wait
from dataclasses import dataclass, field
import itertools
import signal
import threading
import time
from typing import Any, Callable, Hashable, Iterable

from pentapod_sim import shutdown

#: How often the main thread looks for a stop signal while pieces run [s].
POLL = 0.2
#: pyplot is not thread-safe: pieces that draw figures hold this lock.
FIGURE_LOCK = threading.Lock()


class Interrupted(Exception):
    """A stop signal ended the study; ``code`` is the shell's exit code (128 + signal)."""

    def __init__(self, name: str, code: int):
        super().__init__(f'{name} received: stopped')
        self.code = code


@dataclass
class Piece:
    """
    One unit of work of the study.

    Attributes
    ----------
    key : hashable
        Names the piece (e.g. ``('run', 'P1', 'baseline')``); unique.
    work : callable
        Runs in a worker thread; its return value goes to ``done``.
    stage : str
        Stage the piece's time is counted in (:attr:`Schedule.stages`).
    after : tuple of keys
        Pieces that must have finished first.
    priority : int
        Lower starts first among the ready pieces (ties: order of adding).
    done : callable, optional
        ``done(result)`` in the main thread: stores the result and returns the piece's
        progress line (None: no line) and, optionally, new pieces as ``(line, pieces)``.
    lane : str, optional
        Pieces of a lane with a limit (:func:`run_pieces` ``lanes``) run at most that many
        at a time (e.g. runs on one ROS domain: one).
    """

    key: Hashable
    work: Callable[[], Any]
    stage: str
    after: tuple = ()
    priority: int = 0
    done: Callable[[Any], Any] | None = None
    lane: str | None = None


@dataclass
class Schedule:
    """What :func:`run_pieces` measured: per stage the wall span and busy time [s]."""

    started: dict = field(default_factory=dict)    # key -> perf_counter at start
    finished: dict = field(default_factory=dict)   # key -> perf_counter at end
    stage_of: dict = field(default_factory=dict)   # key -> stage

    def stages(self) -> dict[str, tuple[float, float, int]]:
        """Stage -> (wall span from first start to last end, summed busy time, pieces) [s]."""
        out: dict[str, list] = {}
        for key, end in self.finished.items():
            start = self.started[key]
            span = out.setdefault(self.stage_of[key], [start, end, 0.0, 0])
            span[0], span[1] = min(span[0], start), max(span[1], end)
            span[2] += end - start
            span[3] += 1
        return {k: (v[1] - v[0], v[2], v[3]) for k, v in out.items()}


def run_pieces(pieces: Iterable[Piece], workers: int, say: Callable[[str], None],
               schedule: Schedule | None = None, lanes: dict | None = None) -> Schedule:
    """
    Run ``pieces`` (and those their ``done`` adds), at most ``workers`` at a time.

    ``lanes`` limits how many pieces of a lane run at once (lane -> count).

    Prints (``say``) one line per finished piece, prefixed by its number and the count known.

    Raises
    ------
    Exception
        The first error a piece raised (no further piece started; the running ones finished).
    Interrupted
        If a stop signal arrived.
    ValueError
        If a piece waits for a key that no piece has, or two pieces share a key.
    """
    schedule = Schedule() if schedule is None else schedule
    lanes = lanes or {}
    waiting: dict[Hashable, Piece] = {}
    ready: list = []            # (priority, order, piece), sorted
    order = itertools.count()
    finished: set = set()
    running: dict[Future, Piece] = {}
    error: BaseException | None = None
    total = 0

    def add(new: Iterable[Piece]) -> None:
        nonlocal total
        for piece in new:
            if piece.key in waiting or piece.key in schedule.stage_of:
                raise ValueError(f'two pieces are named {piece.key!r}')
            waiting[piece.key] = piece
            schedule.stage_of[piece.key] = piece.stage
            total += 1

    def release() -> None:
        for key, piece in list(waiting.items()):
            if all(k in finished for k in piece.after):
                del waiting[key]
                ready.append((piece.priority, next(order), piece))
        ready.sort(key=lambda item: item[:2])

    def pick() -> Piece | None:
        """The first ready piece whose lane has room (removed from ``ready``)."""
        busy: dict = {}
        for piece in running.values():
            busy[piece.lane] = busy.get(piece.lane, 0) + 1
        for i, (_, _, piece) in enumerate(ready):
            if piece.lane not in lanes or busy.get(piece.lane, 0) < lanes[piece.lane]:
                return ready.pop(i)[2]
        return None

    def timed(piece: Piece) -> Any:
        schedule.started[piece.key] = time.perf_counter()
        try:
            return piece.work()
        finally:
            schedule.finished[piece.key] = time.perf_counter()

    add(pieces)
    release()
    with ThreadPoolExecutor(max_workers=max(1, workers),
                            thread_name_prefix='study') as pool:
        while ready or running:
            stopping = error is not None or shutdown.requested()
            while ready and not stopping and len(running) < max(1, workers):
                piece = pick()
                if piece is None:
                    break
                running[pool.submit(timed, piece)] = piece
            if not running:
                break
            done, _ = wait(running, timeout=POLL, return_when=FIRST_COMPLETED)
            for future in done:
                piece = running.pop(future)
                try:
                    result = future.result()
                    line = piece.done(result) if piece.done else None
                    line, new = line if isinstance(line, tuple) else (line, ())
                except BaseException as err:       # noqa: B902 (re-raised below)
                    if error is None and not shutdown.requested():
                        error = err
                        shutdown.request(signal.SIGTERM)   # stops the other running runs
                    continue
                finished.add(piece.key)
                if line:
                    say(f'({len(finished)}/{total}) {line}')
                add(new)
                release()
    if error is not None:
        raise error
    if shutdown.requested():
        raise Interrupted(shutdown.signal_name(), shutdown.exit_code())
    if waiting:
        missing = {k for p in waiting.values() for k in p.after} - set(schedule.stage_of)
        raise ValueError(f'pieces wait for unknown pieces: {sorted(map(str, missing))}')
    return schedule
