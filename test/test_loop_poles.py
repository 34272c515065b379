"""Closed-loop poles per mode (sim.loop_poles) against closed forms and python-control."""
import control
import numpy as np
import pytest

from pentapod_sim.plant.model import PlantModel
from pentapod_sim.sim.controllers import DiscreteController
from pentapod_sim.sim.loop_poles import (
    closed_loop_poles,
    continuous_loop_poles,
    mac_matrix,
    pair_by_mac,
)

IN, DISP, VEL = 'tcp_force_x', 'tcp_displacement_x', 'tcp_velocity_x'


def modal_plant(freq_hz, zeta, phi, d=0.0) -> PlantModel:
    """Modes with one collocated force input at a point moving phi_i per modal coordinate."""
    phi = np.asarray(phi, dtype=float)
    m = phi.size
    c_disp = np.vstack([phi, np.zeros(m)])
    c_vel = np.vstack([np.zeros(m), phi])
    return PlantModel(2 * np.pi * np.asarray(freq_hz, float), zeta, phi[:, None], c_disp, c_vel,
                      [[d], [0.0]], [IN], [DISP, VEL], ['N'], ['m', 'm/s'], [''], ['', ''])


def damper(g: float) -> DiscreteController:
    return DiscreteController.static([VEL], [IN], [[-g]])


def _s_of(z, dt):
    s = np.log(np.asarray(z, dtype=complex)) / dt
    return s[s.imag > 0]


def test_continuous_single_mode_is_the_damped_quadratic():
    w, z, phi, g = 2 * np.pi * 27.0, 0.001, 0.8, 3.0
    poles = continuous_loop_poles(modal_plant([27.0], z, [phi]), [damper(g)])
    assert poles.structural.all() and poles.s.size == 1
    exact = np.roots([1.0, 2 * z * w + g * phi ** 2, w ** 2])
    assert poles.s[0] == pytest.approx(exact[exact.imag > 0][0], rel=1e-12)
    # collocated viscous damper: zeta_cl = zeta + g phi^2 / (2 omega), omega unchanged
    assert poles.zeta[0] == pytest.approx(z + g * phi ** 2 / (2 * w), rel=1e-12)
    assert poles.freq_hz[0] == pytest.approx(27.0, rel=1e-12)
    assert poles.mode[0] == 0 and poles.mac[0] == pytest.approx(1.0)


def test_continuous_overdamped_mode_gives_two_real_structural_poles():
    w, phi, g = 2 * np.pi * 5.0, 1.0, 200.0
    poles = continuous_loop_poles(modal_plant([5.0], 0.001, [phi]), [damper(g)])
    exact = np.sort(np.roots([1.0, 2 * 0.001 * w + g * phi ** 2, w ** 2]).real)
    np.testing.assert_allclose(np.sort(poles.s.real), exact, rtol=1e-10)
    assert poles.structural.all() and np.all(poles.zeta == 1.0)
    assert sorted(poles.mode) == [-1, 0]          # one mode, two real poles: one is paired


def test_continuous_low_pass_matches_the_characteristic_polynomial():
    w, z, phi, g, wf = 2 * np.pi * 40.0, 0.002, 0.5, 20.0, 2 * np.pi * 300.0
    filt = DiscreteController([VEL], [IN], [[-wf]], [[wf]], [[-g]], [[0.0]])
    poles = continuous_loop_poles(modal_plant([40.0], z, [phi]), [filt])
    # (s^2 + 2 z w s + w^2)(s + wf) + g phi^2 wf s = 0
    char = np.polymul([1, 2 * z * w, w ** 2], [1, wf]) + np.array([0, 0, g * phi ** 2 * wf, 0])
    exact = np.roots(char)
    pair = exact[exact.imag > 0][0]
    assert poles.s[poles.structural][0] == pytest.approx(pair, rel=1e-10)
    assert poles.s[~poles.structural][0] == pytest.approx(exact[exact.imag == 0][0], rel=1e-10)
    assert poles.mode[~poles.structural][0] == -1


@pytest.mark.parametrize('fs', [5000.0, 800.0])
def test_sampled_single_mode_equals_python_control(fs):
    dt, w, z, phi, g = 1 / fs, 2 * np.pi * 60.0, 0.001, 0.7, 8.0
    plant = modal_plant([60.0], z, [phi])
    poles = closed_loop_poles(plant, [damper(g)], dt)
    sys = control.ss([[0, 1], [-w ** 2, -2 * z * w]], [[0], [phi]], [[0, phi]], [[0]])
    ref = _s_of(control.poles(control.feedback(control.sample_system(sys, dt, 'zoh'), g)), dt)
    assert poles.s.size == 1 and poles.structural[0]
    assert poles.s[0] == pytest.approx(ref[0], rel=1e-9)
    assert poles.zeta[0] == pytest.approx(-ref[0].real / abs(ref[0]), rel=1e-9)
    # sampling costs damping against the continuous loop (sampled feedback lags by dt / 2)
    cont = continuous_loop_poles(plant, [damper(g)])
    assert poles.zeta[0] < cont.zeta[0]


