"""Analytic FRFs, closed loops with added dampers, CSV and plots."""
import csv

import control
import numpy as np
import pytest
from statespace_fixtures import all_modes, small_model

from pentapod_sim.errors import ConfigError, PortError
from pentapod_sim.plant import frf, frf_plot, ports
from pentapod_sim.plant.build import from_modal_data
from pentapod_sim.plant.model import PlantModel
from pentapod_sim.plant.reduction import harmonic_response

INPUTS = ['tcp_force_x', 'strut2_bending_moment_2', 'strut1_axial_force']
OUTPUTS = ['tcp_displacement_x', 'tcp_velocity_x', 'strut2_bending_rate_2',
           'strut1_axial_velocity', 'strut1_axial_displacement']


@pytest.fixture(scope='module')
def full():
    model = small_model(7)
    omega, phi = all_modes(model)
    plant = from_modal_data(omega / (2 * np.pi), ports.modal_points(model.points, phi),
                            model.strut_frames, INPUTS, OUTPUTS, zeta=0.01)
    return model, omega, phi, plant


def test_modal_sum_equals_python_control(full):
    plant = full[3]
    freq = np.linspace(1.0, 300.0, 37)
    ours = frf.modal_frf(plant, freq)
    resp = control.frequency_response(plant.to_statespace(), 2 * np.pi * freq)
    ref = np.asarray(resp.complex).reshape(ours.H.shape)
    np.testing.assert_allclose(ours.H, ref, rtol=1e-8, atol=1e-10 * np.abs(ref).max())
    assert ours.H.shape == (len(OUTPUTS), len(INPUTS), 37)


def test_feedthrough_adds_to_every_frequency():
    plant = PlantModel([10.0], [0.0], [[1.0]], [[1.0]], [[0.0]], [[2e-3]], ['tcp_force_x'],
                       ['tcp_displacement_x'], ['N'], ['m'], ['f'], ['x'])
    h = frf.modal_frf(plant, [0.0, 1.0]).pair('tcp_displacement_x', 'tcp_force_x')
    w = 2 * np.pi * 1.0
    np.testing.assert_allclose(h, [1e-2 + 2e-3, 1 / (100 - w ** 2) + 2e-3])


@pytest.mark.parametrize('gain', [0.0, 50.0, 400.0])
def test_single_mode_collocated_damper_closed_form(gain):
    omega, zeta, phi = 2 * np.pi * 35.0, 0.001, 0.7
    plant = PlantModel([omega], [zeta], [[phi]], [[0.0], [0.0]], [[0.0], [phi]],
                       np.zeros((2, 1)), ['strut3_axial_force'],
                       ['strut3_axial_displacement', 'strut3_axial_velocity'],
                       ['N'], ['m', 'm/s'], ['f'], ['x', 'v'])
    closed = frf.damper_feedback(plant, {'strut3_axial_force': gain})
    poles = np.linalg.eigvals(closed.A)
    zeta_cl = -poles.real / np.abs(poles)
    np.testing.assert_allclose(zeta_cl, zeta + gain * phi ** 2 / (2 * omega), rtol=1e-10)
    np.testing.assert_allclose(np.abs(poles), omega, rtol=1e-10)


def test_damped_loop_equals_physical_dampers_in_fe_model(full):
    model, omega, phi, plant = full
    gains = {'strut2_bending_moment_2': 3e3, 'strut1_axial_force': 2e4, 'tcp_force_x': 1e4}
    M = model.M.toarray()
    damping = M @ phi @ np.diag(2 * 0.01 * omega) @ phi.T @ M
    for name, g in gains.items():      # a damper g between the port's two points
        v = ports.port(model.points, model.strut_frames, name).vector
        damping = damping + g * np.outer(v, v)
    B = ports.input_matrix(ports.ports(model.points, model.strut_frames, INPUTS))
    c_disp, c_vel = ports.output_matrices(ports.ports(model.points, model.strut_frames, OUTPUTS))
    freq = np.array([5.0, omega[0] / (2 * np.pi), omega[5] / (2 * np.pi), 250.0])
    x = harmonic_response(model.K, model.M, B, np.eye(model.n_dof), freq, damping)
    direct = np.einsum('on,nif->oif', c_disp, x) \
        + np.einsum('on,nif,f->oif', c_vel, x, 2j * np.pi * freq)
    ours = frf.closed_loop_frf(plant, gains, freq).H
    np.testing.assert_allclose(ours, direct, rtol=1e-6, atol=1e-8 * np.abs(direct).max())


