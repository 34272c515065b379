"""
A strut law with dynamics of its own, recorded on the testbed: identified damping = loop poles.

Lag displacement feedback on the bending ports of struts 1 and 2 (a first-order lag, a
negative stiffness below its corner) runs in the damper node in lockstep on a small demo
plant, the way ``python -m pentapod_damper.design --record`` runs the damper table's laws: a
scenario file written by the table's own writer, the study's damping stage (multisine,
settled, averaged, pLSCF + LSFD). Every dominant mode's identified damping ratio must match
the sampled loop's pole of the law's linear model (its lag, hold and delay) within the
recorded-run tolerances; the continuous loop of the same law differs by more than the
tolerance on the first mode, so a reference without the sampling could not pass.
"""
import os
from pathlib import Path

import numpy as np
import pytest

from fixtures.demo_model import demo_model
from pentapod_damper.design.recorded import record_law, within_tolerances, ZETA_TOLERANCE
from pentapod_damper.design.scenarios import scenario_text
from pentapod_damper.study.config import load_study_config
from pentapod_damper.study.records import PositionModel
from pentapod_sim.plant.ports import collocated_output

pytestmark = [pytest.mark.ros, pytest.mark.slow]

PORTS = [f'strut{i}_bending_moment_{k}' for i in (1, 2) for k in (2, 3)]


@pytest.fixture()
def ros_env(monkeypatch):
    # the session's reserved domain and LOCALHOST discovery (conftest.py); the nodes import
    # this checkout
    assert os.environ.get('ROS_DOMAIN_ID') and os.environ.get('ROS_AUTOMATIC_DISCOVERY_RANGE')
    monkeypatch.setenv('PYTHONPATH', os.pathsep.join(
        [str(Path(__file__).resolve().parents[1]), os.environ.get('PYTHONPATH', '')]))


def _static_port_gains(plant) -> list[float]:
    """Static collocated compliance G_ii(0) of each bending port [rad/(N m)]."""
    a, b, c, d = plant.state_matrices()
    out = []
    for port in PORTS:
        o = plant.output_names.index(collocated_output(port, 'displacement'))
        i = plant.input_names.index(port)
        out.append(float(c[o] @ np.linalg.solve(-a, b[:, i]) + d[o, i]))
    return out


def test_lag_law_recorded_damping_matches_the_sampled_loop_poles(tmp_path, ros_env):
    cfg = load_study_config(sample_rate=2000.0)
    plant = demo_model(n_modes=5, f_min=25.0, f_max=180.0, zeta=0.002, input_scale=0.01,
                       seed=3)
    model_file = plant.save(tmp_path / 'plant.npz')
    model = PositionModel('P1', plant, model_file, plant.content_hash())
    # K = 0.1 of each port's own static stiffness 1 / G_ii(0), corner 60 Hz
    record = {'law': 'lag displacement, bending', 'position': 'P1', 'direction': 'x',
              'sample_rate_hz': '2000.0', 'peak_reduction': 'nan', 'static_ratio': 'nan',
              'check_margin': 'nan', 'check_margin_extra_delay': 'nan', 'delay_steps': '0'}
    params = {'lag_struts': [1, 2], 'lag_port': 'bending',
              'lag_stiffness': [0.1 / g for g in _static_port_gains(plant)],
              'lag_corner_hz': 60.0}
    scenario = tmp_path / 'lag_bending_demo.yaml'
    scenario.write_text(scenario_text(record, params))
    compared, exciter, run = record_law(cfg, model, scenario, tmp_path, print)
    assert run.steps == round(exciter['duration'] * cfg.sample_rate)
    assert len(compared) == 3
    sampled = [m.analytic.sampled_zeta for m in compared]
    assert max(sampled) > 10 * 0.002                      # the law damps
    for m in compared:
        assert within_tolerances(m.zeta_error, m.freq_error, m.peak_error_db), m
    # the sampling matters: the continuous loop's damping misses the tolerance somewhere
    assert max(abs(m.analytic.continuous_zeta / m.analytic.sampled_zeta - 1)
               for m in compared) > ZETA_TOLERANCE