def test_one_sample_delay_equals_python_control_with_z_inverse():
    dt, w, z, phi, g = 1 / 3000, 2 * np.pi * 120.0, 0.001, 0.6, 10.0
    delay = DiscreteController([VEL], [IN], [[0.0]], [[1.0]], [[-g]], [[0.0]])
    poles = closed_loop_poles(modal_plant([120.0], z, [phi]), [delay], dt)
    sys = control.ss([[0, 1], [-w ** 2, -2 * z * w]], [[0], [phi]], [[0, phi]], [[0]])
    sysd = control.sample_system(sys, dt, 'zoh')
    ref_z = control.poles(control.feedback(sysd, control.tf([g], [1, 0], dt)))
    ref = _s_of(ref_z, dt)
    assert poles.s[poles.structural][0] == pytest.approx(ref[0], rel=1e-9)
    # the third eigenvalue (the delay cell, 0 in the open loop) is the controller's
    ctrl = poles.lam[~poles.structural]
    assert ctrl.size == 1
    assert ctrl[0] == pytest.approx(ref_z[np.abs(ref_z.imag) < 1e-12][0].real, abs=1e-12)


def test_feedthrough_loop_input_memory_is_not_structural():
    """A law reading a displacement with feed-through adds u_{k-1}: not a plant pole."""
    dt, phi = 1 / 2000, 0.5
    plant = modal_plant([30.0, 70.0], 0.001, [phi, 0.3], d=1e-4)
    law = DiscreteController.static([DISP], [IN], [[-50.0]])
    poles = closed_loop_poles(plant, [law], dt)
    assert poles.structural.sum() == 2 and (~poles.structural).sum() == 1
    a, b, c, d = plant.discrete_matrices(dt)
    # hand-built loop: x+ = a x + b u, u+ = -g (c x+ + d u)
    g = 50.0
    top = np.hstack([a, b])
    bottom = -g * (c[0] @ top + np.r_[np.zeros(4), d[0, 0]])
    lam = np.linalg.eigvals(np.vstack([top, bottom]))
    np.testing.assert_allclose(np.sort_complex(lam), np.sort_complex(poles.all_lam), atol=1e-12)


def test_hungarian_pairing_beats_greedy():
    mac = np.array([[0.9, 0.8, 0.0], [0.85, 0.1, 0.0], [0.0, 0.0, 1.0]])
    rows, cols = pair_by_mac(mac)
    assert dict(zip(rows, cols)) == {0: 1, 1: 0, 2: 2}     # greedy row 0 -> 0 totals 2.0


def test_mac_pairing_with_permuted_modes_and_independent_shapes():
    """3 modes listed out of frequency order, coupled by one damper: MAC from the QEP."""
    freq = np.array([31.0, 12.0, 29.0])
    phi = np.array([0.9, 0.4, 0.8])
    g, z = 4.0, 0.001
    plant = modal_plant(freq, z, phi)
    poles = continuous_loop_poles(plant, [damper(g)])
    assert poles.structural.sum() == 3
    w = 2 * np.pi * freq
    for j in np.flatnonzero(poles.structural):
        s = poles.s[j]
        i = poles.mode[j]
        assert abs(poles.freq_hz[j] - freq[i]) < 0.5     # paired with its own mode
        # independent shape: null vector of s^2 I + s (2 Z W + g phi phi^T) + W^2
        qep = s ** 2 * np.eye(3) + s * (np.diag(2 * z * w) + g * np.outer(phi, phi)) \
            + np.diag(w ** 2)
        shape = np.linalg.svd(qep)[2][-1].conj()
        assert poles.mac[j] == pytest.approx(abs(shape[i]) ** 2 / np.sum(abs(shape) ** 2),
                                             rel=1e-8)
        assert mac_matrix(shape[:, None], np.eye(3))[0, i] == pytest.approx(poles.mac[j])
    # the 29 and 31 Hz modes are close: the damper mixes them, MAC < 1
    assert poles.mac[poles.structural].min() < 0.99
    assert sorted(poles.mode[poles.structural]) == [0, 1, 2]
    rows = poles.rows(plant)
    assert [r['mode'] for r in rows] == [2, 3, 1]            # by frequency: 12, 29, 31 Hz
    assert [r['open_freq_hz'] for r in rows] == pytest.approx([12.0, 29.0, 31.0])


def test_peak_terms_of_the_open_loop_are_the_modal_peaks():
    freq, z, phi = np.array([20.0, 55.0]), np.array([0.001, 0.004]), np.array([0.6, 0.9])
    plant = modal_plant(freq, z, phi)
    w = 2 * np.pi * freq
    cont = continuous_loop_poles(plant, [])
    peaks = cont.peaks(0, 0)
    order = cont.mode
    # the modal term phi^2 / (s^2 + 2 z w s + w^2) peaks at ~ phi^2 / (2 z w^2 sqrt(1 - z^2))
    np.testing.assert_allclose(peaks, phi[order] ** 2 / (2 * z[order] * w[order] ** 2
                                                         * np.sqrt(1 - z[order] ** 2)),
                               rtol=1e-10)
    sampled = closed_loop_poles(plant, [], 1 / 5000)
    np.testing.assert_allclose(sampled.peaks(0, 0), peaks, rtol=0.02)


