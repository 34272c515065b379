"""Workspace sweep: Dask equals the serial loop, resume after an interrupt, bad poses recorded."""
from pathlib import Path
import re
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from fixtures.processes import sigint_as_in_a_terminal
from pentapod_damper.scenario_laws import continuous_dampers, scenario_laws
from pentapod_damper.study.analytic import continuous_frf, improvement_share, peak_and_rms
from pentapod_damper.sweep import compute as compute_module
from pentapod_damper.sweep import poses as pose_input
from pentapod_damper.sweep.__main__ import main
from pentapod_damper.sweep.compute import BOOKKEEPING, columns, compute_batch
from pentapod_damper.sweep.loops import paired_damping
from pentapod_damper.sweep.runner import run_sweep
from pentapod_damper.sweep.settings import make_settings
from pentapod_damper.sweep.store import as_arrays, ResultStore
from pentapod_damper.sweep.sweep_plot import all_figures, claim_fractions
from pentapod_sim.errors import ConfigError
from pentapod_sim.fe.geometry import inverse_kinematics, layout_from_params
from pentapod_sim.fe.machine_data import load_machine
from pentapod_sim.plant.build import build_plant
from pentapod_sim.plant.frf import damper_feedback
from pentapod_sim.plant.model import PlantModel
from pentapod_sim.scenario.files import read_scenario

ROOT = Path(__file__).resolve().parents[1]
SCENARIOS = ['strut_damping_12', 'strut_damping_all', 'pma_5kg']
N_POINTS = 1000
#: x, y, z [m], a, b [deg]: P1, P2, four more, the last one out of strut 4's stroke.
POSES_DEG = [(0.0, 0.0, 0.85, 0.0, 0.0), (0.3, 0.0, 0.75, 0.0, 10.0),
             (0.1, -0.1, 0.85, 0.0, 0.0), (0.0, 0.2, 0.9, 5.0, 0.0),
             (-0.2, 0.0, 0.8, 0.0, -5.0), (-0.2, 0.6, 0.85, 0.0, 0.0)]
POSES = np.array([[x, y, z, np.radians(a), np.radians(b)] for x, y, z, a, b in POSES_DEG])
POSE_ARGS = ['--pose=' + ','.join(map(str, p)) for p in POSES_DEG]


@pytest.fixture(scope='module')
def settings():
    return make_settings(SCENARIOS, [1.0], n_points=N_POINTS)


@pytest.fixture(scope='module')
def serial(settings, tmp_path_factory):
    """The six poses computed by the plain loop: (out dir, rows by key)."""
    out = tmp_path_factory.mktemp('serial')
    report = run_sweep(POSES, settings, out, serial=True, progress=False)
    assert report.computed == 6 and report.counts == {'ok': 5, 'unreachable': 1}
    return out, _rows(out, settings)


def _rows(out, settings) -> dict:
    table = ResultStore(out, columns(settings), settings.digest).load()
    return {row['key']: row for row in table.to_pylist()}


def _assert_same(rows_a: dict, rows_b: dict) -> None:
    assert rows_a.keys() == rows_b.keys()
    for key, a in rows_a.items():
        b = rows_b[key]
        for name, value in a.items():
            if name in BOOKKEEPING:
                continue
            if isinstance(value, float):
                np.testing.assert_allclose(b[name], value, rtol=1e-7, atol=0,
                                           err_msg=f'{name} at {key}')
            else:
                assert b[name] == value, f'{name} at {key}'


