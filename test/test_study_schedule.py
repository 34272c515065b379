"""
The study's pieces side by side: order, overlap, lanes, failure and Ctrl-C; shared loop work.

The races are made to happen: pieces that must overlap wait on a barrier only two running
pieces can pass; a stop arrives while pieces are running.
"""
import dataclasses
import os
from pathlib import Path
import signal
import subprocess
import sys
import threading
import time

import numpy as np
import pytest

from fixtures.demo_model import demo_model
from fixtures.stopping import stop_handlers  # noqa: F401  (a fixture)
from pentapod_damper.scenario_laws import scenario_laws
from pentapod_damper.study import damping, measured_damping, pipeline
from pentapod_damper.study.analytic import discrete_frf, sampled_loop, SampledPairFrf
from pentapod_damper.study.schedule import Interrupted, Piece, run_pieces
from pentapod_sim import shutdown
from pentapod_sim.errors import RunError
from pentapod_sim.scenario.files import read_scenario
from pentapod_sim.sim.stability import check_loop, controller_of

ROOT = Path(__file__).resolve().parents[1]


pytestmark = pytest.mark.usefixtures('stop_handlers')   # stop signals recorded, as the study does


def _lines():
    lines = []
    return lines, lines.append


def test_independent_pieces_overlap_and_dependents_wait():
    barrier = threading.Barrier(2, timeout=10.0)     # passes only if both run at once
    seen = []
    pieces = [Piece('a', lambda: barrier.wait() or 'a', 's'),
              Piece('b', lambda: barrier.wait() or 'b', 's'),
              Piece('c', lambda: seen.append('c') or 'c', 't', after=('a', 'b'),
                    done=lambda r: f'piece {r}')]
    lines, say = _lines()
    schedule = run_pieces(pieces, 2, say)
    assert seen == ['c']
    assert schedule.started['c'] >= max(schedule.finished['a'], schedule.finished['b'])
    assert lines == ['(3/3) piece c']
    span, busy, count = schedule.stages()['s']
    assert count == 2 and span < busy            # the two overlapped


def test_ready_pieces_start_in_priority_order_and_done_may_add_pieces():
    order = []

    def piece(key, priority, done=None):
        return Piece(key, lambda: order.append(key), 's', priority=priority, done=done)
    added = piece('late', 0)
    pieces = [piece('low', 5), piece('high', 1), piece('mid', 3, done=lambda r: ('', [added]))]
    run_pieces(pieces, 1, lambda line: None)
    assert order == ['high', 'mid', 'late', 'low']


def test_a_lane_limits_its_pieces_but_not_the_others():
    lock = threading.Lock()
    running, peak = [0], [0]
    other = threading.Event()

    def in_lane():
        with lock:
            running[0] += 1
            peak[0] = max(peak[0], running[0])
        other.wait(timeout=0.3)          # long enough for a second lane piece to start
        with lock:
            running[0] -= 1

    pieces = [Piece(f'ros{i}', in_lane, 'runs', lane='ros') for i in range(3)]
    pieces.append(Piece('cpu', lambda: other.wait(timeout=0.3) or time.sleep(0.5), 'cpu'))
    schedule = run_pieces(pieces, 2, lambda line: None, lanes={'ros': 1})
    assert peak[0] == 1
    # the other piece ran beside a lane piece
    assert schedule.started['cpu'] < schedule.finished['ros0']


def test_a_failed_piece_stops_the_running_ones_and_starts_no_more():
    started = threading.Event()
    stopped = []

    def long_run():                      # like a testbed run: ends early on a stop request
        started.set()
        end = time.monotonic() + 20.0
        while time.monotonic() < end and not shutdown.requested():
            time.sleep(0.01)
        stopped.append(shutdown.requested())

    def failing():
        started.wait(timeout=10.0)
        raise RunError('run P1_baseline failed (exit code 1): error: boom')

    never = []
    pieces = [Piece('long', long_run, 'runs', priority=0),
              Piece('fail', failing, 'runs', priority=1),
              Piece('later', lambda: never.append(1), 'runs', priority=2)]
    t0 = time.monotonic()
    with pytest.raises(RunError, match='boom'):
        run_pieces(pieces, 2, lambda line: None)
    assert stopped == [True] and never == []
    assert time.monotonic() - t0 < 10.0