@pytest.mark.slow
def test_statespace_closed_loop_poles_agree_with_python_control(tmp_path, capsys):
    from pentapod_sim.cli.statespace import main
    from pentapod_sim.plant.build import load_or_build_model
    rate, gain = 2000.0, 2e4
    assert main(['closed-loop', '--position', 'P1', '--out', str(tmp_path), '--damper',
                 f'tcp_force_x={gain}', '--poles', '--sample-rate', str(rate),
                 '--check-f-min', '1500']) == 0
    assert 'controller poles' in capsys.readouterr().out
    table = np.genfromtxt(tmp_path / 'loop_poles_P1.csv', delimiter=',', names=True)
    plant, _ = load_or_build_model(position='P1', cache_dir=tmp_path / 'models')
    assert table['mode'].size == np.count_nonzero(plant.frequencies_hz <= 400.0)
    np.testing.assert_allclose(table['open_zeta'], plant.zeta[:table.size])
    sub = plant.select(['tcp_force_x'], ['tcp_velocity_x'])
    cont = control.poles(control.feedback(sub.to_statespace(), gain))
    samp_z = control.poles(control.feedback(sub.discretize(1 / rate), gain))
    samp = np.log(samp_z.astype(complex)) * rate
    for kind, ref in (('continuous', cont), ('sampled', samp)):
        ref = ref[ref.imag > 0]
        freq, zeta = table[f'{kind}_freq_hz'], table[f'{kind}_zeta']
        for f, z in zip(freq, zeta):
            near = ref[np.argmin(np.abs(np.abs(ref) - 2 * np.pi * f))]
            assert abs(near) / (2 * np.pi) == pytest.approx(f, rel=1e-9)
            assert -near.real / abs(near) == pytest.approx(z, rel=1e-6, abs=1e-9)
    untouched = np.isclose(table['continuous_zeta'], table['open_zeta'], rtol=1e-9)
    assert untouched.any() and np.allclose(table['continuous_mac'][untouched], 1.0)
    assert np.all((table['sampled_mac'] > 0) & (table['sampled_mac'] <= 1 + 1e-12))
    assert table['sampled_zeta'][0] < table['continuous_zeta'][0]     # sampling costs damping


def _brute_force_classes(matrix_at, start, origin, steps=4000):
    """Nearest-neighbour tracking over many small gain steps (no refinement)."""
    from scipy.optimize import linear_sum_assignment
    lam = start
    for t in np.linspace(0, 1, steps + 1)[1:]:
        new = np.linalg.eigvals(matrix_at(t))
        rows, cols = linear_sum_assignment(np.abs(lam[:, None] - new[None, :]))
        labels = np.empty_like(origin)
        labels[cols] = origin[rows]
        lam, origin = new, labels
    return lam, origin


def test_poles_near_a_resonant_filter_are_classed_as_fine_tracking_classes_them():
    """Second-order low-pass at the mode's frequency: the filter and mode poles interact."""
    from pentapod_sim.sim.loop_poles import _open_loop_start, _scaled, continuous_loop_system
    w, wf, zf, phi, g = 2 * np.pi * 50.0, 2 * np.pi * 52.0, 0.05, 1.0, 40.0
    plant = modal_plant([50.0], 0.002, [phi])
    filt = DiscreteController([VEL], [IN], [[0, 1], [-wf ** 2, -2 * zf * wf]], [[0], [wf ** 2]],
                              [[-g, 0]], [[0.0]])
    poles = continuous_loop_poles(plant, [filt])

    def matrix_at(t):
        return continuous_loop_system(plant, [_scaled(filt, t)])[0]
    start, origin = _open_loop_start(plant, [filt], 4, None)
    lam, labels = _brute_force_classes(matrix_at, start, origin)
    for s, structural in zip(poles.s, poles.structural):
        k = np.argmin(np.abs(lam - s))
        assert abs(lam[k] - s) < 1e-9 * abs(s)
        assert structural == (labels[k] >= 0)
    assert poles.structural.sum() == 1
    # the loop's poles are those of python-control's feedback through the filter
    sys = control.ss([[0, 1], [-w ** 2, -2 * 0.002 * w]], [[0], [phi]], [[0, phi]], [[0]])
    ref = control.poles(control.feedback(sys, control.tf([g * wf ** 2],
                                                         [1, 2 * zf * wf, wf ** 2])))
    np.testing.assert_allclose(np.sort_complex(poles.all_lam), np.sort_complex(ref), rtol=1e-9)
