"""Spectrum windows solved side by side in window processes: the same modes, every one once."""
import multiprocessing
import os
from pathlib import Path
import signal
import subprocess
import sys
import time

import numpy as np
from numpy.testing import assert_allclose
import pytest
from test_modes_solver import chain_frequencies, fixed_free_chain

from fixtures.processes import sigint_as_in_a_terminal
from pentapod_sim.errors import ModalError
from pentapod_sim.modes import slicing, window_pool
from pentapod_sim.modes.solver import solve_modes
from pentapod_sim.modes.window_pool import (
    default_workers,
    MAX_DEFAULT_WORKERS,
    PARALLEL_MIN_DOF,
    WindowPool,
)

ROOT = Path(__file__).resolve().parents[1]


def _logging_pids(monkeypatch, path: Path) -> None:
    """Each window solve appends the id of the process that ran it to ``path``."""
    real = window_pool.window_eigs

    def logged(*args, **kwargs):
        with open(path, 'a') as f:
            f.write(f'{os.getpid()}\n')
        return real(*args, **kwargs)
    monkeypatch.setattr(window_pool, 'window_eigs', logged)


def test_windows_side_by_side_give_the_closed_form_modes(monkeypatch, tmp_path):
    n = 3000
    K, M = fixed_free_chain(n)
    exact = chain_frequencies(n)
    _logging_pids(monkeypatch, tmp_path / 'pids')
    res = solve_modes(K, M, n_modes=120, modes_per_window=25, workers=2)
    pids = set((tmp_path / 'pids').read_text().split())
    assert len(pids) == 2 and str(os.getpid()) not in pids   # two window processes did it
    assert res.stats['window_processes'] == 2 and res.stats['windows'] >= 4
    assert_allclose(res.frequencies, exact[:120], rtol=1e-9)
    assert_allclose(res.shapes.T @ (M @ res.shapes), np.eye(120), atol=1e-8)
    f_max = 0.5 * (exact[99] + exact[100])
    res = solve_modes(K, M, f_max=f_max, modes_per_window=25, workers=2)
    assert res.sturm_count == res.n_modes == 100
    assert_allclose(res.frequencies, exact[:100], rtol=1e-9)


@pytest.mark.parametrize(('stretch', 'what'), [(0.2, 'windows_unused'), (3.0, 'gap_windows')])
def test_windows_solved_ahead_at_bad_shifts_cost_time_not_modes(monkeypatch, stretch, what):
    """
    The shift of a window solved ahead is a guess; make it bad.

    Too close to the window before (0.2: it ends up below the cut it should continue from and
    must be dropped) or too far (3.0: a gap of uncounted modes below it, so a window must be
    solved in the gap).
    """
    real = slicing._edge_above

    def bad_guess(lam, sigma, target):
        return sigma + stretch * (real(lam, sigma, target) - sigma)
    monkeypatch.setattr(slicing, '_edge_above', bad_guess)
    n = 3000
    K, M = fixed_free_chain(n)
    res = solve_modes(K, M, n_modes=150, modes_per_window=20, workers=2)
    assert res.stats[what] >= 1
    assert_allclose(res.frequencies, chain_frequencies(n)[:150], rtol=1e-9)
    assert_allclose(res.shapes.T @ (M @ res.shapes), np.eye(150), atol=1e-8)


def test_a_window_process_that_dies_is_a_modal_error_not_a_hang(monkeypatch):
    real = window_pool.window_eigs

    def dies_above_the_first_window(K, M, factor, k, *args):
        if factor.count > 30:
            os._exit(3)   # as if the kernel's out-of-memory killer took it
        return real(K, M, factor, k, *args)
    monkeypatch.setattr(window_pool, 'window_eigs', dies_above_the_first_window)
    K, M = fixed_free_chain(3000)
    with pytest.raises(ModalError, match='window process ended without a result'):
        solve_modes(K, M, n_modes=120, modes_per_window=25, workers=2)


def test_a_window_not_needed_stops_when_the_pool_closes(monkeypatch, tmp_path):
    """Closing the pool abandons a window mid-solve instead of waiting a minute for it."""
    started = tmp_path / 'started'

    def slow(K, M, factor, k, method, tol, checkpoint=None):
        started.touch()
        for _ in range(6000):   # 60 s unless the checkpoint stops it
            checkpoint()
            time.sleep(0.01)
        return np.zeros(k), np.zeros((K.shape[0], k))
    monkeypatch.setattr(window_pool, 'window_eigs', slow)
    K, M = fixed_free_chain(1000)
    t0 = time.monotonic()
    with WindowPool(K, M, 'arpack', 1e-8, workers=2) as pool:
        future = pool.submit(1.0, 5)
        while not started.exists():   # the window process is inside the solve
            time.sleep(0.01)
    assert future.result() is None
    assert time.monotonic() - t0 < 30.0
    with pytest.raises(ModalError, match='abandoned'):
        pool.result(future)


