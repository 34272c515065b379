"""PlantModel: continuous/discrete state space against physics, save/load, building."""
import dataclasses
import zipfile

import control
import numpy as np
import pytest
import scipy.signal as signal
from statespace_fixtures import all_modes, small_model

from pentapod_sim.errors import ConfigError, ModelFileError, PortError
from pentapod_sim.plant import ports
from pentapod_sim.plant.build import build_plant, from_modal_data
from pentapod_sim.plant.model import PlantModel
from pentapod_sim.plant.reduction import harmonic_response, static_compliance

INPUTS = ['tcp_force_y', 'strut1_bending_moment_3', 'strut4_axial_force', 'pma_force_z']
OUTPUTS = ['tcp_displacement_y', 'tcp_velocity_y', 'strut1_bending_3', 'strut1_bending_rate_3',
           'strut4_axial_displacement', 'pma_mount_velocity_z']


@pytest.fixture(scope='module')
def full():
    """Small FE model, all its modes and the plant keeping every mode (zeta = 0.02)."""
    model = small_model(4)
    omega, phi = all_modes(model)
    plant = from_modal_data(omega / (2 * np.pi), ports.modal_points(model.points, phi),
                            model.strut_frames, INPUTS, OUTPUTS, zeta=0.02)
    return model, omega, phi, plant


def one_mode(omega=2 * np.pi * 40.0, zeta=0.01, b=0.3, c=0.3) -> PlantModel:
    return PlantModel([omega], [zeta], [[b]], [[c]], [[0.0]], [[0.0]], ['tcp_force_x'],
                      ['tcp_displacement_x'], ['N'], ['m'], ['f'], ['x'])


def test_poles_are_modal(full):
    _, omega, _, plant = full
    poles = np.sort_complex(plant.to_statespace().poles())
    expected = -0.02 * omega + 1j * omega * np.sqrt(1 - 0.02 ** 2)
    expected = np.sort_complex(np.r_[expected, expected.conj()])
    np.testing.assert_allclose(poles, expected, rtol=1e-9)


def test_names_reach_python_control(full):
    sys = full[3].to_statespace()
    assert sys.input_labels == INPUTS and sys.output_labels == OUTPUTS


def test_statespace_equals_direct_harmonic_solve_of_fe_model(full):
    model, omega, phi, plant = full
    M = model.M.toarray()
    damping = M @ phi @ np.diag(2 * 0.02 * omega) @ phi.T @ M   # modal damping matrix
    B = ports.input_matrix(ports.ports(model.points, model.strut_frames, INPUTS))
    out = ports.ports(model.points, model.strut_frames, OUTPUTS)
    c_disp, c_vel = ports.output_matrices(out)
    freq = np.array([3.0, omega[0] / (2 * np.pi), 0.5 * (omega[3] + omega[4]) / (2 * np.pi)])
    x = harmonic_response(model.K, model.M, B, np.eye(model.n_dof), freq, damping)
    w = 2 * np.pi * freq
    direct = np.einsum('on,nif->oif', c_disp, x) + np.einsum('on,nif,f->oif', c_vel, x, 1j * w)
    resp = control.frequency_response(plant.to_statespace(), w)
    h = np.asarray(resp.complex).reshape(len(OUTPUTS), len(INPUTS), -1)
    np.testing.assert_allclose(h, direct, rtol=1e-7, atol=1e-9 * np.abs(direct).max())


def test_zoh_matches_scipy_cont2discrete(full):
    plant = full[3]
    a, b, c, d = plant.state_matrices()
    a_ref, b_ref, *_ = signal.cont2discrete((a, b, c, d), 2e-4, method='zoh')
    a_d, b_d, _, _ = plant.discrete_matrices(2e-4)
    np.testing.assert_allclose(a_d, a_ref, atol=1e-10)
    np.testing.assert_allclose(b_d, b_ref, atol=1e-12 * np.abs(b_ref).max())


def test_discrete_step_hits_closed_form_continuous_step_at_samples():
    w, z, bc = 2 * np.pi * 40.0, 0.01, 0.09
    plant = one_mode(w, z)
    dt, n = 1e-3, 200
    t = dt * np.arange(n)
    resp = control.forced_response(plant.discretize(dt), t, np.ones(n))
    wd = w * np.sqrt(1 - z ** 2)
    exact = bc / w ** 2 * (1 - np.exp(-z * w * t) * (np.cos(wd * t)
                                                      + z / np.sqrt(1 - z ** 2) * np.sin(wd * t)))
    np.testing.assert_allclose(np.ravel(resp.outputs), exact, atol=1e-9 * bc / w ** 2)


