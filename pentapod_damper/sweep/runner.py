"""
Run the poses of a sweep on Dask (or in a plain loop) and stream the rows into the store.

By default a :class:`distributed.LocalCluster` starts worker processes with one thread each
and single-threaded BLAS (``OPENBLAS_NUM_THREADS=1`` and friends set before the workers
spawn); ``scheduler`` connects to an existing cluster instead (dask-jobqueue, Kubernetes,
``dask scheduler`` by hand; docs/sweep.md). One task computes ``batch`` poses
(:func:`pentapod_damper.sweep.compute.compute_batch`); the client writes each finished task's
rows as one Parquet file, so only the tasks in flight are lost when a sweep is stopped. A task
that raises (a worker killed, an import error on a remote worker) gives ``failed`` rows with
the error; the other tasks go on.

On Linux the local workers are forked from the client process (``fork`` start method), so they
start with the client's imports (numpy, scipy, python-control, the FE and plant code: about
1.3 s per fresh worker process on an idle core, 11 s measured under load) instead of importing
them again; this needs the client's BLAS to be single-threaded already
(``OPENBLAS_NUM_THREADS=OMP_NUM_THREADS=1`` in the environment when this module was imported,
as tools/env.sh sets them), otherwise the workers are spawned fresh as before. Each phase of a
Dask run is timed in :attr:`SweepReport.timings`.
"""
from __future__ import annotations

from dataclasses import dataclass, field
import logging
import multiprocessing
import os
from pathlib import Path
import sys
import time
from typing import Any, Callable, Iterator, Sequence

import numpy as np

from pentapod_damper.sweep.compute import columns, compute_batch, FAILED
from pentapod_damper.sweep.poses import AXES, pose_key
from pentapod_damper.sweep.settings import SweepSettings
from pentapod_damper.sweep.store import ResultStore
from pentapod_damper.sweep.warm import import_seconds

#: Environment of the local workers: one BLAS/OpenMP thread per worker process.
WORKER_ENV = {'OPENBLAS_NUM_THREADS': 1, 'OMP_NUM_THREADS': 1, 'MKL_NUM_THREADS': 1}
#: Number of local worker processes by default.
DEFAULT_WORKERS = 2
#: Whether the BLAS of this process was single-threaded when it was loaded (the environment
#: when this module, which imports numpy, was imported): only then may workers be forked.
BLAS_SINGLE_THREADED = all(os.environ.get(k) == '1'
                           for k in ('OPENBLAS_NUM_THREADS', 'OMP_NUM_THREADS'))


@dataclass
class SweepReport:
    """What a call of :func:`run_sweep` did; times in s."""

    poses: int = 0
    skipped: int = 0
    computed: int = 0
    counts: dict[str, int] = field(default_factory=dict)     # status -> poses computed now
    #: (pose, error) of the failed poses
    errors: list[tuple[list[float], str]] = field(default_factory=list)
    seconds: float = 0.0
    workers: int = 0
    interrupted: bool = False
    #: Dask run only: seconds of each phase in the client ('cluster start', 'worker imports',
    #: 'scatter', 'tasks' (first submit to last result), 'store', 'progress', 'close') and
    #: 'start method' (fork or spawn; None with ``scheduler``).
    timings: dict[str, Any] = field(default_factory=dict)

    @property
    def poses_per_minute(self) -> float:
        """Poses computed now per minute of wall time."""
        return 60.0 * self.computed / self.seconds if self.seconds > 0 else float('nan')


Row = dict[str, Any]
#: ``compute(poses, keys, settings) -> rows`` of one task.
Compute = Callable[[Sequence[Sequence[float]], Sequence[str], SweepSettings], list[Row]]


def failed_rows(poses: Sequence[Sequence[float]], keys: Sequence[str],
                error: BaseException) -> list[Row]:
    """Rows of a task that raised instead of returning rows."""
    now = time.time()
    return [{'key': k, 'status': FAILED, 'error': f'{type(error).__name__}: {error}',
             'finished_at': now, **{a: float(v) for a, v in zip(AXES, p)}}
            for p, k in zip(poses, keys)]


def _batches(poses: np.ndarray, keys: list[str],
             size: int) -> Iterator[tuple[list[list[float]], list[str]]]:
    for start in range(0, len(keys), size):
        yield poses[start:start + size].tolist(), keys[start:start + size]


def _progress(total: int, enabled: bool) -> Any:
    from tqdm import tqdm
    return tqdm(total=total, unit='pose', desc='sweep', disable=not enabled, file=sys.stderr,
                smoothing=0.1)


def start_method() -> str:
    """
    How local workers are started: ``fork`` or ``spawn``.

    ``fork`` (they inherit this process's imports) on Linux when this process's BLAS is
    single-threaded (:data:`BLAS_SINGLE_THREADED`), else ``spawn`` (a fresh interpreter that
    imports everything again).
    """
    if BLAS_SINGLE_THREADED and 'fork' in multiprocessing.get_all_start_methods():
        return 'fork'
    return 'spawn'


def local_cluster(n_workers: int, method: str | None = None) -> Any:
    """
    A LocalCluster of ``n_workers`` single-threaded processes with single-threaded BLAS.

    ``method``: ``fork``, ``forkserver`` or ``spawn`` (default :func:`start_method`).
    """
    import dask
    from distributed import LocalCluster
    environ = dict(dask.config.get('distributed.nanny.pre-spawn-environ', {}), **WORKER_ENV)
    logging.getLogger('distributed').setLevel(logging.ERROR)    # no start/stop chatter
    with dask.config.set({'distributed.nanny.pre-spawn-environ': environ,
                          'distributed.worker.multiprocessing-method':
                              method or start_method()}):
        return LocalCluster(n_workers=n_workers, threads_per_worker=1, processes=True,
                            dashboard_address=':0', silence_logs=logging.ERROR)


