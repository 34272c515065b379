"""
The struts' load-cell forces on the strut state topic (effort of the joints ``strut<i>_drive``).

The layout puts ``strut<i>_force`` [N] in the effort of the feed-drive joint, with the drive
displacement and velocity as its position and velocity, NaN effort for the strut's other joints
and no effort at all on the topics without one. A composed run of the shipped iff_struts
scenario's laws (on a small synthetic plant with load cells, at the scenario's sample rate)
closes IFF through the nodes: its trace is the offline sampled loop's bit for bit, and the
efforts recorded on /pentapod/strut_states are the plant's load-cell outputs, recomputed here
as y_k = C x_k + D u_{k-1} of an independent zero-order-hold discretisation of the plant.
"""
import os
from pathlib import Path
import subprocess
import sys

import numpy as np
import pytest
from scipy.linalg import expm

from fixtures.demo_model import load_cell_model
from pentapod_damper.scenario_laws import scenario_laws
from pentapod_sim import interface
from pentapod_sim.analysis.bag.reader import open_bag
from pentapod_sim.plant.model import PlantModel
from pentapod_sim.plant.ports import N_STRUTS, OUTPUT_NAMES
from pentapod_sim.scenario.files import dump_params, read_scenario
from pentapod_sim.sim.closed_loop import excitation_matrix, simulate
from pentapod_sim.sim.excitation import Excitation, ExcitationSpec
from pentapod_sim.sim.multirate import MultiRatePlant
from pentapod_sim.topic_layout import batch_layout

ROOT = Path(__file__).resolve().parents[1]
SCENARIO = ROOT / 'config' / 'scenarios' / 'iff_struts.yaml'
STRUTS = range(1, N_STRUTS + 1)
TCP = ['tcp_force_x', 'tcp_force_y', 'tcp_force_z']


def test_the_load_cell_force_is_the_effort_of_the_drive_joint():
    assert interface.port_location('strut3_force') == (
        interface.STRUT_STATES, 'strut3_drive', 'effort')
    assert interface.port_location('strut3_drive_displacement')[1:] == ('strut3_drive',
                                                                         'position')
    names = list(OUTPUT_NAMES)
    y = np.random.default_rng(0).normal(size=len(names))
    layouts = {lay.topic: lay for lay in interface.state_layouts(names)}
    strut = layouts[interface.STRUT_STATES]
    pos, vel, eff = strut.values(y)
    for i in STRUTS:
        j = strut.joints.index(f'strut{i}_drive')
        assert (pos[j], vel[j], eff[j]) == (y[names.index(f'strut{i}_drive_displacement')],
                                            y[names.index(f'strut{i}_drive_velocity')],
                                            y[names.index(f'strut{i}_force')])
        assert vel[strut.joints.index(f'strut{i}_axial')] == y[
            names.index(f'strut{i}_axial_velocity')]
    has = np.array([j.endswith('_drive') for j in strut.joints])
    assert has.sum() == N_STRUTS and np.isnan(eff[~has]).all()
    for topic in (interface.TCP_STATE, interface.PMA_MOUNT_STATE):    # as before: no effort
        assert layouts[topic].values(y)[2].size == 0
    # a display batch of 3 steps carries the efforts of every step
    rows = np.random.default_rng(1).normal(size=(3, len(names)))
    batch = batch_layout(strut, len(names), 3, 'b')
    eff3 = batch.values(rows.reshape(-1))[2].reshape(3, -1)
    for s in range(3):
        np.testing.assert_array_equal(eff3[s], strut.values(rows[s])[2])
    # a model without the load cells publishes no effort on the strut topic
    without = [n for n in names if not n.endswith('_force')]
    lay = next(x for x in interface.state_layouts(without) if x.topic == interface.STRUT_STATES)
    assert lay.values(np.zeros(len(without)))[2].size == 0


