"""
Multi-rate plant through ROS: the scenario runner's lockstep run equals the offline loop.

Separate processes and composed (``--composed``: one process, one executor) alike.

The plant integrates ``substeps`` exact ZOH substeps per exchange; the sources answer once per
exchange (/clock tick). The trace (exchange y, u and full-rate y) and the batched full-rate
topic must be the very bits of :func:`pentapod_sim.sim.closed_loop.simulate` with a
:class:`pentapod_sim.sim.multirate.MultiRatePlant` -- for a damper scenario (low-pass and delay
in the law) and a PMA scenario.
"""
import os
import subprocess
import sys

import numpy as np
import pytest

from fixtures.demo_model import demo_model
from pentapod_damper.scenario_laws import scenario_laws
from pentapod_sim.analysis.bag.reader import open_bag
from pentapod_sim.interface import TCP_STATE_FULLRATE
from pentapod_sim.scenario.files import dump_params, read_scenario
from pentapod_sim.sim.closed_loop import closed_loop_system, excitation_matrix, simulate
from pentapod_sim.sim.excitation import Excitation, ExcitationSpec
from pentapod_sim.sim.multirate import MultiRatePlant

pytestmark = [pytest.mark.ros, pytest.mark.slow]

TCP = ['tcp_force_x', 'tcp_force_y', 'tcp_force_z']
EXCITER = {'kind': 'random', 'amplitude': 50.0, 'direction': [1.0, 0.5, 0.0],
           'f_start': 5.0, 'f_end': 300.0, 'duration': 0.3, 'seed': 3}
CONTROLLERS = {
    'damper': {'damper': {'tcp_directions': ['x', 'y'], 'tcp_gain': 1000.0,
                          'filter_order': 2, 'bandwidth_hz': 250.0, 'filter_damping': 0.5,
                          'delay_steps': 0, 'bending_struts': [1], 'bending_gain': 150.0}},
    'pma': {'pma': {'directions': ['x'], 'proof_mass': 2.0, 'gain': 1000.0,
                    'highpass_hz': 5.0}},
}


def _scenario(tmp_path, kind: str, rate: float, substeps: int, steps: int, record: bool):
    model_file = demo_model(6, seed=4).save(tmp_path / 'model.npz')
    doc = {'/**': {'ros__parameters': {'sample_rate': rate}},
           'exciter': {'ros__parameters': dict(EXCITER)}}
    for name, params in CONTROLLERS[kind].items():
        doc[name] = {'ros__parameters': params}
    doc['plant'] = {'ros__parameters': {
        'model_file': str(model_file), 'steps': steps, 'substeps': substeps,
        'sources': ['exciter', *CONTROLLERS[kind]], 'output_file': str(tmp_path / 'trace.npz'),
        'startup_timeout': 60.0}}
    if record:
        doc['recorder'] = {'ros__parameters': {'output_dir': str(tmp_path / 'bags'),
                                               'bag_name': 'run',
                                               'topics': [TCP_STATE_FULLRATE]}}
        doc['plant']['ros__parameters']['wait_for_subscribers'] = ['recorder']
    path = tmp_path / 'scenario.yaml'
    path.write_text(dump_params(doc))
    return path


@pytest.mark.parametrize('kind,rate,substeps,record,composed', [
    ('damper', 1000.0, 10, True, False), ('pma', 1500.0, 8, False, False),
    ('damper', 1000.0, 10, True, True), ('pma', 1500.0, 8, False, True)],
    ids=['damper', 'pma', 'damper-composed', 'pma-composed'])
def test_ros_multirate_run_equals_offline_loop_bit_for_bit(tmp_path, kind, rate, substeps,
                                                          record, composed):
    steps = 500
    path = _scenario(tmp_path, kind, rate, substeps, steps, record)
    proc = subprocess.run([sys.executable, '-m', 'pentapod_sim.scenario.runner', str(path),
                           '--timeout', '240', *(['--composed'] if composed else [])],
                          env=dict(os.environ), capture_output=True, text=True, timeout=300)
    log = proc.stdout + proc.stderr
    assert proc.returncode == 0, log
    assert len([line for line in log.splitlines() if 'starting ' in line]) == (
        1 if composed else len(read_scenario(path).sections)), log
    run = np.load(tmp_path / 'trace.npz')
    assert int(run['steps_run']) == steps and int(run['substeps']) == substeps
    assert float(run['dt']) == pytest.approx(1 / rate, rel=1e-15)

    model = demo_model(6, seed=4)
    plant = MultiRatePlant.from_model(model, rate, substeps)
    laws = scenario_laws(read_scenario(path).sections, 1 / rate)
    if kind == 'damper':                       # a stable loop (the PMA's high-pass: no model)
        assert np.abs(np.linalg.eigvals(closed_loop_system(plant, laws).a)).max() < 1.0
    exc = Excitation(ExcitationSpec(**EXCITER), 1 / rate).series(steps)
    ref = simulate(plant, laws, excitation_matrix(plant, TCP, exc, steps), full_rate=True)
    assert np.any(ref.u[:, [plant.input_index[p] for p in laws[0].actuator_ports]])
    assert np.array_equal(run['u'], ref.u)
    assert np.array_equal(run['y'], ref.y)
    assert run['y_full'].shape == (steps * substeps, len(model.output_names))
    assert np.array_equal(run['y_full'], ref.y_full)
    assert np.array_equal(run['x_final'], plant.x)
    if record:
        bag = open_bag(tmp_path / 'bags' / 'run')
        names = list(run['output_names'])
        for j in (0, 1, substeps - 1):
            disp = bag.series(f'{TCP_STATE_FULLRATE}.position.tcp_x@{j}')
            vel = bag.series(f'{TCP_STATE_FULLRATE}.velocity.tcp_y@{j}')
            assert disp.values.size == steps, j
            assert np.array_equal(disp.time_ns, np.round(np.arange(steps) / rate * 1e9))
            full = run['y_full'].reshape(steps, substeps, -1)
            assert np.array_equal(disp.values, full[:, j, names.index('tcp_displacement_x')])
            assert np.array_equal(vel.values, full[:, j, names.index('tcp_velocity_y')])


@pytest.mark.parametrize('value', ['0', '1001', '2.5'])
def test_bad_substeps_stop_the_plant_naming_the_value(tmp_path, value):
    model_file = demo_model(2).save(tmp_path / 'model.npz')
    proc = subprocess.run([sys.executable, '-m', 'pentapod_sim.nodes.plant_node', '--ros-args',
                           '-p', f'model_file:={model_file}', '-p', f'substeps:={value}'],
                          env=dict(os.environ), capture_output=True, text=True, timeout=60)
    assert proc.returncode == 1
    assert f"node 'plant': parameter substeps = {value}" in proc.stderr, proc.stderr
