"""Mode selection by dc gain, static error/correction and the harmonic reference solve."""
import numpy as np
import pytest
from statespace_fixtures import all_modes, small_model

from pentapod_sim.errors import ConfigError
from pentapod_sim.plant import ports
from pentapod_sim.plant import reduction as red

INPUTS = ['tcp_force_x', 'tcp_force_y', 'strut1_bending_moment_2', 'strut2_axial_force']
OUTPUTS = ['tcp_displacement_x', 'tcp_displacement_y', 'strut1_bending_2',
           'strut2_axial_displacement']


@pytest.fixture(scope='module')
def system():
    model = small_model(2)
    omega, phi = all_modes(model)
    B = ports.input_matrix(ports.ports(model.points, model.strut_frames, INPUTS))
    C, _ = ports.output_matrices(ports.ports(model.points, model.strut_frames, OUTPUTS))
    return model, omega, phi, B, C


def test_static_compliance_equals_dense_inverse(system):
    model, _, _, B, C = system
    exact = C @ np.linalg.solve(model.K.toarray(), B)
    np.testing.assert_allclose(red.static_compliance(model.K, B, C), exact, rtol=1e-10)


def test_dc_gains_of_all_modes_sum_to_compliance(system):
    # K^-1 = Phi Omega^-2 Phi^T for mass-normalised modes
    model, omega, phi, B, C = system
    gains = red.modal_dc_gains(omega, phi.T @ B, C @ phi)
    assert gains.shape == (model.n_dof, 4, 4)
    np.testing.assert_allclose(gains.sum(axis=0), red.static_compliance(model.K, B, C),
                               rtol=1e-8, atol=1e-20)


def test_select_by_absolute_relative_and_count():
    g = np.array([[1e-7, 0.0], [-6e-8, 1e-9], [1e-10, 4e-8], [2e-9, 0.0]])[:, :, None]
    np.testing.assert_array_equal(red.select_modes(g, abs_limit=5e-8), [0, 1])
    # shares of column 1: 1e-9 / 4.1e-8 = 0.024, 4e-8 / 4.1e-8 = 0.98
    np.testing.assert_array_equal(red.select_modes(g, rel_limit=0.02), [0, 1, 2])
    np.testing.assert_array_equal(red.select_modes(g, count=2), [0, 2])


@pytest.mark.parametrize('kwargs', [{'abs_limit': -1.0}, {'abs_limit': 0.0},
                                    {'abs_limit': float('nan')}, {'abs_limit': '5e-8'},
                                    {'rel_limit': 1.5}, {'count': 0}, {'count': 2.5},
                                    {}, {'abs_limit': 1e-8, 'count': 3}])
def test_bad_limits_name_the_value(kwargs):
    with pytest.raises(ConfigError) as info:
        red.select_modes(np.ones((3, 1, 1)), **kwargs)
    for value in kwargs.values():
        assert repr(value) in str(info.value) or str(value) in str(info.value)


def test_collocated_static_error_shrinks_and_correction_is_exact(system):
    model, omega, phi, B, C = system
    b, c = phi.T @ B, C @ phi
    g_full = red.static_compliance(model.K, B, C)
    errors = []
    top = np.abs(red.modal_dc_gains(omega, b, c)).max()
    for limit in (top / 10, top / 1e3, top / 1e5):
        res = red.reduce_modes(omega, b, c, g_full, abs_limit=limit)
        kept_sum = c[:, res.keep] @ np.diag(omega[res.keep] ** -2.0) @ b[res.keep]
        np.testing.assert_allclose(res.g_reduced, kept_sum, rtol=1e-10, atol=1e-14 * top)
        expected = (kept_sum - g_full) / g_full * 100
        np.testing.assert_allclose(res.error_percent, expected, rtol=1e-8, atol=1e-8)
        np.testing.assert_allclose(res.error_corrected_percent, 0.0, atol=1e-9)
        np.testing.assert_allclose(res.g_reduced + res.residual, g_full, rtol=1e-12)
        errors.append(np.abs(np.diag(res.error_percent)))
    # diagonal (collocated) gains are all >= 0, so dropping modes always under-estimates
    assert np.all(np.diag(res.error_percent) <= 1e-9)
    assert np.all(errors[0] >= errors[1] - 1e-12) and np.all(errors[1] >= errors[2] - 1e-12)


def test_harmonic_solve_equals_modal_sum_between_resonances(system):
    model, omega, phi, B, C = system
    f_res = omega / (2 * np.pi)
    freq = 0.5 * (f_res[:6:2] + f_res[1:7:2])
    h = red.harmonic_response(model.K, model.M, B, C, freq)
    w = 2 * np.pi * freq
    modal = np.einsum('om,mi,mf->oif', C @ phi, phi.T @ B,
                      1 / (omega[:, None] ** 2 - w[None] ** 2))
    np.testing.assert_allclose(h, modal, rtol=1e-7, atol=1e-12 * np.abs(modal).max())


def test_frf_error_percent_definition():
    ref = np.array([[[1.0, 2.0, 4.0]]])
    approx = np.array([[[1.0, 2.2, 4.0]]])
    assert red.frf_error_percent(approx, ref)[0, 0] == pytest.approx(5.0)
    assert np.isnan(red.frf_error_percent(ref * 0, ref * 0)[0, 0])


def test_rigid_modes_have_no_dc_gain():
    with pytest.raises(ConfigError, match='rigid'):
        red.modal_dc_gains([0.0, 10.0], np.ones((2, 1)), np.ones((1, 2)))


def test_resonance_gain_is_single_mode_peak():
    # |H(i w_n)| of one mode = c b / (2 zeta w_n^2)
    omega, zeta, b, c = 2 * np.pi * 50.0, 0.02, 0.4, 0.7
    g = red.modal_resonance_gains([omega], [zeta], [[b]], [[c]])[0, 0, 0]
    peak = abs(c * b / (omega ** 2 - omega ** 2 + 2j * zeta * omega * omega))
    assert g == pytest.approx(peak, rel=1e-12)
    # a lightly damped mode with a small dc gain wins on the resonance measure
    gains = red.modal_resonance_gains([10.0, 20.0], [0.001, 0.1], [[1.0], [2.0]], [[1.0, 2.0]])
    np.testing.assert_array_equal(red.select_modes(gains, count=1), [0])
    with pytest.raises(ConfigError, match='zeta'):
        red.modal_resonance_gains([10.0], [0.0], [[1.0]], [[1.0]])