def _independent_outputs(model: PlantModel, u: np.ndarray, dt: float) -> np.ndarray:
    """y_k = C x_k + D u_{k-1} (u_{-1} = 0, x_0 = 0) of the zero-order-hold sampled plant."""
    m, n_in = model.b.shape
    a = np.block([[np.zeros((m, m)), np.eye(m)],
                  [-np.diag(model.omega ** 2), -np.diag(2 * model.zeta * model.omega)]])
    b = np.vstack([np.zeros((m, n_in)), model.b])
    big = np.zeros((2 * m + n_in, 2 * m + n_in))
    big[:2 * m, :2 * m], big[:2 * m, 2 * m:] = a, b
    phi = expm(big * dt)
    a_d, b_d = phi[:2 * m, :2 * m], phi[:2 * m, 2 * m:]
    c = np.hstack([model.c_disp, model.c_vel])
    x, u_prev, y = np.zeros(2 * m), np.zeros(n_in), np.empty((len(u), c.shape[0]))
    for k, u_k in enumerate(u):
        y[k] = c @ x + model.d @ u_prev
        x, u_prev = a_d @ x + b_d @ u_k, u_k
    return y


@pytest.mark.ros
@pytest.mark.slow
@pytest.mark.parametrize('executor', ['events', 'single'])
def test_iff_struts_through_the_nodes_equals_the_offline_loop_and_publishes_the_forces(
        tmp_path, executor):
    """Composed run: the in-process hand-off (``events``) or every message on DDS (``single``)."""
    shipped = read_scenario(SCENARIO).sections
    rate = float(shipped['plant']['sample_rate'])      # the shared sample rate (/**)
    steps = 2000
    exciter = {k: v for k, v in shipped['exciter'].items() if k != 'sample_rate'}
    exciter['duration'] = steps / rate
    damper = {k: v for k, v in shipped['damper_struts'].items() if k != 'sample_rate'}
    model = load_cell_model(8, seed=4)
    doc = {'/**': {'ros__parameters': {'sample_rate': rate}},
           'exciter': {'ros__parameters': exciter},
           'damper_struts': {'ros__parameters': damper},
           'plant': {'ros__parameters': {
               'model_file': str(model.save(tmp_path / 'model.npz')), 'steps': steps,
               'sources': ['exciter', 'damper_struts'],
               'output_file': str(tmp_path / 'trace.npz'), 'startup_timeout': 60.0,
               'wait_for_subscribers': ['recorder']}},
           'recorder': {'ros__parameters': {'output_dir': str(tmp_path / 'bags'),
                                            'bag_name': 'run'}}}
    path = tmp_path / 'scenario.yaml'
    path.write_text(dump_params(doc))
    proc = subprocess.run([sys.executable, '-m', 'pentapod_sim.nodes.composed', str(path)],
                          env=dict(os.environ, PENTAPOD_EXECUTOR=executor),
                          capture_output=True, text=True, timeout=300, cwd=ROOT)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    run = dict(np.load(tmp_path / 'trace.npz'))

    plant = MultiRatePlant.from_model(model, rate, 1)
    laws = scenario_laws(read_scenario(path).sections, 1 / rate)
    exc = Excitation(ExcitationSpec(**exciter), 1 / rate).series(steps)
    ref = simulate(plant, laws, excitation_matrix(plant, TCP, exc, steps))
    assert int(run['steps_run']) == steps
    assert np.array_equal(run['u'], ref.u) and np.array_equal(run['y'], ref.y)
    inputs, outputs = list(run['input_names']), list(run['output_names'])
    for i in STRUTS:      # the IFF loop is closed: every strut's actuator pushed
        assert np.any(run['u'][:, inputs.index(f'strut{i}_drive_force')]), i

    bag = open_bag(tmp_path / 'bags' / 'run')
    y_check = _independent_outputs(model, run['u'], 1 / rate)
    for i in STRUTS:
        force = bag.series(f'{interface.STRUT_STATES}.effort.strut{i}_drive')
        assert force.unit == 'N' and force.values.size == steps
        column = outputs.index(f'strut{i}_force')
        assert np.array_equal(force.values, run['y'][:, column])
        scale = np.max(np.abs(y_check[:, column]))
        assert scale > 0
        np.testing.assert_allclose(force.values, y_check[:, column], rtol=0,
                                   atol=1e-9 * scale)
        moved = bag.series(f'{interface.STRUT_STATES}.position.strut{i}_drive').values
        np.testing.assert_allclose(
            moved, y_check[:, outputs.index(f'strut{i}_drive_displacement')], rtol=0,
            atol=1e-9 * np.max(np.abs(moved)))
