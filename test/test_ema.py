"""
Modal identification (pLSCF, stability diagram, selection, LSFD) on systems with known poles.

The FRFs come from periodic multisine records with white output noise in the time domain,
estimated by synchronous averaging: the whole chain `analyze modes` runs on a bag. Required
accuracy (issue 13): frequencies within 0.1 %, damping ratios within 5 % relative.
"""
from modal_systems import multisine, periodic_response, TenModes, TwoDof
import numpy as np
import pytest

from pentapod_sim.analysis.ema.identify import identify_modes
from pentapod_sim.analysis.ema.lsfd import lsfd
from pentapod_sim.analysis.ema.poles import plscf, select_poles, stability_diagram, Tolerances
from pentapod_sim.analysis.frf.periodic import synchronous_frf

DT = 1e-3  # s


def measured_frfs(system, period_steps, f_high, n_periods, noise_rel, seed):
    """Synchronously averaged FRFs (No, F), their noise std and the lines [Hz]."""
    bins = np.arange(int(2 * period_steps * DT), int(f_high * period_steps * DT) + 1)
    rng = np.random.default_rng(seed)
    u, y = periodic_response(system, multisine(period_steps, bins), DT, n_periods + 1,
                             noise_rel, rng)
    frfs = [synchronous_frf(u, out, DT, period_steps, settle_periods=1) for out in y]
    return (frfs[0].freq, np.array([r.H for r in frfs]), np.array([r.noise_std for r in frfs]))


def matched(model, system):
    """Indices of the true modes nearest to the identified ones (each exactly once)."""
    index = [int(np.argmin(np.abs(system.freq_hz - f))) for f in model.freq_hz]
    assert sorted(index) == list(range(len(system.freq_hz))), (model.freq_hz, system.freq_hz)
    return index


def errors(model, system):
    k = matched(model, system)
    return (np.abs(model.freq_hz / system.freq_hz[k] - 1),
            np.abs(model.damping / system.damping[k] - 1))


@pytest.mark.parametrize('seed', [0, 1, 2])
def test_two_dof_with_noise(seed):
    system = TwoDof(zeta=(0.001, 0.02))
    freq, h, sigma = measured_frfs(system, 4000, 100.0, 8, 0.02, seed)
    model = identify_modes(freq, h, sigma=sigma)
    err_f, err_z = errors(model, system)
    assert err_f.max() < 1e-3 and err_z.max() < 0.05, (err_f, err_z)
    # modal constants of the mass-normalised modes (phi_o phi_1), within 2 %
    k = matched(model, system)
    constants = model.fit.modal_constants[:, 0, :].real
    np.testing.assert_allclose(constants, system.modal_constants[:, k], rtol=0.02)


@pytest.mark.parametrize('seed', [0, 1])
def test_ten_modes_with_noise(seed):
    system = TenModes()
    freq, h, sigma = measured_frfs(system, 10000, 200.0, 8, 0.02, seed)
    model = identify_modes(freq, h, sigma=sigma, refine=True)  # 12.3 Hz: see below
    err_f, err_z = errors(model, system)
    assert err_f.max() < 1e-3 and err_z.max() < 0.05, (err_f, err_z)
    synth = model.synthesise(freq)[:, 0, :]
    exact = system.frf(freq)[:, 0, :]
    assert np.linalg.norm(synth - exact) < 0.02 * np.linalg.norm(exact)


def test_pole_refinement_removes_bias_of_a_sparsely_sampled_peak():
    """The 12.3 Hz mode at 0.1 % has a 0.025 Hz half-power band between 0.1 Hz lines."""
    system = TenModes()
    freq, h, sigma = measured_frfs(system, 10000, 200.0, 8, 0.02, 0)
    raw = identify_modes(freq, h, sigma=sigma)
    refined = identify_modes(freq, h, sigma=sigma, refine=True)
    assert errors(raw, system)[1][0] > 0.05  # linearised pLSCF: biased
    assert errors(refined, system)[1][0] < 0.05  # 2.0 % measured