def test_damping_lowers_the_resonance_peak(full):
    plant = full[3]
    f0 = full[1][0] / (2 * np.pi)
    freq = np.linspace(0.8 * f0, 1.2 * f0, 400)
    open_ = frf.modal_frf(plant, freq).pair('tcp_displacement_x', 'tcp_force_x')
    closed = frf.closed_loop_frf(plant, {'tcp_force_x': 1e4}, freq).pair(
        'tcp_displacement_x', 'tcp_force_x')
    assert np.abs(closed).max() < np.abs(open_).max()


def test_bad_dampers(full):
    plant = full[3]
    with pytest.raises(ConfigError, match='-5'):
        frf.damper_feedback(plant, {'tcp_force_x': -5.0})
    with pytest.raises(PortError, match='strut2_axial_velocity'):
        frf.damper_feedback(plant.select(outputs=OUTPUTS), {'strut2_axial_force': 1.0})
    with pytest.raises(ConfigError, match='frequencies'):
        frf.modal_frf(plant, [-1.0])


def test_csv_and_plots(full, tmp_path):
    plant = full[3]
    freq = np.linspace(1, 200, 50)
    res = frf.modal_frf(plant, freq, label='open')
    path = frf.frf_to_csv([res], [('tcp_displacement_x', 'tcp_force_x')], tmp_path / 'h.csv')
    with open(path) as stream:
        rows = list(csv.reader(stream))
    assert rows[0] == ['freq_hz', 'open:tcp_displacement_x/tcp_force_x:mag',
                       'open:tcp_displacement_x/tcp_force_x:phase_deg']
    h = res.pair('tcp_displacement_x', 'tcp_force_x')
    np.testing.assert_allclose([float(r[1]) for r in rows[1:]], np.abs(h), rtol=1e-12)
    png = frf_plot.frf_plot([res], 'tcp_displacement_x', 'tcp_force_x', tmp_path / 'h.png',
                       mode_freqs=[plant.frequencies_hz])
    bars = frf_plot.dc_gain_plot(plant.c_disp[0] * plant.b[:, 0] / plant.omega ** 2,
                            plant.frequencies_hz, tmp_path / 'dc.png', limit=1e-9, keep=[0, 2])
    for p in (png, bars):
        assert p.read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'


def test_statespace_cli_writes_report_plots_and_plant(tmp_path):
    import json

    from pentapod_sim.cli.statespace import main
    from pentapod_sim.plant.build import load_reduction_config
    from pentapod_sim.plant.model import PlantModel
    assert main(['report', '--position', 'P1', '--out', str(tmp_path)]) == 0
    row = json.loads((tmp_path / 'reduction_report.json').read_text())[0]
    assert 0 < row['modes_kept'] < row['modes_computed']
    assert row['static_error_percent_without_correction'] < 0   # collocated: under-estimate
    assert abs(row['static_error_percent_with_correction']) < 1e-8
    assert row['reference_vs_direct_solve_percent_of_peak'] < 0.1
    assert main(['dcgain', '--position', 'P1', '--out', str(tmp_path)]) == 0
    table = np.loadtxt(tmp_path / 'dcgain_tcp_displacement_y_tcp_force_y_P1.csv',
                       delimiter=',', skiprows=1)
    assert table[:, 3].sum() == row['modes_kept']
    limit = load_reduction_config().relevance[0].abs_limit
    np.testing.assert_array_equal(table[:, 3] == 1, np.abs(table[:, 2]) >= limit)
    # all computed modes miss only the (small) flexibility of the modes above 750 Hz
    assert table[:, 2].sum() == pytest.approx(row['static_compliance_m_per_n'], rel=0.01)
    assert main(['build', '--position', 'P1', '--out', str(tmp_path)]) == 0
    plant = PlantModel.load(tmp_path / 'plant_P1.npz')
    assert plant.meta['position'] == 'P1' and plant.meta['static_correction']
    assert main(['closed-loop', '--position', 'P1', '--out', str(tmp_path),
                 '--damper', 'strut1_bending_moment_2=oops']) == 1
