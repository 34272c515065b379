"""
The study's stages side by side on dask: order, overlap, the ROS lane, failure and Ctrl-C.

The races are made to happen: stages that must overlap wait on a barrier only two running
stages can pass; a stop arrives while stages are running.
"""
import dataclasses
from dataclasses import dataclass
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
from pentapod_damper.study.config import load_study_config
from pentapod_damper.study.pipeline import scenario_pma
from pentapod_damper.study.records import PositionModel
from pentapod_damper.study.schedule import compute, Graph, Interrupted, study_graph
from pentapod_sim import shutdown
from pentapod_sim.errors import RunError
from pentapod_sim.scenario.files import read_scenario
from pentapod_sim.sim.stability import check_loop, controller_of

ROOT = Path(__file__).resolve().parents[1]


pytestmark = pytest.mark.usefixtures('stop_handlers')   # stop signals recorded, as the study does


@dataclass
class Done:
    """A stage's record: its progress line names it."""

    name: str

    def describe(self) -> str:
        return f'stage {self.name}'


def _lines():
    lines = []
    return lines, lines.append


def _dependencies(graph) -> dict:
    """Key -> keys it waits for, of the dask graph of delayed stages."""
    from dask.core import get_dependencies
    dsk = dict(graph.__dask_graph__())
    return {key: get_dependencies(dsk, key) for key in dsk}


def test_independent_stages_overlap_and_dependents_wait():
    barrier = threading.Barrier(2, timeout=10.0)     # passes only if both run at once
    seen = []
    g = Graph()

    def meet(name):
        barrier.wait()
        return Done(name)
    a = g.add('s', 'a', meet, 'a')
    b = g.add('s', 'b', meet, 'b')
    c = g.add('t', 'c', lambda x, y: seen.append((x.name, y.name)) or Done('c'), a, b)
    lines, say = _lines()
    (value,), progress = compute([c], g.stage_of, 2, say)
    assert value == Done('c') and seen == [('a', 'b')]
    assert progress.started['t: c'] >= max(progress.finished['s: a'], progress.finished['s: b'])
    assert sorted(lines) == ['(1/3) stage a', '(2/3) stage b', '(3/3) stage c'] or \
        sorted(lines) == ['(1/3) stage b', '(2/3) stage a', '(3/3) stage c']
    span, busy, count = progress.timings()['s']
    assert count == 2 and span < busy            # the two overlapped


def test_two_stages_may_not_share_a_name():
    g = Graph()
    g.add('s', 'a', lambda: Done('a'))
    with pytest.raises(ValueError, match="two stages are named 's: a'"):
        g.add('s', 'a', lambda: Done('a'))


def test_the_lane_runs_one_testbed_run_at_a_time_beside_other_stages():
    lock = threading.Lock()
    running, peak = [0], [0]
    other = threading.Event()

    def testbed_run(name):
        with lock:
            running[0] += 1
            peak[0] = max(peak[0], running[0])
        other.wait(timeout=0.3)          # long enough for a second run to start
        with lock:
            running[0] -= 1
        return Done(name)

    g = Graph(lane=True)
    runs = [g.run('runs', f'r{i}', testbed_run, f'r{i}') for i in range(3)]
    cpu = g.add('cpu', 'work', lambda: other.wait(timeout=0.3) or time.sleep(0.5) or Done('c'))
    _, progress = compute([*runs, cpu], g.stage_of, 2, lambda line: None)
    assert peak[0] == 1
    # the analytic stage ran beside a testbed run
    assert progress.started['cpu: work'] < progress.finished['runs: r0']
    # without the lane the runs run side by side
    running[0] = peak[0] = 0
    free = Graph()
    runs = [free.run('runs', f'r{i}', testbed_run, f'r{i}') for i in range(2)]
    compute(runs, free.stage_of, 2, lambda line: None)
    assert peak[0] == 2


