"""
Bounded work before step 0: the truncation check's size, its progress, and stopping it.

``sample_rate`` 1e6 Hz (inside the parameter's range) once made the plant solve every FE mode
below 2 MHz (all 3060 of the default mesh) and their loop's eigenvalues before step 0, for
minutes and deaf to SIGINT. Now a cut-off or a mode count above the documented bounds is
refused at once with one line, the build reports progress and stops at the next slice.
"""
import signal
import time

import numpy as np
import pytest

from fixtures.stopping import stop_handlers  # noqa: F401  (a fixture)
from pentapod_sim.errors import ConfigError
from pentapod_sim.fe.assembly import build_model
from pentapod_sim.fe.machine_data import load_machine
from pentapod_sim.modes.solver import solve_modes
from pentapod_sim.plant import check_model
from pentapod_sim.plant.check_model import (
    check_f_max,
    check_mode_count,
    check_model_from_fe,
    CheckStopped,
    MAX_CHECK_F_MAX,
    MAX_CHECK_MODES,
)
from pentapod_sim.plant.config import load_reduction_config
from pentapod_sim.scenario.files import dump_params
from pentapod_sim.sim import stability


@pytest.fixture(scope='module')
def fe():
    return build_model(load_machine(), 'P2')


def test_a_cut_off_above_the_bound_is_refused_naming_the_sample_rate():
    with pytest.raises(ConfigError) as err:
        check_f_max(1.0e6)
    text = str(err.value)
    assert '\n' not in text and 'sample_rate = 1e+06 Hz' in text and '2e+06 Hz' in text
    assert f'{MAX_CHECK_F_MAX:g} Hz' in text and 'loop_check: off' in text
    with pytest.raises(ConfigError, match='check f_min = 30000 Hz'):
        check_f_max(1000.0, 30000.0)
    assert check_f_max(MAX_CHECK_F_MAX / 2) == MAX_CHECK_F_MAX      # the bound itself passes
    assert check_f_max(5000.0) == 10000.0


def test_the_mode_count_is_the_solvers_and_too_many_modes_are_refused(fe):
    """Sturm count against the modes actually solved; above the bound: one line, no solve."""
    modes = solve_modes(fe.K, fe.M, f_max=1500.0)
    assert check_mode_count(fe, 1500.0) == modes.n_modes > 0
    start = time.monotonic()
    with pytest.raises(ConfigError) as err:       # 2475 modes below 20 kHz (default mesh)
        check_mode_count(fe, 20000.0)
    assert time.monotonic() - start < 2.0
    text = str(err.value)
    count = int(text.split('has ')[1].split()[0])
    assert count > MAX_CHECK_MODES and '20000 Hz' in text and '\n' not in text
    assert count == check_model.sturm_count(fe.K, fe.M, (2 * np.pi * 20000.0) ** 2)


def test_a_build_reports_progress_past_a_second_and_stops_when_asked(fe, monkeypatch):
    """The check model of 10 kHz (1425 modes) takes seconds: progress once a second, then stop."""
    messages = []
    monkeypatch.setattr(check_model, 'PROGRESS_PERIOD', 0.3)
    start = time.monotonic()
    with pytest.raises(CheckStopped):
        check_model_from_fe(fe, load_reduction_config(), 10000.0, messages.append,
                            stop=lambda: any('modes below 10000 Hz solved' in m
                                             for m in messages))
    assert time.monotonic() - start < 30.0
    solved = [m for m in messages if 'solved' in m]
    assert len(solved) == 1 and solved[0].endswith('modes below 10000 Hz solved'), messages
    found, _, wanted = solved[0].split()[:3]
    assert 0 < int(found) < 1425 and int(wanted) == 1425, solved


def test_long_eigenvalue_problems_report_their_time(monkeypatch):
    monkeypatch.setattr(stability, 'PROGRESS_FIRST', 0.0)
    monkeypatch.setattr(stability, 'PROGRESS_PERIOD', 0.01)
    matrix = np.random.default_rng(1).normal(size=(300, 300)) / 40.0
    messages = []
    radius, _ = stability.spectral_radius(matrix, 1e-3, messages.append)
    assert radius == pytest.approx(np.abs(np.linalg.eigvals(matrix)).max(), rel=1e-12)
    assert messages and 'eigenvalues of the sampled loop (300 states)' in messages[0]
    with pytest.raises(np.linalg.LinAlgError):          # the worker's error reaches the caller
        stability.spectral_radius(np.full((3, 4), np.nan), 1e-3, messages.append)


