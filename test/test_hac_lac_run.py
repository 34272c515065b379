"""
HAC-LAC through ROS: the plant node with the feed drives' rotors and the damper node's cascade.

A lockstep run (composed and as separate processes) equals the offline loop of the same
discrete plant with drives and the same ``FeedDrives`` controller bit for bit, and so does a
multi-rate plant's (``substeps`` 4) against the offline multi-rate loop; the run status
and the bag say which drives the plant stepped; the start-up truncation check refuses a drive
delay that makes the loop unstable; a bad drives file is one error line naming it.
"""
import dataclasses
from pathlib import Path
import re

import numpy as np
import pytest

from fixtures.drives_plant import drives_plant
from pentapod_damper.scenario_laws import scenario_laws
from pentapod_sim import interface
from pentapod_sim.analysis.bag.reader import open_bag
from pentapod_sim.plant.drives import DriveSet, load_drives
from pentapod_sim.plant.model import PlantModel
from pentapod_sim.scenario.files import dump_params, read_scenario
from pentapod_sim.scenario.runner import run_scenario
from pentapod_sim.sim.closed_loop import excitation_matrix, simulate
from pentapod_sim.sim.excitation import Excitation, ExcitationSpec
from pentapod_sim.sim.multirate import MultiRatePlant

pytestmark = [pytest.mark.ros, pytest.mark.slow]

RATE, STEPS = 5000.0, 1500
EXCITER = {'kind': 'random', 'amplitude': 50.0, 'direction': [1.0, 0.0, 0.0],
           'f_start': 5.0, 'f_end': 400.0, 'duration': STEPS / RATE, 'seed': 3}
DAMPER = {'drive_struts': [1, 2, 3, 4, 5], 'drive_iff_gain': 150.0, 'drive_iff_omega': 2.3,
          'filter_order': 2, 'bandwidth_hz': 500.0}


def _scenario(tmp_path: Path, tag: str, drives: str = 'drives.yaml',
              record: bool = True, **plant_params) -> Path:
    model_file = tmp_path / 'model.npz'
    if not model_file.exists():
        drives_plant()[1].save(model_file)
    plant = {'model_file': str(model_file), 'steps': STEPS, 'sources': ['exciter', 'damper'],
             'drives': drives, 'loop_check': 'refuse',
             'output_file': str(tmp_path / f'trace_{tag}.npz'), 'startup_timeout': 60.0,
             **plant_params}
    doc = {'/**': {'ros__parameters': {'sample_rate': RATE}},
           'exciter': {'ros__parameters': dict(EXCITER)},
           'damper': {'ros__parameters': dict(DAMPER, drive_file=drives)},
           'plant': {'ros__parameters': plant}}
    if record:
        plant['wait_for_subscribers'] = ['recorder']
        doc['recorder'] = {'ros__parameters': {'output_dir': str(tmp_path / 'bags'),
                                               'bag_name': tag}}
    path = tmp_path / f'scenario_{tag}.yaml'
    path.write_text(dump_params(doc))
    return path


def test_lockstep_hac_lac_run_is_the_offline_loop(tmp_path):
    traces = {}
    for tag, composed in (('composed', True), ('separate', False)):
        path = _scenario(tmp_path, tag)
        assert run_scenario(path, {}, 300.0, log_dir=tmp_path / f'logs_{tag}',
                            composed=composed) == 0
        traces[tag] = dict(np.load(tmp_path / f'trace_{tag}.npz'))
        bag = open_bag(tmp_path / 'bags' / tag)
        drives = bag.custom_data['pentapod_start.drives']
        assert drives.endswith('drives.yaml on struts [1, 2, 3, 4, 5]'), drives
        assert bag.topic(interface.STRUT_STATES).count == STEPS
        # the motor ports on their topics: the encoder beside the drive joint, the command
        # on the damper's force topic
        trace = traces[tag]
        names = [list(trace['output_names']), list(trace['input_names'])]
        for i in (1, 5):
            for field in ('position', 'velocity'):
                got = bag.series(f'{interface.STRUT_STATES}.{field}.strut{i}_motor').values
                want = trace['y'][:, names[0].index(f'strut{i}_motor_{field}')]
                assert np.array_equal(got, want), (i, field)
            got = bag.series(f'{interface.force_topic("damper")}.effort.strut{i}_motor_force')
            assert np.array_equal(got.values,
                                  trace['u'][:, names[1].index(f'strut{i}_motor_force')])
    # the offline loop: the same discrete plant with drives, the same laws, the same force
    core = MultiRatePlant.from_model(
        DriveSet(load_drives()).on(PlantModel.load(tmp_path / 'model.npz')), RATE)
    laws = scenario_laws(read_scenario(path).sections, 1 / RATE)
    force = Excitation(ExcitationSpec(**EXCITER), 1 / RATE).series(STEPS)[:, :1]
    offline = simulate(core, laws, excitation_matrix(core, ['tcp_force_x'], force, STEPS))
    for tag, trace in traces.items():
        assert np.array_equal(trace['y'], offline.y), tag
        assert np.array_equal(trace['u'], offline.u), tag
    motor = offline.input_names.index('strut1_motor_force')
    assert np.abs(offline.u[:, motor]).max() > 0          # the cascade acted