def test_a_signal_stops_the_pieces_with_the_shells_exit_code():
    def interrupt():                     # Ctrl-C arrives while pieces run
        os.kill(os.getpid(), signal.SIGINT)
        time.sleep(0.5)

    never = []
    pieces = [Piece('a', interrupt, 's'), Piece('b', lambda: time.sleep(0.5), 's'),
              Piece('c', lambda: never.append(1), 's', after=('a',))]
    with pytest.raises(Interrupted) as err:
        run_pieces(pieces, 2, lambda line: None)
    assert err.value.code == 130 and never == []


def test_unknown_dependency_is_named():
    with pytest.raises(ValueError, match='nothing'):
        run_pieces([Piece('a', lambda: None, 's', after=('nothing',))], 2, lambda line: None)


def test_ctrl_c_stops_the_study_without_a_traceback(tmp_path):
    """SIGINT to the study while its pieces run: one line, exit code 130, no traceback."""
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    proc = subprocess.Popen([sys.executable, '-m', 'pentapod_damper.study', '--analytic-only',
                             '--out', str(tmp_path / 'study')], cwd=tmp_path, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    first = proc.stdout.readline()          # the first finished piece: the others run
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=120)
    assert first.startswith('[study') and '(1/' in first, first + err
    assert proc.returncode == 130, err
    assert 'Traceback' not in err and 'study stopped: SIGINT received' in err
    assert not (tmp_path / 'study' / 'report.md').exists()


def test_shared_loop_gives_the_same_frfs_and_poles_bit_for_bit():
    """One eigen-decomposition and one pole computation per loop serve every consumer."""
    plant = demo_model(n_modes=6, f_min=20.0, f_max=300.0, zeta=0.02, feedthrough=1e-8)
    dt = 1.0 / 3000.0
    laws = scenario_laws(read_scenario('tcp_damping').sections, dt)
    loop = sampled_loop(plant, laws, dt)
    freq = np.linspace(5.0, 400.0, 50)
    fresh, shared = (discrete_frf(plant, laws, dt, freq, 'tcp_force_x', lp)
                     for lp in (None, loop))
    for port in fresh.outputs:
        np.testing.assert_array_equal(fresh.outputs[port], shared.outputs[port])
    pair = [SampledPairFrf(plant, laws, dt, 'tcp_displacement_x', 'tcp_force_x', lp)
            for lp in (None, loop)]
    np.testing.assert_array_equal(pair[0](freq), pair[1](freq))
    # and the pair FRF is the FRF of the whole loop
    np.testing.assert_allclose(pair[0](freq), fresh.outputs['tcp_displacement_x'],
                               rtol=1e-9, atol=0)
    poles = damping.loop_poles(plant, laws, dt)
    assert (damping.scenario_rows(plant, 'demo', 'tcp_damping', dt, laws=laws, poles=poles)
            == damping.scenario_rows(plant, 'demo', 'tcp_damping', dt))
    assert (measured_damping.settle_rows(plant, laws, dt, 'x', poles)
            == measured_damping.settle_rows(plant, laws, dt, 'x'))


def test_truncation_check_is_kept_per_loop_and_read_back_exactly(tmp_path, monkeypatch):
    plant = demo_model(n_modes=4, f_min=30.0, f_max=200.0, zeta=0.01, seed=3)
    check = demo_model(n_modes=12, f_min=30.0, f_max=2000.0, zeta=0.01, seed=3)
    model = pipeline.PositionModel('demo', plant, tmp_path / 'p.npz', plant.content_hash(),
                                   check)
    monkeypatch.setattr(pipeline, 'CHECK_CACHE', tmp_path / 'cache')
    dt = 1.0 / 3000.0
    laws = scenario_laws(read_scenario('tcp_damping').sections, dt)
    controllers = [controller_of(law) for law in laws]
    direct = check_loop(plant, check, controllers, dt, 'warn', 'first')
    first = pipeline.checked_loop(model, controllers, dt, 'warn', 'first')
    assert first == direct and len(list((tmp_path / 'cache').glob('*.json'))) == 1

    def no_solve(*args, **kwargs):
        raise AssertionError('the check was solved again')
    monkeypatch.setattr(pipeline, 'check_loop', no_solve)
    again = pipeline.checked_loop(model, controllers, dt, 'warn', 'again')
    assert again == dataclasses.replace(direct, label='again')     # every digit kept
    with pytest.raises(AssertionError, match='solved again'):       # another loop: solved
        pipeline.checked_loop(model, controllers, dt / 2, 'warn', 'faster')
