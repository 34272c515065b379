"""
Benchmark of the workspace sweep (pentapod_damper.sweep): Dask workers against a plain loop.

The same poses (reachable, default scenarios of config/study.yaml) are computed four ways into
fresh result folders: the serial loop in this process (baseline), a LocalCluster with one
worker process and one with two, forked from this process (the runner's default on Linux), and
one with two spawned workers (fresh interpreters that import everything again: the runner's
way before, and its fallback). Each is timed from the cluster's start to its last stored row,
so the start-up counts. Poses per minute and the ratio to the serial loop are the figures; the
rows of all runs must agree (note). Each note gives the load average (1 min) at the start and
at the end of that run (the machine has 2 cores; the workers of the run itself add up to 2)
and compute/wall: the poses' summed compute time (``seconds`` column) over the run's wall time
(2 is the most two workers can give), and the CPU time of the bench's own process in the
run (client, scheduler and nannies of a LocalCluster live there). The load average lags by a
minute, so each note also gives what the run shared the cores with: the poses' compute time
against the serial loop's (1.00x: no contention) and the cores other processes used during
the run (the machine's busy CPU time from /proc/stat beyond this process's and the poses' CPU
time, over the run's wall time; the workers' imports and Dask overhead count as other). Peak memory
per task: VmHWM of a fresh process after one pose, against the same process after its
imports.

Where a pose's time goes (rows "sweep, per pose: ..."): the imports of a fresh (spawned)
worker process, then the stages of ``pentapod_damper.sweep.compute.evaluate`` timed one by one
on the serial poses (model build, modes, plant reduction, laws = the closed loops of every
scenario). Where the two-worker runs lose against the serial loop (rows "sweep, 2 workers
(fork|spawn): ..."): each phase as the runner times it (``SweepReport.timings``): cluster
start, the workers' imports, scatter of the settings, the client's Parquet writes, the progress
bar, closing the cluster, and the task overhead: the run's task phase beyond the poses'
compute time shared by the workers (dispatch, result transfer, idle ends). The row "sweep,
task round trip" measures one task directly: a task that returns one result row, submitted and
awaited one after the other on a forked worker (median of 20; the row's pickled size in the
note).
"""
from __future__ import annotations

import contextlib
import json
import os
from pathlib import Path
import pickle
import subprocess
import sys
import tempfile
import time

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))   # run from a checkout
from pentapod_damper.sweep import runner  # noqa: E402
from pentapod_damper.sweep.compute import BOOKKEEPING, columns  # noqa: E402
from pentapod_damper.sweep.poses import grid  # noqa: E402
from pentapod_damper.sweep.runner import local_cluster, run_sweep  # noqa: E402
from pentapod_damper.sweep.settings import make_settings  # noqa: E402
from pentapod_damper.sweep.store import ResultStore  # noqa: E402

MEMORY_SCRIPT = """
import json, sys
sys.path.insert(0, {root!r})
from pentapod_damper.sweep.compute import compute_pose, peak_rss_mb
from pentapod_damper.sweep.settings import make_settings
settings = make_settings()
before = peak_rss_mb()
row = compute_pose([0.1, -0.1, 0.85, 0.0, 0.0], 'bench', settings)
print(json.dumps({{'before': before, 'after': peak_rss_mb(), 'status': row['status']}}))
"""


def _busy_seconds() -> float:
    """
    CPU seconds all processes of the machine have used since boot (/proc/stat; NaN off Linux).

    User, nice, system, irq, softirq and steal time of every core.
    """
    try:
        with open('/proc/stat', encoding='ascii') as stream:
            fields = stream.readline().split()[1:]
    except OSError:
        return float('nan')
    user, nice, system, _idle, _iowait, irq, softirq, steal = map(int, fields[:8])
    return (user + nice + system + irq + softirq + steal) / os.sysconf('SC_CLK_TCK')


@contextlib.contextmanager
def _start_method(method: str | None):
    """Make the runner start its local workers with ``method`` (None: its own choice)."""
    default = runner.start_method
    if method is not None:
        runner.start_method = lambda: method
    try:
        yield
    finally:
        runner.start_method = default


def _poses(quick: bool) -> np.ndarray:
    """A reachable x-y grid around the workspace centre (P1's slice)."""
    n = 2 if quick else 4
    return grid(f'-0.15:0.15:{n}', f'-0.15:0.15:{n}' if not quick else '0:0.1:2', '0.85')


def _rows(out: Path, settings) -> dict:
    table = ResultStore(out, columns(settings), settings.digest).load()
    return {r['key']: {k: v for k, v in r.items() if k not in BOOKKEEPING}
            for r in table.to_pylist()}