def test_discrete_equals_continuous_with_held_input(full):
    # continuous response to a held input = superposition of shifted continuous step responses
    plant = full[3].select(['tcp_force_y'], ['tcp_displacement_y'])
    dt, n = 1e-3, 60
    u_k = np.random.default_rng(0).normal(size=n)
    t = dt * np.arange(n)
    step = np.ravel(control.step_response(plant.to_statespace(), t).outputs)
    jumps = np.diff(np.r_[0.0, u_k])
    cont = sum(jump * np.r_[np.zeros(k), step[:n - k]] for k, jump in enumerate(jumps))
    disc = control.forced_response(plant.discretize(dt), t, u_k)
    np.testing.assert_allclose(np.ravel(disc.outputs), cont, atol=1e-9 * np.abs(cont).max())


def test_rigid_body_mode_zoh_is_exact():
    plant = one_mode(omega=0.0, zeta=0.0, b=1.0, c=1.0)
    phi, gamma = plant.zoh_blocks(0.1)
    np.testing.assert_allclose(phi[0], [[1.0, 0.1], [0.0, 1.0]])
    np.testing.assert_allclose(gamma[0], [0.1 ** 2 / 2, 0.1])


@pytest.mark.parametrize('dt', [0.0, -1e-3, float('nan')])
def test_bad_sample_time(dt):
    with pytest.raises(ConfigError, match='dt'):
        one_mode().discretize(dt)


def test_save_load_roundtrip(full, tmp_path):
    plant = full[3]
    plant.meta['position'] = 'P1'
    path = plant.save(tmp_path / 'plant.npz')
    back = PlantModel.load(path)
    for name in ('omega', 'zeta', 'b', 'c_disp', 'c_vel', 'd'):
        np.testing.assert_array_equal(getattr(back, name), getattr(plant, name))
    assert back.input_names == INPUTS and back.output_units == plant.output_units
    assert back.meta['position'] == 'P1'


def test_edited_file_is_rejected(full, tmp_path):
    path = full[3].save(tmp_path / 'plant.npz')
    with zipfile.ZipFile(path) as src:
        members = {n: src.read(n) for n in src.namelist()}
    with np.load(path) as data:
        omega = data['omega'].copy()
    omega[0] *= 1.01
    edited = tmp_path / 'edited.npz'
    with open(edited, 'wb') as stream:
        np.save(stream, omega)
    members['omega.npy'] = edited.read_bytes()
    with zipfile.ZipFile(edited, 'w') as dst:
        for name, data in members.items():
            dst.writestr(name, data)
    with pytest.raises(ModelFileError, match='hash'):
        PlantModel.load(edited)
    (tmp_path / 'cut.npz').write_bytes(path.read_bytes()[:200])
    with pytest.raises(ModelFileError, match='cut.npz'):
        PlantModel.load(tmp_path / 'cut.npz')


def test_shape_mismatch_is_reported():
    with pytest.raises(ModelFileError, match='b has shape'):
        PlantModel([1.0, 2.0], [0.01, 0.01], [[1.0]], [[1.0, 1.0]], [[0.0, 0.0]], [[0.0]],
                   ['tcp_force_x'], ['tcp_displacement_x'], ['N'], ['m'], ['f'], ['x'])


def test_select_unknown_port(full):
    with pytest.raises(PortError, match='not in this plant model'):
        full[3].select(['tcp_force_x'])


def test_build_plant_static_gain_equals_fe_compliance():
    from pentapod_sim.fe.assembly import build_model
    from pentapod_sim.fe.machine_data import load_machine
    from pentapod_sim.plant.build import load_reduction_config
    cfg = load_reduction_config()
    cfg = dataclasses.replace(
        cfg, inputs=('tcp_force_x', 'tcp_force_y', 'tcp_force_z', 'strut1_axial_force'),
        outputs=('tcp_displacement_x', 'tcp_displacement_y', 'tcp_displacement_z',
                 'strut1_axial_displacement', 'tcp_velocity_y'), relevance=cfg.relevance[:1])
    plant = build_plant('P1', reduction_cfg=cfg)
    fe = build_model(load_machine(), 'P1')
    B = ports.input_matrix(ports.ports(fe.points, fe.strut_frames, cfg.inputs))
    C, _ = ports.output_matrices(ports.ports(fe.points, fe.strut_frames, cfg.outputs))
    exact = static_compliance(fe.K, B, C)
    a, b, c, d = plant.state_matrices()
    dc = d - c @ np.linalg.solve(a, b)        # G(0) = D - C A^-1 B
    np.testing.assert_allclose(dc, exact, rtol=1e-8, atol=1e-8 * np.abs(exact).max())
    assert 0 < plant.n_modes < plant.meta['n_modes_computed']
    assert plant.meta['params_sha256'] == fe.meta['params_sha256']