def run_sweep(poses: np.ndarray, settings: SweepSettings, out_dir: str | Path, *,
              scheduler: str | None = None, n_workers: int = DEFAULT_WORKERS, batch: int = 1,
              serial: bool = False, progress: bool = True, compute: Compute = compute_batch,
              on_rows: Callable[[list[Row]], None] | None = None) -> SweepReport:
    """
    Compute every pose not yet in the store of ``out_dir``.

    Parameters
    ----------
    poses : (N, 5) ndarray
        x, y, z [m], a, b [rad].
    settings : SweepSettings
        What to compute (:func:`pentapod_damper.sweep.settings.make_settings`).
    out_dir : str or Path
        Folder of the result dataset.
    scheduler : str, optional
        Address of a running Dask scheduler (``tcp://host:8786``) or its scheduler file
        (``*.json``); default a LocalCluster.
    n_workers : int
        Processes of the LocalCluster.
    batch : int
        Poses per task.
    serial : bool
        Compute in this process, one pose after the other, without Dask.
    progress : bool
        Show a progress bar on stderr.
    compute : callable
        ``compute(poses, keys, settings) -> rows`` of one task.
    on_rows : callable, optional
        Called with the rows of every finished task (after they are stored).

    Returns
    -------
    SweepReport
        ``interrupted`` is set when Ctrl-C stopped it; the finished tasks are stored.
    """
    if batch < 1 or n_workers < 1:
        raise ValueError(f'batch and n_workers must be >= 1, got {batch}, {n_workers}')
    store = ResultStore(out_dir, columns(settings), settings.digest).open()
    poses = np.asarray(poses, dtype=float).reshape(-1, 5)
    keys = [pose_key(p, settings.digest) for p in poses]
    done = store.done_keys()
    todo = [i for i, k in enumerate(keys) if k not in done]
    report = SweepReport(poses=len(keys), skipped=len(keys) - len(todo))
    t0 = time.perf_counter()

    def finish(rows: list[Row]) -> None:
        t_store = time.perf_counter()
        store.write(rows)
        t_bar = time.perf_counter()
        report.computed += len(rows)
        for row in rows:
            report.counts[row['status']] = report.counts.get(row['status'], 0) + 1
            if row['status'] == FAILED:
                report.errors.append(([row[a] for a in AXES], row['error']))
        bar.update(len(rows))
        timings['store'] = timings.get('store', 0.0) + t_bar - t_store
        timings['progress'] = timings.get('progress', 0.0) + time.perf_counter() - t_bar
        if on_rows is not None:
            on_rows(rows)

    tasks = list(_batches(poses[todo], [keys[i] for i in todo], batch))
    timings = report.timings
    t_bar = time.perf_counter()
    bar = _progress(len(todo), progress)
    timings['progress'] = time.perf_counter() - t_bar
    try:
        if serial or not tasks:
            report.workers = 1 if tasks else 0
            for chunk, chunk_keys in tasks:
                finish(compute(chunk, chunk_keys, settings))
        else:
            _run_dask(tasks, settings, scheduler, n_workers, compute, finish, report)
    except KeyboardInterrupt:
        report.interrupted = True
    finally:
        bar.close()
        report.seconds = time.perf_counter() - t0
    return report


def _run_dask(tasks: list[tuple[list[list[float]], list[str]]], settings: SweepSettings,
              scheduler: str | None, n_workers: int, compute: Compute,
              finish: Callable[[list[Row]], None], report: SweepReport) -> None:
    from distributed import as_completed, Client
    timings = report.timings
    t0 = time.perf_counter()
    timings['start method'] = None if scheduler else start_method()
    cluster = None if scheduler else local_cluster(n_workers)
    if scheduler and scheduler.endswith('.json'):     # dask scheduler --scheduler-file
        client = Client(scheduler_file=scheduler)
    else:
        client = Client(scheduler or cluster)
    futures: dict[Any, tuple[list[list[float]], list[str]]] = {}
    try:
        report.workers = len(client.scheduler_info()['workers'])
        t1 = time.perf_counter()
        # the workers import the pose code now, all at once (about 0 s for forked workers);
        # a worker that cannot (no package) fails its tasks instead, one by one
        try:
            timings['worker imports'] = max(client.run(import_seconds).values(), default=0.0)
        except Exception:  # noqa: BLE001 -- reported by the tasks as failed rows
            timings['worker imports'] = float('nan')
        t2 = time.perf_counter()
        shared = client.scatter(settings, broadcast=True)
        t3 = time.perf_counter()
        timings.update({'cluster start': t1 - t0, 'worker imports wall': t2 - t1,
                        'scatter': t3 - t2})
        futures = {client.submit(compute, chunk, chunk_keys, shared, pure=False):
                   (chunk, chunk_keys) for chunk, chunk_keys in tasks}
        for future in as_completed(futures):
            chunk, chunk_keys = futures[future]
            try:
                rows = future.result()
            except Exception as err:  # noqa: BLE001 -- the task's poses are recorded failed
                rows = failed_rows(chunk, chunk_keys, err)
            finish(rows)
            future.release()
        timings['tasks'] = time.perf_counter() - t3
    finally:
        t4 = time.perf_counter()
        if futures:
            client.cancel(list(futures))
        client.close()
        if cluster is not None:
            cluster.close()
        timings['close'] = time.perf_counter() - t4