def _same(a: dict, b: dict) -> bool:
    if a.keys() != b.keys():
        return False
    for key, row in a.items():
        for name, value in row.items():
            other = b[key][name]
            if isinstance(value, float):
                if not np.isclose(value, other, rtol=1e-7, atol=0, equal_nan=True):
                    return False
            elif value != other:
                return False
    return True


def _memory() -> dict:
    out = subprocess.run([sys.executable, '-c', MEMORY_SCRIPT.format(root=str(ROOT))],
                         capture_output=True, text=True, check=True, cwd=ROOT)
    return json.loads(out.stdout.strip().splitlines()[-1])


IMPORT_SCRIPT = """
import sys, time
sys.path.insert(0, {root!r})
t0 = time.perf_counter()
import pentapod_damper.sweep.compute  # noqa: F401
print(time.perf_counter() - t0)
"""


def _stages(poses: np.ndarray, settings) -> dict:
    """Median seconds per pose of each stage of ``evaluate`` (reachable poses only)."""
    from pentapod_damper.sweep.compute import first_modes, loops_of
    from pentapod_damper.sweep.loops import loop_columns
    from pentapod_sim.errors import UnreachablePoseError
    from pentapod_sim.modes.frame_reduction import build_model
    from pentapod_sim.modes.solver import solve_modes
    from pentapod_sim.plant.build import plant_from_fe, reduce_plant
    times: dict[str, list[float]] = {'model build': [], 'modes': [], 'plant': [], 'laws': []}
    loops = loops_of(settings)
    freq = np.linspace(*settings.freq[:2], int(settings.freq[2]))
    for pose in poses:
        t0 = time.perf_counter()
        try:
            fe = build_model(settings.machine, pose)
        except UnreachablePoseError:
            continue
        t1 = time.perf_counter()
        modes = solve_modes(fe.K, fe.M, f_max=max(settings.mode_f_max,
                                                  settings.reduction.modes_f_max))
        first_modes(fe, settings.mode_f_max, modes)
        t2 = time.perf_counter()
        plant_all, keep = plant_from_fe(fe, settings.reduction, lambda m: None, modes)
        plant = reduce_plant(plant_all, keep, settings.reduction.static_correction)
        t3 = time.perf_counter()
        loop_columns(plant, loops, freq, settings.band, 1.0 / settings.sample_rate,
                     settings.pma_force_amplitude, settings.share_labels())
        t4 = time.perf_counter()
        for name, dt in zip(times, (t1 - t0, t2 - t1, t3 - t2, t4 - t3)):
            times[name].append(dt)
    out = subprocess.run([sys.executable, '-c', IMPORT_SCRIPT.format(root=str(ROOT))],
                         capture_output=True, text=True, check=True, cwd=ROOT)
    result = {name: float(np.median(v)) for name, v in times.items()}
    result['imports (fresh worker)'] = float(out.stdout.strip().splitlines()[-1])
    return result


def _echo(row: dict) -> dict:
    return row


def _round_trip(row: dict) -> tuple[float, int]:
    """Median seconds of one task returning ``row`` on a forked worker, and the row's bytes."""
    from distributed import Client
    cluster = local_cluster(1, 'fork')
    client = Client(cluster)
    try:
        times = []
        for _ in range(20):
            t0 = time.perf_counter()
            client.submit(_echo, row, pure=False).result()
            times.append(time.perf_counter() - t0)
    finally:
        client.close()
        cluster.close()
    return float(np.median(times)), len(pickle.dumps(row))


#: Runs of the comparison: label, run_sweep keywords, start method of the local workers.
RUNS = (('serial loop', {'serial': True}, None), ('1 worker', {'n_workers': 1}, 'fork'),
        ('2 workers', {'n_workers': 2}, 'fork'), ('2 workers, spawned', {'n_workers': 2},
                                                  'spawn'))
#: Phases of a Dask run (SweepReport.timings) reported as rows, in order.
PHASES = ('cluster start', 'worker imports', 'scatter', 'task overhead', 'store', 'progress',
          'close')