def test_two_worker_cluster_equals_serial_loop_and_survives_a_failing_task(settings, serial,
                                                                           tmp_path):
    """2-worker LocalCluster rows equal the serial rows; a raising task is recorded failed."""
    poison = [0.05, 0.05, 0.85, 0.0, 0.0]

    def flaky(poses, keys, shared):           # pickled by value onto the workers
        if any(np.allclose(p, poison) for p in poses):
            raise RuntimeError('injected failure of this task')
        import os as worker_os
        rows = compute_batch(poses, keys, shared)
        for row in rows:
            row['error'] = worker_os.environ.get('OPENBLAS_NUM_THREADS', 'unset')
        return rows

    report = run_sweep(np.vstack([POSES, poison]), settings, tmp_path, n_workers=2,
                       progress=False, compute=flaky)
    assert report.workers == 2 and report.computed == 7
    assert report.counts == {'ok': 5, 'unreachable': 1, 'failed': 1}
    rows = _rows(tmp_path, settings)
    failed = [r for r in rows.values() if r['status'] == 'failed']
    assert len(failed) == 1 and 'injected failure' in failed[0]['error']
    assert np.allclose([failed[0][a] for a in 'xyzab'], poison)
    assert {r['error'] for r in rows.values() if r['status'] != 'failed'} == {'1'}
    assert len({r['worker'] for r in rows.values() if r['status'] == 'ok'}) == 2
    ok = {k: dict(r, error=serial[1][k]['error']) for k, r in rows.items()
          if r['status'] != 'failed'}
    _assert_same(serial[1], ok)
    # a rerun computes the failed pose again, and nothing else
    again = []
    report = run_sweep(np.vstack([POSES, poison]), settings, tmp_path, serial=True,
                       progress=False, on_rows=again.extend)
    assert report.skipped == 6 and [r['status'] for r in again] == ['ok']
    assert np.allclose([again[0][a] for a in 'xyzab'], poison)


#: Ten more reachable poses for the interruption test: enough work left after the first pose's
#: file that the SIGINT always lands mid-run, even when a loaded machine delays the test's poll.
MORE_DEG = [(0.01 * i, 0.01 * i, 0.85, 0.0, 0.0) for i in range(1, 11)]


def test_interrupted_sweep_resumes_without_recomputing(settings, serial, tmp_path):
    """Ctrl-C stops a running sweep; the rerun skips every pose whose file was written."""
    poses_deg = POSES_DEG + MORE_DEG
    poses = np.array([[x, y, z, np.radians(a), np.radians(b)] for x, y, z, a, b in poses_deg])
    cmd = [sys.executable, '-m', 'pentapod_damper.sweep',
           *['--pose=' + ','.join(map(str, q)) for q in poses_deg], '--scenarios',
           ','.join(SCENARIOS), '--n-points', str(N_POINTS), '--out', str(tmp_path),
           '--workers', '2', '--no-plots', '--no-progress']
    proc = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            text=True, preexec_fn=sigint_as_in_a_terminal)
    results = tmp_path / 'results'
    deadline = time.monotonic() + 240
    while not list(results.glob('*.parquet')) and proc.poll() is None:   # first task done
        assert time.monotonic() < deadline, 'no task finished in time'
        time.sleep(0.05)
    proc.send_signal(signal.SIGINT)
    output = proc.communicate(timeout=120)[0]
    assert proc.returncode == 130, output
    assert 'run the same command again to resume' in output
    before = {p.name: p.stat().st_mtime_ns for p in results.glob('*.parquet')}
    assert 1 <= len(before) < len(poses), 'the sweep was not interrupted midway'
    done_keys = set(_rows(tmp_path, settings))
    computed = []
    report = run_sweep(poses, settings, tmp_path, serial=True, progress=False,
                       on_rows=computed.extend)
    assert report.skipped == len(before)
    assert {r['key'] for r in computed}.isdisjoint(done_keys)
    assert len(computed) == len(poses) - len(before)
    assert all(p.stat().st_mtime_ns == before[p.name] for p in results.glob('*.parquet')
               if p.name in before)
    rows = _rows(tmp_path, settings)
    assert len(rows) == len(poses)
    _assert_same(serial[1], {k: r for k, r in rows.items() if k in serial[1]})


def test_unreachable_pose_is_recorded_with_the_violated_limit(serial):
    row = next(r for r in serial[1].values() if r['status'] == 'unreachable')
    assert 'stroke_max' in row['error'] and np.isnan(row['peak_xx_open'] or np.nan)
    strut = int(row['error'].split(':')[0].split()[-1])
    machine = load_machine()
    layout = layout_from_params(machine)
    lengths = inverse_kinematics(layout, POSES[-1]).lengths
    assert lengths[strut - 1] > layout.stroke_max[strut - 1]


def test_failing_pose_in_the_serial_loop_is_recorded(settings, tmp_path, monkeypatch):
    real = compute_module.evaluate

    def evaluate(pose, shared):
        if pose[0] == 0.1:
            raise np.linalg.LinAlgError('singular matrix (injected)')
        return real(pose, shared)

    monkeypatch.setattr(compute_module, 'evaluate', evaluate)
    report = run_sweep(POSES[:3], settings, tmp_path, serial=True, progress=False)
    assert report.counts == {'ok': 2, 'failed': 1}
    assert report.errors == [(list(POSES[2]), 'LinAlgError: singular matrix (injected)')]