@pytest.mark.parametrize('fmt', ['npz', 'csv'])
def test_external_modal_data_gives_the_same_plant(full, tmp_path, fmt):
    from pentapod_sim.plant import external_modes
    model, omega, phi, plant = full
    data = external_modes.from_fe_modes(model.points, model.strut_frames, omega / (2 * np.pi), phi)
    if fmt == 'npz':
        path, frames = external_modes.save_npz(data, tmp_path / 'modes.npz'), None
    else:
        path = external_modes.save_csv(data, tmp_path / 'modes.csv')
        frames = tmp_path / 'frames.yaml'
        frames.write_text(f'strut_frames: {model.strut_frames.tolist()}\n')
    back = external_modes.load_modal_data(path, frames)
    again = from_modal_data(back.frequencies_hz, back.point_shapes, back.strut_frames,
                            INPUTS, OUTPUTS, zeta=0.02)
    np.testing.assert_allclose(again.b, plant.b, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(again.c_vel, plant.c_vel, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(again.omega, plant.omega, rtol=1e-12)


def test_external_modal_data_errors(full, tmp_path):
    from pentapod_sim.plant import external_modes
    model, omega, phi, _ = full
    data = external_modes.from_fe_modes(model.points, model.strut_frames, omega / (2 * np.pi), phi)
    path = external_modes.save_csv(data, tmp_path / 'modes.csv')
    lines = path.read_text().splitlines()
    (tmp_path / 'gap.csv').write_text('\n'.join(lines[:-1]) + '\n')   # one row missing
    with pytest.raises(ModelFileError, match='non-finite'):
        external_modes.load_modal_data(tmp_path / 'gap.csv')
    (tmp_path / 'cols.csv').write_text('mode,frequency_hz,point,ux\n1,2.0,tcp,0.1\n')
    with pytest.raises(ModelFileError, match='missing columns'):
        external_modes.load_modal_data(tmp_path / 'cols.csv')
    no_frames = external_modes.load_modal_data(path)
    with pytest.raises(ModelFileError, match='strut frames'):
        from_modal_data(no_frames.frequencies_hz, no_frames.point_shapes, None,
                        ['strut1_axial_force'], ['tcp_displacement_x'])
    with pytest.raises(ModelFileError, match='format'):
        external_modes.load_modal_data(tmp_path / 'modes.unv')


def test_relevance_rules_are_united(full):
    from pentapod_sim.plant.build import keep_by_relevance
    plant = full[3]
    tcp = {'inputs': ['tcp_force_y'], 'outputs': ['tcp_displacement_y'], 'count': 3}
    strut = {'inputs': ['strut4_axial_force'], 'outputs': ['strut4_axial_displacement'],
             'count': 3}
    a, b = keep_by_relevance(plant, [tcp]), keep_by_relevance(plant, [strut])
    np.testing.assert_array_equal(keep_by_relevance(plant, [tcp, strut]), np.union1d(a, b))
    with pytest.raises(ConfigError, match="'peak'"):
        keep_by_relevance(plant, [dict(tcp, measure='peak')])
    with pytest.raises(ConfigError, match='2 given'):
        from_modal_data([10.0, 20.0, 30.0], {'tcp': np.ones((6, 3))}, None, ['tcp_force_x'],
                        ['tcp_displacement_x'], zeta=[0.01, 0.02])


def test_reduce_without_fe_compliance(full):
    from pentapod_sim.plant.build import reduce_plant
    plant = full[3]                       # from modal data: no C K^-1 B known
    small = reduce_plant(plant, [0, 2], static_correction=False)
    np.testing.assert_array_equal(small.omega, plant.omega[[0, 2]])
    assert not small.d.any() and small.meta['kept_modes'] == [1, 3]
    with pytest.raises(ConfigError, match='static correction'):
        reduce_plant(plant, [0, 2])