def run(quick: bool, n_side: int | None = None) -> list[dict]:
    """Return benchmark rows (see bench/run_all.py); ``n_side``: grid of n_side**2 poses."""
    settings = make_settings()
    poses = _poses(quick) if n_side is None else grid(
        f'-0.15:0.15:{n_side}', f'-0.15:0.15:{n_side}', '0.85')
    n = len(poses)
    figures, rows_of, compute_s, timings, loads = {}, {}, {}, {}, {}
    client_cpu, busy, others = {}, {}, {}
    with tempfile.TemporaryDirectory() as tmp:
        for label, kwargs, method in RUNS:
            out = Path(tmp) / label.replace(' ', '_').replace(',', '')
            load0 = os.getloadavg()[0]
            t0, cpu0, busy0 = time.perf_counter(), time.process_time(), _busy_seconds()
            with _start_method(method):
                report = run_sweep(poses, settings, out, progress=False, **kwargs)
            seconds = time.perf_counter() - t0
            client_cpu[label] = time.process_time() - cpu0
            busy[label] = _busy_seconds() - busy0
            loads[label] = (load0, os.getloadavg()[0])
            if report.counts.get('ok') != n:
                raise RuntimeError(f'{label}: {report.counts} of {n} poses; {report.errors}')
            figures[label] = (60.0 * n / seconds, seconds)
            rows_of[label] = _rows(out, settings)
            table = ResultStore(out, columns(settings), settings.digest).load()
            compute_s[label] = float(table.column('seconds').to_numpy().sum())
            pose_cpu = float(table.column('cpu_seconds').to_numpy().sum())
            # cores used by other processes: the machine's busy time beyond this run's own
            others[label] = max(busy[label] - client_cpu[label] - pose_cpu, 0.0) / seconds
            timings[label] = dict(report.timings, workers=report.workers)
            if label == 'serial loop':
                cpu = float(np.median(table.column('cpu_seconds').to_numpy()))
                one_row = table.to_pylist()[0]
    agree = all(_same(rows_of['serial loop'], rows_of[k]) for k, _, _ in RUNS[1:])
    base, base_s = figures['serial loop']
    rows = []
    for label, _, method in RUNS[1:]:
        ppm, seconds = figures[label]
        rows.append({'name': f'sweep, {label}', 'value': ppm, 'unit': 'poses/min',
                     'baseline': 'sweep, serial loop', 'baseline_value': base,
                     'ratio': ppm / base,
                     'note': f'{n} poses in {seconds:.1f} s (serial {base_s:.1f} s, median CPU '
                             f'{cpu:.2f} s per pose), workers {method}ed, LocalCluster start '
                             f'included; compute/wall {compute_s[label] / seconds:.2f} (serial '
                             f'{compute_s["serial loop"] / base_s:.2f}); CPU of this '
                             f'process (client, scheduler, nannies) {client_cpu[label]:.1f} s; '
                             f'rows '
                             f'{"equal" if agree else "DIFFER"}; poses took '
                             f'{compute_s[label] / compute_s["serial loop"]:.2f}x their serial '
                             f'time; other processes used {others[label]:.2f} cores (serial run '
                             f'{others["serial loop"]:.2f}); load {loads[label][0]:.1f} at '
                             f'the start, {loads[label][1]:.1f} at the end ({os.cpu_count()} '
                             f'cores)'})
    stages = _stages(poses, settings)
    total = sum(stages.values())
    for stage, seconds in stages.items():
        rows.append({'name': f'sweep, per pose: {stage}', 'value': seconds, 'unit': 's',
                     'baseline': None, 'baseline_value': None, 'ratio': None,
                     'note': f'{100 * seconds / total:.0f} % of {total:.2f} s; median of '
                             f'{n} poses (imports: once per spawned worker); load '
                             f'{os.getloadavg()[0]:.1f}'})
    for label in ('2 workers', '2 workers, spawned'):
        phase = timings[label]
        phase['task overhead'] = phase['tasks'] - compute_s[label] / phase['workers']
        wall = figures[label][1]
        method = 'fork' if label == '2 workers' else 'spawn'
        for name in PHASES:
            rows.append({'name': f'sweep, 2 workers ({method}): {name}', 'value': phase[name],
                         'unit': 's', 'baseline': None, 'baseline_value': None, 'ratio': None,
                         'note': f"{100 * phase[name] / wall:.0f} % of the run's {wall:.1f} s "
                                 f'for {n} poses (compute {compute_s[label]:.1f} s over '
                                 f'{phase["workers"]} workers); load {loads[label][0]:.1f}'})
    trip, size = _round_trip(one_row)
    rows.append({'name': 'sweep, task round trip', 'value': trip, 'unit': 's',
                 'baseline': None, 'baseline_value': None, 'ratio': None,
                 'note': f'one task returning one result row ({size} B pickled) on a forked '
                         f'worker, median of 20; load {os.getloadavg()[0]:.1f}'})
    mem = _memory()
    rows.append({'name': 'sweep, peak memory per task', 'value': mem['after'] - mem['before'],
                 'unit': 'MB', 'baseline': 'process after imports and settings',
                 'baseline_value': mem['before'], 'ratio': None,
                 'note': f'VmHWM of a fresh process: {mem["after"]:.0f} MB after one pose '
                         f'({mem["status"]})'})
    return rows


if __name__ == '__main__':
    # python bench/bench_sweep.py [--quick] [--side N]: N x N poses (default 4: 16 poses)
    side = int(sys.argv[sys.argv.index('--side') + 1]) if '--side' in sys.argv else None
    for row in run(quick='--quick' in sys.argv, n_side=side):
        print(row)