def test_share_and_pma_columns_equal_the_study_functions_on_the_full_plant(settings, serial):
    """P1 row against the study's continuous FRFs of the full reduced plant (all ports)."""
    row = next(r for r in serial[1].values() if np.allclose([r[a] for a in 'xyzab'], POSES[0]))
    plant = build_plant('P1')
    freq = np.linspace(*settings.freq[:2], N_POINTS)
    lo, hi = settings.band
    values = {}
    for name in ['baseline'] + SCENARIOS:
        dampers = continuous_dampers(scenario_laws(read_scenario(name).sections, 1 / 3000.0))
        for d in 'xyz':
            h = continuous_frf(plant, dampers, freq, f'tcp_displacement_{d}', f'tcp_force_{d}')
            values[(name, d)] = peak_and_rms(h, freq, lo, hi)
    for d in 'xyz':
        np.testing.assert_allclose(row[f'peak_{d}{d}_open'], values[('baseline', d)][0],
                                   rtol=1e-8)
        for k, kind in enumerate(('peak', 'rms')):
            share = improvement_share(values[('baseline', d)][k],
                                      values[('strut_damping_12', d)][k],
                                      values[('strut_damping_all', d)][k])
            np.testing.assert_allclose(row[f'share_{kind}_{d}{d}'], share, rtol=1e-7)
    w = 2 * np.pi * freq
    v = continuous_frf(plant, {'pma_force_x': 20000.0}, freq, 'pma_mount_velocity_x',
                       'tcp_force_x')
    band = (freq >= lo) & (freq <= hi)
    np.testing.assert_allclose(row['pma_force_x_pma_5kg'], (20000.0 * 10 * np.abs(v))[band].max(),
                               rtol=1e-8)
    stroke = 10 * np.abs(v) * np.sqrt(1 + (4000.0 / w) ** 2) / w
    np.testing.assert_allclose(row['pma_stroke_x_pma_5kg'], stroke[band].max(), rtol=1e-8)


def test_closed_loop_damping_of_an_uncoupled_mode_has_the_closed_form():
    """One mode in x, one in y; a TCP damper g in x: zeta = zeta0 + g phi^2 / (2 omega)."""
    omega, zeta, phi, g = np.array([2 * np.pi * 40, 2 * np.pi * 55]), 0.002, 0.08, 300.0
    names_in = ['tcp_force_x', 'tcp_force_y']
    names_out = ['tcp_displacement_x', 'tcp_displacement_y', 'tcp_velocity_x',
                 'tcp_velocity_y']
    b = np.array([[phi, 0.0], [0.0, phi]])
    c_disp = np.vstack([b.T, np.zeros((2, 2))])
    c_vel = np.vstack([np.zeros((2, 2)), b.T])
    plant = PlantModel(omega, np.full(2, zeta), b, c_disp, c_vel, np.zeros((4, 2)), names_in,
                       names_out, ['N'] * 2, ['m'] * 2 + ['m/s'] * 2, [''] * 2, [''] * 4)
    lam, vec = np.linalg.eig(damper_feedback(plant, {'tcp_force_x': g}).A)
    result = paired_damping(lam, vec, {'x': 0, 'y': 1})
    np.testing.assert_allclose(result['x'][0], zeta + g * phi ** 2 / (2 * omega[0]), rtol=1e-9)
    np.testing.assert_allclose(result['y'][0], zeta, rtol=1e-9)
    np.testing.assert_allclose(result['x'][1], omega[0] / (2 * np.pi), rtol=1e-9)