# -- with ROS: the plant node ------------------------------------------------------------------
def real_scenario(tmp_path, rate: float, steps: int = 100):
    """Plant at P2 (cached in the test's folder), exciter, TCP damper: a loop to check."""
    doc = {'/**': {'ros__parameters': {'sample_rate': rate}},
           'exciter': {'ros__parameters': {'kind': 'impulse', 'amplitude': 10.0}},
           'damper': {'ros__parameters': {'tcp_directions': ['x'], 'tcp_gain': 100.0}},
           'plant': {'ros__parameters': {
               'position': 'P2', 'model_cache_dir': str(tmp_path / 'models'), 'steps': steps,
               'sources': ['exciter', 'damper'], 'loop_check': 'warn',
               'startup_timeout': 120.0}}}
    path = tmp_path / 'scenario.yaml'
    path.write_text(dump_params(doc))
    return path


@pytest.mark.ros
@pytest.mark.slow
def test_a_huge_sample_rate_is_refused_before_any_work(tmp_path):
    """sample_rate 1e6: one line naming it, within the time of building the plant itself."""
    from test_stopping import Runner
    run = Runner(real_scenario(tmp_path, 1.0e6), tmp_path, '--timeout', '200')
    try:
        code = run.proc.wait(timeout=90)
    except Exception:
        run.kill_all()
        pytest.fail(f'still running after 90 s:\n{run.text()}')
    out = run.text()
    assert code == 1, out
    lines = [x for x in out.splitlines() if x.startswith('error: truncation check')]
    assert len(lines) == 1 and 'sample_rate = 1e+06 Hz' in lines[0], out
    assert 'Traceback' not in out and 'modes below 2e+06 Hz solved' not in out
    assert not list((tmp_path / 'models').glob('check_*'))


def _sigint_after(run, *lines: str) -> tuple[int, float, str]:
    """SIGINT to a runner once its output showed ``lines`` (in order): exit code, s, output."""
    try:
        for line in lines:
            run.wait_for(line, timeout=180)
        sent = time.monotonic()
        run.proc.send_signal(signal.SIGINT)
        code = run.proc.wait(timeout=30)
        return code, time.monotonic() - sent, run.text()
    finally:
        run.kill_all()


@pytest.mark.ros
@pytest.mark.slow
def test_sigint_during_the_check_model_build_stops_the_plant_at_once(tmp_path):
    """5 kHz: the 10 kHz check model (seconds to build) reports progress; SIGINT ends it."""
    from test_stopping import Runner
    run = Runner(real_scenario(tmp_path, 5000.0), tmp_path, '--timeout', '300')
    code, took, out = _sigint_after(run, 'building the check model of P2',
                                    'modes below 10000 Hz solved')      # progress
    assert code == 130, out
    assert took < 3.0, (took, out)              # the runner's SIGKILL would come after 5 s
    assert 'stopped by SIGINT' in out and 'killed' not in out, out
    assert 'eigenvalues of the sampled loop' not in out and 'step 0' not in out
    assert not list((tmp_path / 'models').glob('check_*'))


@pytest.mark.ros
@pytest.mark.slow
def test_sigint_during_the_loops_eigenvalues_ends_a_composed_run_cleanly(tmp_path):
    """
    Ctrl-C while the composed plant solves its loop's eigenvalues: exit 130, not SIGSEGV.

    The signal comes once the eigenvalue problem has run for a second (its progress line), so
    it is still inside LAPACK when the process ends: the race of the old end, where Python's
    finalisation ran under that thread and killed 3 of 4 such runs with SIGSEGV. Three runs
    (the check model is built by the first and loaded by the others); each must end within the
    runner's grace time and say it exited with the check still running.
    """
    from test_stopping import Runner
    scenario = real_scenario(tmp_path, 5000.0)
    for attempt in range(3):
        run = Runner(scenario, tmp_path, '--composed', '--timeout', '300')
        code, took, out = _sigint_after(run, 'eigenvalues of the sampled loop')
        assert code == 130, (attempt, out)
        assert 'killed' not in out and 'SIGSEGV' not in out, (attempt, out)
        assert 'exiting with truncation check still running' in out, (attempt, out)  # the race
        assert took < 4.0, (attempt, took, out)     # the runner's SIGKILL would come after 5 s
        assert 'step 0' not in out and not list((tmp_path / 'models').glob('loop_check_*'))