def test_a_multi_rate_plant_with_drives_through_ros_is_the_offline_loop(tmp_path):
    """Substeps 4: the plant node steps the rotors at 20 kHz, exchanges at 5 kHz; bit for bit."""
    substeps = 4
    path = _scenario(tmp_path, 'multirate', record=False, substeps=substeps)
    assert run_scenario(path, {}, 300.0, log_dir=tmp_path / 'logs', composed=True) == 0
    trace = dict(np.load(tmp_path / 'trace_multirate.npz'))
    core = MultiRatePlant.from_model(
        DriveSet(load_drives()).on(PlantModel.load(tmp_path / 'model.npz')), RATE, substeps)
    assert core.substeps == substeps and core.n_states == 2 * 186 + 15
    laws = scenario_laws(read_scenario(path).sections, 1 / RATE)
    force = Excitation(ExcitationSpec(**EXCITER), 1 / RATE).series(STEPS)[:, :1]
    offline = simulate(core, laws, excitation_matrix(core, ['tcp_force_x'], force, STEPS))
    assert np.array_equal(trace['y'], offline.y)
    assert np.array_equal(trace['u'], offline.u)
    # and not the single-rate plant's bits (the substeps were stepped)
    single = MultiRatePlant.from_model(
        DriveSet(load_drives()).on(PlantModel.load(tmp_path / 'model.npz')), RATE)
    for law in laws:
        law.reset()
    one = simulate(single, laws, excitation_matrix(single, ['tcp_force_x'], force, STEPS))
    assert not np.array_equal(one.y, offline.y)
    assert np.abs(offline.u[:, offline.input_names.index('strut1_motor_force')]).max() > 0


def test_the_loop_check_refuses_an_unstable_drive_delay(tmp_path):
    """15 samples of drive delay: radius 1.014 on this plant (test_hac_lac); refused."""
    params = dataclasses.replace(load_drives(), delay_steps=15)
    slow = tmp_path / 'slow_drives.yaml'
    slow.write_text(''.join(f'{f.name}: {getattr(params, f.name)}\n'
                            for f in dataclasses.fields(params) if f.name != 'source'))
    path = _scenario(tmp_path, 'slow', str(slow), record=False)
    code = run_scenario(path, {}, 120.0, log_dir=tmp_path / 'logs', composed=True)
    assert code != 0
    lines = [line for f in (tmp_path / 'logs').glob('*.log')
             for line in f.read_text().splitlines()]
    refused = [line for line in lines if 'truncation check (loop_check = refuse)' in line]
    assert refused and re.search(r'unstable; spectral radius 1\.01', refused[0]), lines[-20:]


def test_a_bad_drives_file_is_one_named_error(tmp_path):
    path = _scenario(tmp_path, 'bad', 'no_such_drives.yaml', record=False)
    code = run_scenario(path, {}, 120.0, log_dir=tmp_path / 'logs', composed=True)
    assert code != 0
    text = '\n'.join(f.read_text() for f in (tmp_path / 'logs').glob('*.log'))
    errors = [line for line in text.splitlines() if line.startswith('error:')]
    assert any("'no_such_drives.yaml' not found" in e for e in errors), errors
    assert 'Traceback' not in text
