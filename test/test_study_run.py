"""
A recorded testbed run measures what the model predicts (real processes, DDS on localhost).

Plant, exciter, a TCP damper and the recorder run in lockstep as separate processes; the FRF
measured from the bag at every multisine line must match the analytic FRF of the sampled
closed loop within 1 dB (0.1 %-damped modes: the run starts at the loop's periodic steady
state), and the bag must hold every step exactly once.
"""
import os
from pathlib import Path

import numpy as np
import pytest

from fixtures.demo_model import demo_model
from pentapod_damper.scenario_laws import scenario_laws
from pentapod_damper.study import damping, measured_damping, pipeline
from pentapod_damper.study.config import load_study_config
from pentapod_damper.study.records import PositionModel
from pentapod_damper.study.runs import damping_excitation, run_on_testbed
from pentapod_sim.scenario.files import read_scenario

pytestmark = [pytest.mark.ros, pytest.mark.slow]


@pytest.fixture()
def ros_env(monkeypatch):
    # the session's reserved domain and LOCALHOST discovery (conftest.py); the nodes import
    # this checkout
    assert os.environ.get('ROS_DOMAIN_ID') and os.environ.get('ROS_AUTOMATIC_DISCOVERY_RANGE')
    monkeypatch.setenv('PYTHONPATH', os.pathsep.join(
        [str(Path(__file__).resolve().parents[1]), os.environ.get('PYTHONPATH', '')]))


def test_recorded_frf_matches_the_sampled_loop_within_1_db_at_every_line(tmp_path, ros_env):
    """
    From the periodic steady state: every line within 1 dB, the periods repeat; from rest not.

    The baseline (no law: the plant's modes at 0.1 %) and the TCP damper (a law with states
    that start at rest) on a small plant.
    """
    cfg = load_study_config(sample_rate=2000.0, period=0.5, f_max=300.0, band=(2.0, 300.0))
    plant = demo_model(n_modes=5, f_min=25.0, f_max=220.0, zeta=0.001, feedthrough=2e-9,
                       seed=3)
    model_file = plant.save(tmp_path / 'plant.npz')
    model = PositionModel('demo', plant, model_file, plant.content_hash())
    steps = int(round(cfg.duration * cfg.sample_rate))
    for scenario in ('baseline', 'tcp_damping'):
        ana = pipeline.scenario_analytic(model, scenario, cfg, np.linspace(1, 300, 50))
        starts = [pipeline.steady_start(cfg, ana)] + ([None] if scenario == 'baseline' else [])
        for start in starts:
            run = run_on_testbed(scenario, 'P1', model_file, model.model_hash, cfg, tmp_path,
                                 timeout=240.0, composed=False, initial_state=start)
            mes = pipeline.measure(run, cfg)
            assert mes.n_messages == {'/pentapod/tcp_state': steps,
                                      '/pentapod/excitation': steps}
            np.testing.assert_allclose(mes.freq, np.arange(1, 151) / 0.5)   # every line
            worst, peak = pipeline.deviation_db(mes, ana.discrete, 'tcp_displacement_x')
            if start is None:               # from rest the check can fail: the modes ring
                assert worst > 1.0 and mes.periodicity > 1e-3, (scenario, worst)
                continue
            assert worst < 1.0, f'{scenario}: measured FRF deviates {worst:.2f} dB'
            # the periods repeat: what is left of the laws' start transient after one period
            assert abs(peak) < 1.0 and mes.periodicity < 1e-4, (scenario, peak, mes.periodicity)


@pytest.mark.parametrize('start', ['rest', 'steady'])
def test_damping_identified_from_a_recorded_run_matches_the_sampled_loop_poles(tmp_path,
                                                                                ros_env, start):
    """
    A multisine damping run with a TCP damper (composed) identifies the sampled-loop poles.

    From rest it settles for the decay times of the slowest strong mode; from the loop's
    periodic steady state (the study's default, ``damping.start``) one period settles the
    law's own start.

    Every dominant mode's identified damping ratio lies within 5 % and its frequency within
    0.1 % of the analytic sampled-loop pole, its identified peak within 1 dB of the analytic
    sampled-loop FRF's.
    """
    cfg = load_study_config(sample_rate=2000.0)
    plant = demo_model(n_modes=5, f_min=25.0, f_max=180.0, zeta=0.002, input_scale=0.01,
                       seed=3)
    model_file = plant.save(tmp_path / 'plant.npz')
    dt = cfg.dt
    laws = scenario_laws(read_scenario('tcp_damping').sections, dt)
    rows = damping.scenario_rows(plant, 'demo', 'tcp_damping', dt)
    xx = [r for r in rows if r.direction == 'xx']
    assert xx and max(r.sampled_zeta for r in xx) > 2 * 0.002     # the damper adds damping
    settle = damping.settling_time(measured_damping.settle_rows(plant, laws, dt, 'x'),
                                   cfg.damping_time_constants)
    exciter = damping_excitation(cfg, settle)
    assert exciter['settle_periods'] * cfg.damping_period >= settle
    initial = None
    if start == 'steady':
        model = PositionModel('demo', plant, model_file, plant.content_hash())
        ana = pipeline.scenario_analytic(model, 'tcp_damping', cfg, np.linspace(1, 300, 50))
        exciter = damping_excitation(cfg, cfg.damping_period)
        assert exciter['settle_periods'] == 1
        initial = pipeline.steady_start(cfg, ana, exciter)
    run = run_on_testbed('tcp_damping', 'P1', model_file, plant.content_hash(), cfg, tmp_path,
                         kind='damping', exciter=exciter, timeout=300.0, initial_state=initial)
    ident = measured_damping.identify_run(run.bag, 'x', cfg.damping_band)
    compared = measured_damping.compare(rows, ident, plant, laws, dt, 'x')
    assert len(compared) == len(xx)
    for r in compared:
        assert abs(r.zeta_error) < 0.05, r
        assert abs(r.freq_error) < 1e-3, r
        assert abs(r.peak_error_db) < 1.0, r