_ORPHAN_SCRIPT = """
import os, sys, time
sys.path.insert(0, {test_dir!r})
from pentapod_sim import shutdown
from pentapod_sim.modes import window_pool
from pentapod_sim.modes.solver import solve_modes
from test_modes_solver import fixed_free_chain

def stuck(*args, **kwargs):
    with open({pids!r}, 'a') as f:
        f.write(f'{{os.getpid()}}\\n')
    time.sleep(600)

shutdown.install()   # as in a node: SIGTERM only records a stop request
window_pool.window_eigs = stuck
K, M = fixed_free_chain(2000)
solve_modes(K, M, n_modes=60, modes_per_window=12, workers=2)
"""


def _gone(pid: int, seconds: float) -> bool:
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            return True
        time.sleep(0.05)
    return False


def _survivors(pids: list[int]) -> list[int]:
    """The processes still alive 10 s on (killed then, so that none outlives the test)."""
    alive = [pid for pid in pids if not _gone(pid, 10.0)]
    for pid in alive:
        os.kill(pid, 9)
    return alive


def test_a_window_process_does_not_outlive_its_caller(tmp_path):
    """The caller killed by SIGKILL mid-solve: its window processes, busy or idle, end too."""
    pids = tmp_path / 'pids'
    script = _ORPHAN_SCRIPT.format(test_dir=str(Path(__file__).parent), pids=str(pids))
    caller = subprocess.Popen([sys.executable, '-c', script], cwd=ROOT)
    try:
        end = time.monotonic() + 60.0
        while not (pids.exists() and pids.read_text().strip()) and time.monotonic() < end:
            assert caller.poll() is None, 'the caller ended before its window started'
            time.sleep(0.05)
        busy = int(pids.read_text().split()[0])
        children = Path(f'/proc/{caller.pid}/task/{caller.pid}/children').read_text()
        windows = [int(pid) for pid in children.split()]
        assert busy in windows and len(windows) == 2
    finally:
        caller.kill()
        caller.wait()
    alive = _survivors(windows)
    assert not alive, f'window processes {alive} outlived their caller'


def test_ctrl_c_stops_the_modes_command_and_its_window_processes():
    """
    SIGINT to the process group, as a terminal's Ctrl-C: one line, exit 130, nothing left.

    The job (1000 modes, windows of 20: minutes) cannot end before the signal even when this
    test is starved of CPU after its second window: with 300 modes (28 s alone) a loaded
    suite once saw the command finish first and exit 0.
    """
    cmd = [sys.executable, '-m', 'pentapod_sim.cli.modes', '--position', 'P1',
           '--element-size', '0.004', '--n-modes', '1000', '--modes-per-window', '20',
           '--no-neuber', '--workers', '2', '--out', '/nonexistent/never-written']
    caller = subprocess.Popen(cmd, cwd=ROOT, stderr=subprocess.PIPE, text=True,
                              start_new_session=True, preexec_fn=sigint_as_in_a_terminal)
    try:
        err = ''
        while 'window 2:' not in err:   # the window processes are at work
            line = caller.stderr.readline()
            assert line, f'modes ended before its second window: {err}'
            err += line
        group = [int(pid) for pid in subprocess.run(
            ['pgrep', '-g', str(caller.pid)], capture_output=True, text=True).stdout.split()]
        assert len(group) == 3                     # the command and its 2 window processes
        os.killpg(caller.pid, signal.SIGINT)
        err += caller.stderr.read()
        assert caller.wait(timeout=30) == 130
    finally:
        if caller.poll() is None:
            os.killpg(caller.pid, signal.SIGKILL)
            caller.wait()
    assert err.rstrip().endswith('modes: stopped by SIGINT'), err[-2000:]
    assert 'Traceback' not in err, err[-2000:]
    alive = _survivors(group)
    assert not alive, f'processes {alive} outlived the command'


def test_default_workers_one_per_core_for_large_problems_only():
    cores = len(os.sched_getaffinity(0))
    code = ('from pentapod_sim.modes.window_pool import default_workers as d; '
            f'print(d({PARALLEL_MIN_DOF}), d({PARALLEL_MIN_DOF - 1}))')
    out = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                         check=True, cwd=ROOT).stdout.split()
    assert out == [str(min(cores, MAX_DEFAULT_WORKERS)), '1']
    # a pool's worker processes are daemonic and may not start window processes
    with multiprocessing.get_context('fork').Pool(1) as pool:
        assert pool.apply(default_workers, (10 * PARALLEL_MIN_DOF,)) == 1


def test_zero_workers_is_refused_by_name():
    K, M = fixed_free_chain(1000)
    with pytest.raises(ValueError, match='workers=0'):
        solve_modes(K, M, n_modes=20, workers=0)