def test_a_failed_stage_stops_the_running_ones_and_starts_no_more():
    started = threading.Event()
    stopped = []

    def long_run():                      # like a testbed run: ends early on a stop request
        started.set()
        end = time.monotonic() + 20.0
        while time.monotonic() < end and not shutdown.requested():
            time.sleep(0.01)
        stopped.append(shutdown.requested())
        return Done('long')

    def failing():
        started.wait(timeout=10.0)
        raise RunError('run P1_baseline failed (exit code 1): error: boom')

    never = []
    g = Graph()
    long = g.add('runs', 'long', long_run)
    fail = g.add('runs', 'fail', failing)
    later = g.add('runs', 'later', lambda *_: never.append(1), fail)
    t0 = time.monotonic()
    with pytest.raises(RunError, match='boom'):
        compute([long, later], g.stage_of, 2, lambda line: None)
    assert stopped == [True] and never == []
    assert time.monotonic() - t0 < 10.0


def test_a_signal_stops_the_stages_with_the_shells_exit_code():
    def interrupt():                     # Ctrl-C arrives while stages run
        os.kill(os.getpid(), signal.SIGINT)
        time.sleep(0.5)
        return Done('a')

    never = []
    g = Graph()
    a = g.add('s', 'a', interrupt)
    b = g.add('s', 'b', lambda: time.sleep(0.5) or Done('b'))
    c = g.add('s', 'c', lambda _: never.append(1) or Done('c'), a)
    with pytest.raises(Interrupted) as err:
        compute([b, c], g.stage_of, 2, lambda line: None)
    assert err.value.code == 130 and never == []


def test_the_study_graph_has_every_stage_and_its_inputs(tmp_path):
    """One analytic stage and one FRF run per pair; damping, step runs where the file says."""
    cfg = load_study_config()
    freq = np.linspace(1.0, 10.0, 3)
    g = study_graph(cfg, tmp_path, freq)
    pairs = [(p, s) for p in cfg.positions for s in cfg.scenarios]
    assert list(g.analytic) == pairs and list(g.frf_runs) == pairs
    assert list(g.damping_runs) == [(p, s) for p, s in pairs if s in cfg.damping_scenarios]
    pma = [s for s in cfg.scenarios if scenario_pma(s) is not None]
    assert pma == ['pma_5kg', 'pma_1kg'] and list(g.step_runs) == list(g.pma) == pma
    deps = _dependencies(g.frf_runs[pairs[0]])['FRF and step runs: P1 baseline']
    # the run needs its model and analytic results; runs may go side by side: none waits for
    # another
    assert deps == {'models: P1', 'analytic FRFs, checks and poles: P1 baseline'}
    analytic_only = study_graph(cfg, tmp_path, freq, runs=False)
    assert not analytic_only.frf_runs and not analytic_only.damping_runs
    assert not analytic_only.step_runs and list(analytic_only.pma) == pma


def test_on_the_lane_every_testbed_run_waits_for_the_one_before(tmp_path):
    cfg = load_study_config()
    g = study_graph(cfg, tmp_path, np.linspace(1.0, 10.0, 3), lane=True)
    runs = [*g.damping_runs.values(), *g.frf_runs.values(), *g.step_runs.values()]
    deps = _dependencies(runs[-1])
    keys = [r.key for r in runs]
    for before, after in zip(keys, keys[1:]):
        assert before in deps[after], (before, after)
    assert len(keys) == 8 + 18 + 2


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
    model = PositionModel('demo', plant, tmp_path / 'p.npz', plant.content_hash(), check)
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


def test_the_ready_stage_with_the_longest_chain_starts_first():
    """
    Critical-path order: after a model, its damping run (22 s) before four lobes (0.5 s each).

    dask's own order (depth first) would run the lobes and their table first, leaving the
    long run to the end.
    """
    order = []
    g = Graph()

    def stage(name, *_):
        order.append(name)
        return Done(name)
    model = g.add('models', 'm', stage, 'm')
    lobes = [g.add('stability lobes', f's{i}', stage, f's{i}', model) for i in range(4)]
    run = g.add('damping runs', 'd', stage, 'd', model)
    table = g.add('stability lobes', 'table', stage, 'table', *lobes)
    compute([table, run], g.stage_of, 1, lambda line: None)
    assert order[:2] == ['m', 'd'] and order[-1] == 'table'
