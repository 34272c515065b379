"""
Benchmark of the workspace sweep (pentapod_damper.sweep): Dask workers against a plain loop.

The same poses (reachable, default scenarios of config/study.yaml) are computed three ways into
fresh result folders: the serial loop in this process (baseline), a LocalCluster with one
worker process and one with two (each timed from the cluster's start to its last stored row,
so the start-up counts). Poses per minute and the ratio to the serial loop are the figures; the
rows of all runs must agree (note). Peak memory per task: VmHWM of a fresh process after one
pose, against the same process after its imports.

Where a pose's time goes (rows "sweep, per pose: ..."): the imports of a fresh worker
process, then the stages of ``pentapod_damper.sweep.compute.evaluate`` timed one by one on the
serial poses (model build, modes, plant reduction, laws = the closed loops of every scenario),
and the transfer: the two-worker run's wall time beyond its poses' compute time shared by the
two workers (cluster start, task and result transfer, store). Every row states the load
average it ran under (2 cores: the ratios need an idle machine).
"""
from __future__ import annotations

import json
import os
from pathlib import Path
import subprocess
import sys
import tempfile
import time

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))   # run from a checkout
from pentapod_damper.sweep.compute import BOOKKEEPING, columns  # noqa: E402
from pentapod_damper.sweep.poses import grid  # noqa: E402
from pentapod_damper.sweep.runner import run_sweep  # noqa: E402
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


def run(quick: bool) -> list[dict]:
    """Return benchmark rows (see bench/run_all.py)."""
    settings = make_settings()
    poses = _poses(quick)
    n = len(poses)
    load = os.getloadavg()[0]
    figures, rows_of, compute_s = {}, {}, {}
    with tempfile.TemporaryDirectory() as tmp:
        for label, kwargs in (('serial loop', {'serial': True}), ('1 worker', {'n_workers': 1}),
                              ('2 workers', {'n_workers': 2})):
            out = Path(tmp) / label.replace(' ', '_')
            t0 = time.perf_counter()
            report = run_sweep(poses, settings, out, progress=False, **kwargs)
            seconds = time.perf_counter() - t0
            if report.counts.get('ok') != n:
                raise RuntimeError(f'{label}: {report.counts} of {n} poses; {report.errors}')
            figures[label] = (60.0 * n / seconds, seconds)
            rows_of[label] = _rows(out, settings)
            compute_s[label] = float(ResultStore(out, columns(settings), settings.digest)
                                     .load().column('seconds').to_numpy().sum())
            if label == 'serial loop':
                table = ResultStore(out, columns(settings), settings.digest).load()
                cpu = float(np.median(table.column('cpu_seconds').to_numpy()))
    agree = all(_same(rows_of['serial loop'], rows_of[k]) for k in ('1 worker', '2 workers'))
    base, base_s = figures['serial loop']
    rows = []
    for label in ('2 workers', '1 worker'):
        ppm, seconds = figures[label]
        rows.append({'name': f'sweep, {label}', 'value': ppm, 'unit': 'poses/min',
                     'baseline': 'sweep, serial loop', 'baseline_value': base,
                     'ratio': ppm / base,
                     'note': f'{n} poses in {seconds:.1f} s (serial {base_s:.1f} s, median CPU '
                             f'{cpu:.2f} s per pose), LocalCluster start included; rows '
                             f'{"equal" if agree else "DIFFER"}; load {load:.1f} at the start '
                             f'({os.cpu_count()} cores)'})
    stages = _stages(poses, settings)
    stages['transfer (2 workers)'] = (figures['2 workers'][1]
                                      - compute_s['2 workers'] / 2.0) / n
    total = sum(stages.values())
    for stage, seconds in stages.items():
        rows.append({'name': f'sweep, per pose: {stage}', 'value': seconds, 'unit': 's',
                     'baseline': None, 'baseline_value': None, 'ratio': None,
                     'note': f'{100 * seconds / total:.0f} % of {total:.2f} s; median of '
                             f'{n} poses (imports: once per worker; transfer: 2-worker wall '
                             f'time beyond compute / 2, per pose); load {load:.1f}'})
    mem = _memory()
    rows.append({'name': 'sweep, peak memory per task', 'value': mem['after'] - mem['before'],
                 'unit': 'MB', 'baseline': 'process after imports and settings',
                 'baseline_value': mem['before'], 'ratio': None,
                 'note': f'VmHWM of a fresh process: {mem["after"]:.0f} MB after one pose '
                         f'({mem["status"]})'})
    return rows


if __name__ == '__main__':
    for row in run(quick='--quick' in sys.argv):
        print(row)