def test_noise_free_poles_are_exact_and_spurious_ones_are_not_selected():
    system = TenModes()
    freq = np.arange(20, 2000) * 0.1
    diagram = stability_diagram(plscf(freq, system.frf(freq), range(1, 61)))
    poles = select_poles(diagram)
    assert len(poles) == 10
    np.testing.assert_allclose(np.sort_complex(poles), np.sort_complex(system.poles), rtol=1e-6)
    # every order from 26 on (20 for the modes, more for the modes outside the band)
    # holds the 10 poles, labelled stable; the extra poles of higher orders are not
    for entry in diagram[25:]:
        stable = entry.freq[entry.classes == 's']
        assert len(stable) == 10
        np.testing.assert_allclose(stable, system.freq_hz, rtol=1e-4)


def test_poly_reference_two_inputs():
    """Two inputs (force on mass 1 and on mass 2): pLSCF with matrix polynomial, MAC test."""
    system = TwoDof(zeta=(0.005, 0.01))
    freq = np.arange(20, 1000) * 0.1
    h = np.empty((2, 2, len(freq)), dtype=complex)
    for j, f in enumerate(freq):
        w = 2 * np.pi * f
        h[:, :, j] = np.linalg.inv(system.k - w * w * system.m + 1j * w * system.c)
    diagram = stability_diagram(plscf(freq, h, range(1, 21)))
    assert all(len(e.factors[0]) == 2 for e in diagram if len(e.poles))
    poles = select_poles(diagram)
    np.testing.assert_allclose(np.sort_complex(poles), np.sort_complex(system.poles), rtol=1e-6)
    fit = lsfd(freq, h, poles)
    order = np.argsort(np.abs(poles))
    # residue matrix of mode r is phi_r phi_r^T / (2 j w_d): symmetric, rank one
    for r in order:
        constants = fit.modal_constants[:, :, r].real
        np.testing.assert_allclose(constants, constants.T, rtol=1e-5, atol=1e-12)
        assert abs(np.linalg.det(constants)) < 1e-6 * np.abs(constants).max() ** 2


def test_lsfd_residuals_take_up_modes_outside_the_band():
    """Modes at 4 and 600 Hz outside a 30-80 Hz band: mass line and static flexibility."""
    system = TenModes(freq_hz=(4.0, 50.0, 600.0), damping=(0.01, 0.01, 0.01))
    freq = np.arange(300, 800) * 0.1
    h = system.frf(freq)
    fit = lsfd(freq, h, system.poles[1:2])
    np.testing.assert_allclose(fit.modal_constants[:, 0, 0], system.modal_constants[:, 1],
                               rtol=1e-3)
    assert np.linalg.norm(fit.synthesise(freq) - h) < 1e-3 * np.linalg.norm(h)
    # upper residual = sum of the static flexibilities of the modes above
    wn = 2 * np.pi * system.freq_hz[2]
    np.testing.assert_allclose(fit.upper[:, 0], system.modal_constants[:, 2] / wn ** 2,
                               rtol=0.05)


def test_no_mode_in_band_is_a_clear_error():
    system = TwoDof(zeta=(0.001, 0.02))
    freq = np.arange(1, 1000) * 0.1
    h = system.frf(freq)
    rng = np.random.default_rng(0)
    noise = 1e-9 * (rng.standard_normal(h.shape) + 1j * rng.standard_normal(h.shape))
    band = (30.0, 45.0)  # between 24.3 and 49.5 Hz: only the modes' tails
    with pytest.raises(ValueError, match='no mode in 30 .. 45 Hz'):
        identify_modes(freq, np.zeros_like(h) + noise, band=band)
    with pytest.raises(ValueError, match='holds 0 FRF lines: too few'):
        identify_modes(freq, h, band=(200.0, 300.0))


def test_tolerances_select_by_support():
    """A pole cluster that is stable over fewer orders than min_stable is not selected."""
    system = TwoDof(zeta=(0.001, 0.02))
    freq = np.arange(20, 1000) * 0.1
    diagram = stability_diagram(plscf(freq, system.frf(freq), range(1, 11)))
    assert len(select_poles(diagram, Tolerances(min_stable=5))) == 2
    assert len(select_poles(diagram, Tolerances(min_stable=11))) == 0


def test_selecting_from_an_unlabelled_diagram_names_the_missing_step():
    system = TwoDof(zeta=(0.001, 0.02))
    freq = np.arange(20, 1000) * 0.1
    orders = plscf(freq, system.frf(freq), range(1, 4))
    with pytest.raises(ValueError, match=r'order 1 has no pole classes; .*stability_diagram'):
        select_poles(orders)
