"""
The drives' rows recorded: identified damping = the poles of the loop *with the rotors*.

HAC-LAC (IFF inside the feed drives' position loops) runs in the damper node on a small plant
with drive ports whose plant node steps the drives' rotors (plant parameter ``drives``), the
way ``python -m pentapod_damper.design --record`` records the table's drives rows: a scenario
file written by the table's own writer, the study's damping stage (periodic steady state of
the loop with the rotors, multisine, pLSCF + LSFD). Every dominant mode's identified damping
must match the sampled loop's pole of the plant with its drives' rotors and the cascade
within the recorded-run tolerances. If the record path built its loop without the rotors
(the locked links), it could not close the cascade on the motor ports at all.
"""
import os
from pathlib import Path

import numpy as np
import pytest

from fixtures.drives_plant import drives_plant, OUTPUTS
from pentapod_damper.design.recorded import record_law, within_tolerances
from pentapod_damper.design.scenarios import scenario_text
from pentapod_damper.study import stages
from pentapod_damper.study.config import load_study_config
from pentapod_damper.study.records import PositionModel
from pentapod_sim.analysis.bag.reader import open_bag
from pentapod_sim.plant.drives import DrivenPlant

pytestmark = [pytest.mark.ros, pytest.mark.slow]

ZETA = 0.001
#: HAC-LAC of test_hac_lac_run.py on all five struts.
PARAMS = {'drive_struts': [1, 2, 3, 4, 5], 'drive_file': 'drives.yaml',
          'drive_iff_gain': 150.0, 'drive_iff_omega': 2.3, 'filter_order': 2,
          'bandwidth_hz': 500.0}


@pytest.fixture()
def ros_env(monkeypatch):
    # the session's reserved domain and LOCALHOST discovery (conftest.py); the nodes import
    # this checkout
    assert os.environ.get('ROS_DOMAIN_ID') and os.environ.get('ROS_AUTOMATIC_DISCOVERY_RANGE')
    monkeypatch.setenv('PYTHONPATH', os.pathsep.join(
        [str(Path(__file__).resolve().parents[1]), os.environ.get('PYTHONPATH', '')]))


def test_hac_lac_recorded_damping_matches_the_loop_with_the_drives(tmp_path, ros_env):
    cfg = load_study_config(sample_rate=5000.0)
    # the 12 lowest modes (32-60 Hz), with every TCP displacement (the study's directions)
    outputs = OUTPUTS[:1] + ['tcp_displacement_y', 'tcp_displacement_z'] + OUTPUTS[1:]
    plant = drives_plant(ZETA, n_modes=12, outputs=outputs)[1]
    model_file = plant.save(tmp_path / 'plant.npz')
    model = PositionModel('P1', plant, model_file, plant.content_hash())
    record = {'law': 'IFF + position loop (HAC-LAC)', 'position': 'P1', 'direction': 'x',
              'sample_rate_hz': '5000.0', 'peak_reduction': 'nan', 'static_ratio': 'nan',
              'check_margin': 'nan', 'check_margin_extra_delay': 'nan', 'delay_steps': '0'}
    scenario = tmp_path / 'hac_lac_demo.yaml'
    scenario.write_text(scenario_text(record, PARAMS))
    compared, exciter, run = record_law(cfg, model, scenario, tmp_path, print)
    assert run.steps == round(exciter['duration'] * cfg.sample_rate)
    drives = open_bag(run.bag).custom_data['pentapod_start.drives']
    assert drives.endswith('drives.yaml on struts [1, 2, 3, 4, 5]'), drives
    assert len(compared) == 3
    for m in compared:
        assert within_tolerances(m.zeta_error, m.freq_error, m.peak_error_db), m
    # the drives damp: a mode's damping far from the plant's own, in the run and the poles
    assert max(m.analytic.sampled_zeta for m in compared) > 2 * ZETA
    assert max(m.measured_zeta for m in compared) > 2 * ZETA


def test_the_record_path_closes_the_loop_on_the_plant_with_the_rotors(tmp_path):
    """The analytic side of the record path: the loop on the DrivenPlant the node steps."""
    cfg = load_study_config(sample_rate=5000.0)
    outputs = OUTPUTS[:1] + ['tcp_displacement_y', 'tcp_displacement_z'] + OUTPUTS[1:]
    plant = drives_plant(ZETA, n_modes=12, outputs=outputs)[1]
    model = PositionModel('P1', plant, plant.save(tmp_path / 'plant.npz'), plant.content_hash())
    record = {'law': 'feed drives alone (position loops)', 'position': 'P1', 'direction': 'x',
              'sample_rate_hz': '5000.0', 'peak_reduction': 'nan', 'static_ratio': 'nan',
              'check_margin': 'nan', 'check_margin_extra_delay': 'nan', 'delay_steps': '0'}
    scenario = tmp_path / 'drives_demo.yaml'
    scenario.write_text(scenario_text(record, {'drive_struts': [1, 2, 3, 4, 5],
                                               'drive_file': 'drives.yaml'}))
    ana = stages.analyse_scenario(cfg, np.linspace(1.0, 200.0, 50), model, str(scenario),
                                  damping_run=True)
    assert isinstance(ana.plant, DrivenPlant) and ana.plant.plant is plant
    assert ana.sampled is not None and ana.sampled.core.n_states == 2 * 12 + 3 * 5
    assert ana.modes and all(r.sampled_mac > 0.9 for r in ana.modes)