def test_pose_inputs_and_keys(tmp_path):
    poses = pose_input.grid('-0.1:0.1:3', '0:0.2:2', '0.85', '0', '0:10:2')
    assert poses.shape == (12, 5)
    assert np.allclose(poses[:3, 0], [-0.1, 0.0, 0.1]) and np.allclose(poses[3, :2], [-0.1, 0.2])
    assert np.allclose(poses[6:, 4], np.radians(10.0))
    csv = tmp_path / 'poses.csv'
    csv.write_text('x,y,z,a_deg,b_deg\n0.1,0,0.85,0,10\n0,0.2,0.9,5,0\n')
    assert np.allclose(pose_input.read_csv(csv)[0], [0.1, 0, 0.85, 0, np.radians(10)])
    csv.write_text('x,y,z,a_deg,b_deg\n0.1,0,0.85,0,10\n0,zero,0.9,5,0\n')
    with pytest.raises(ConfigError, match='row 3'):
        pose_input.read_csv(csv)
    with pytest.raises(ConfigError, match="z = '1:2'"):
        pose_input.parse_range('1:2', 'z')
    key = pose_input.pose_key(POSES[1], 'abc')
    assert key == pose_input.pose_key(POSES[1] + 1e-9, 'abc')
    assert key != pose_input.pose_key(POSES[1] + 1e-5, 'abc')
    assert key != pose_input.pose_key(POSES[1], 'abd')


def test_cli_names_bad_input(capsys, tmp_path):
    assert main(['--x=0:1', '--out', str(tmp_path), '--no-plots']) == 1
    assert "x = '0:1'" in capsys.readouterr().err
    assert main(['--pose', '0,0,0.85', '--out', str(tmp_path)]) == 1
    assert main(['--positions', 'P9', '--out', str(tmp_path)]) == 1
    assert 'P9' in capsys.readouterr().err


def test_maps_and_claim_summary_of_a_grid(settings, tmp_path):
    """Figures of a 3x3 slice with known shares; the claim counts follow from them."""
    store = ResultStore(tmp_path, columns(settings), settings.digest).open()
    shares = np.linspace(0.4, 1.0, 9)
    rows = []
    for i, (x, y) in enumerate((x, y) for y in (-0.1, 0, 0.1) for x in (-0.1, 0, 0.1)):
        row = {'key': f'k{i}', 'status': 'ok' if i != 4 else 'unreachable', 'x': x, 'y': y,
               'z': 0.85, 'a': 0.0, 'b': 0.0, 'finished_at': float(i),
               'frame_mode_f': 27.0 + i, 'strut_mode_f': 30.0 + i}
        for kind in ('peak', 'rms'):
            for dd in ('xx', 'yy', 'zz'):
                row[f'share_{kind}_{dd}'] = shares[i] if i != 4 else None
                row[f'{kind}_{dd}_open'] = 1e-6
        rows.append(row)
    store.write(rows)
    data = as_arrays(store.load())
    expected = int(np.sum(np.delete(shares, 4) >= 0.7))
    assert claim_fractions(data)[('peak', 'xx')] == (expected, 8)
    paths = [p.name for p in all_figures(store.load(), store.schema, tmp_path / 'fig',
                                          groups=('share',))]
    assert 'share_z0.850_a0.0_b0.0.png' in paths and 'claim_summary.png' in paths
    assert all((tmp_path / 'fig' / p).stat().st_size > 10000 for p in paths)


def test_docs_column_table_matches_the_columns(settings):
    """docs/sweep.md's column table names every column of a sweep, and nothing else."""
    text = (ROOT / 'docs' / 'sweep.md').read_text()
    table = text.split('<!-- columns:begin -->')[1].split('<!-- columns:end -->')[0]
    fields = {'dd': '(xx|yy|zz)', 'loop': '[a-z0-9_.]+', 'label': '[a-z0-9_.]+', 'a': '[xyz]',
              'tail': '(_x[0-9.]+)?'}
    patterns, units = [], {}
    for line in table.splitlines()[3:]:
        names, unit = line.split('|')[1:3]
        for name in re.findall(r'`([^`]+)`', names):
            regex = re.sub(r'\\\{(\w+)\\\}', lambda m: fields[m.group(1)], re.escape(name))
            patterns.append(re.compile(regex))
            units[regex] = unit.strip()
    doubled = make_settings(SCENARIOS, [1.0, 2.0], n_points=N_POINTS)
    cols = columns(settings) + columns(doubled)
    for name, _, unit, _ in cols:
        match = [p for p in patterns if p.fullmatch(name)]
        assert match, f'{name} is not in docs/sweep.md'
        assert units[match[0].pattern] == unit, name
    assert all(any(p.fullmatch(c[0]) for c in cols) for p in patterns)
