"""FRF estimation and damping identification against a 2-DOF system with a closed-form FRF."""
import warnings

import numpy as np
from numpy.testing import assert_allclose
import pytest
from scipy import linalg, signal

from pentapod_sim.analysis.frf.estimation import amplitude_spectrum, estimate_frf
from pentapod_sim.analysis.frf.peaks import find_resonances, peak_reductions

FS = 1000.0  # Hz
F_MODES = (20.0, 50.0)  # Hz, natural frequencies of the test structure
ZETA = 0.02


def two_dof(zeta: float = ZETA):
    """Mass, stiffness, damping (modal damping zeta on both modes) of a 2-DOF chain."""
    m = np.diag([2.0, 1.0])  # kg
    # choose K so that the undamped frequencies are F_MODES with mass-normalised modes
    phi = np.array([[1.0, 1.0], [1.0, -2.0]])  # M-orthogonal: 2*1*1 + 1*1*(-2) = 0
    phi = phi / np.sqrt(np.diag(phi.T @ m @ phi))
    omega = 2 * np.pi * np.asarray(F_MODES)
    phi_inv = np.linalg.inv(phi)
    k = phi_inv.T @ np.diag(omega ** 2) @ phi_inv
    c = phi_inv.T @ np.diag(2 * zeta * omega) @ phi_inv
    return m, k, c


def analytic_frf(freq, zeta: float = ZETA):
    """Receptance x1/F1 [m/N] = [K - w^2 M + j w C]^-1 [0, 0]."""
    m, k, c = two_dof(zeta)
    w = 2 * np.pi * np.asarray(freq)
    return np.array([np.linalg.inv(k - wi ** 2 * m + 1j * wi * c)[0, 0] for wi in w])


def zoh_system(zeta: float = ZETA):
    """(Ad, Bd, Cd, Dd) of the 2-DOF chain, force on mass 1 -> x1, exact ZOH at FS."""
    m, k, c = two_dof(zeta)
    minv = np.linalg.inv(m)
    a = np.block([[np.zeros((2, 2)), np.eye(2)], [-minv @ k, -minv @ c]])
    b = np.concatenate([np.zeros((2, 1)), minv[:, :1]])
    cmat = np.array([[1.0, 0.0, 0.0, 0.0]])
    return signal.cont2discrete((a, b, cmat, np.zeros((1, 1))), 1 / FS)[:4]


def sampled_frf(freq, zeta: float = ZETA):
    """
    FRF of the sampled (ZOH) system, C (z I - Ad)^-1 Bd at z = exp(j 2 pi f / FS) [m/N].

    This is what the simulated records obey exactly; it differs from the continuous FRF by
    the ZOH (about half a sample of delay), e.g. 0.1 rad of phase at 33 Hz.
    """
    ad, bd, cd, _ = zoh_system(zeta)
    z = np.exp(2j * np.pi * np.asarray(freq) / FS)
    return np.array([(cd @ np.linalg.solve(zi * np.eye(4) - ad, bd))[0, 0] for zi in z])


def simulate(force, zeta: float = ZETA):
    """Displacement x1 [m] for a force on mass 1 [N], exact ZOH discretisation."""
    _, y, _ = signal.dlsim(zoh_system(zeta) + (1 / FS,), force)
    return y[:, 0]


def test_modes_of_test_structure_are_as_designed():
    m, k, _ = two_dof()
    w2 = linalg.eigh(k, m, eigvals_only=True)
    assert_allclose(np.sqrt(w2) / (2 * np.pi), F_MODES, rtol=1e-10)


@pytest.fixture(scope='module')
def random_record():
    rng = np.random.default_rng(1)
    force = rng.normal(0.0, 10.0, 16384 * 9)  # N
    return force, simulate(force)


def test_random_excitation_h1_matches_closed_form(random_record):
    force, x1 = random_record
    res = estimate_frf(force, x1, FS, 'random', nperseg=16384, input_unit='N',
                       output_unit='m')
    assert res.unit == 'm/N' and res.n_averages == 17
    good = (res.coherence > 0.95) & (res.freq > 2) & (res.freq < 200)
    assert good.sum() > 0.8 * np.sum((res.freq > 2) & (res.freq < 200))
    exact = sampled_frf(res.freq[good])
    assert_allclose(np.abs(res.H[good]), np.abs(exact), rtol=0.08)
    phase_err = np.angle(res.H[good] / exact)
    assert np.max(np.abs(phase_err)) < 0.1  # rad
    # noise-free data: H1 and H2 agree where coherence is high
    assert_allclose(np.abs(res.H2[good]), np.abs(res.H1[good]), rtol=0.08)


def test_h1_h2_bracket_true_frf_with_output_noise(random_record):
    force, x1 = random_record
    rng = np.random.default_rng(2)
    noisy = x1 + rng.normal(0.0, 0.3 * np.std(x1), len(x1))
    res = estimate_frf(force, noisy, FS, 'random', nperseg=4096)
    band = (res.freq > 5) & (res.freq < 150)
    # output noise biases H2 upwards, leaves H1 unbiased: |H1| <= |H2| (Cauchy-Schwarz)
    assert np.all(np.abs(res.H1[band]) <= np.abs(res.H2[band]) * (1 + 1e-9))
    assert np.median(res.coherence[band]) < 0.99


def test_random_damping_and_frequencies_identified(random_record):
    force, x1 = random_record
    res = estimate_frf(force, x1, FS, 'random', nperseg=16384)
    peaks = find_resonances(res, fmin=5, fmax=150)
    assert len(peaks) == 2
    assert_allclose([p.freq for p in peaks], F_MODES, rtol=0.01)
    assert_allclose([p.damping_ratio for p in peaks], [ZETA, ZETA], rtol=0.15)
    exact = np.abs(analytic_frf([p.freq for p in peaks]))
    assert_allclose([p.magnitude for p in peaks], exact, rtol=0.1)


def test_impulse_excitation_frf_and_damping():
    n = int(20 * FS)
    force = np.zeros(n)
    force[100:103] = 500.0 * np.sin(np.pi * np.arange(1, 4) / 4)  # short half-sine hammer
    x1 = simulate(force)
    with pytest.warns(UserWarning, match='impulse spectrum falls below'):  # 3-sample pulse
        res = estimate_frf(force, x1, FS, 'impulse')
    assert res.exp_window_tau is None  # response decayed within the record
    band = (res.freq > 2) & (res.freq < 150)
    assert_allclose(res.H[band], sampled_frf(res.freq[band]), rtol=0.02)
    peaks = find_resonances(res, fmin=5, fmax=150)
    assert_allclose([p.freq for p in peaks], F_MODES, rtol=0.005)
    assert_allclose([p.damping_ratio for p in peaks], [ZETA, ZETA], rtol=0.1)


def test_impulse_exponential_window_damping_is_removed():
    zeta = 0.005
    n = int(4 * FS)
    force = np.zeros(n)
    force[10] = 1000.0
    x1 = simulate(force, zeta)
    with warnings.catch_warnings():
        warnings.simplefilter('ignore')
        res = estimate_frf(force, x1, FS, 'impulse')
        peaks = find_resonances(res, fmin=30, fmax=150)
    assert res.exp_window_tau is not None
    # the 50 Hz mode: window damping 1/(2 pi 50 tau) ~ 0.006 is added, then subtracted again
    assert_allclose(peaks[0].freq, F_MODES[1], rtol=0.01)
    assert abs(peaks[0].damping_ratio - zeta) < 0.4 * zeta


def test_sine_excitation_gives_one_point():
    t = np.arange(int(10 * FS)) / FS
    force = 20.0 * np.sin(2 * np.pi * 33.0 * t)
    x1 = simulate(force)
    res = estimate_frf(force, x1, FS, 'sine')
    assert_allclose(res.freq, [33.0], rtol=1e-3)
    assert_allclose(res.H, sampled_frf([33.0]), rtol=0.01)
    assert res.coherence[0] > 0.999


def test_chirp_excitation_matches_closed_form():
    t = np.arange(int(60 * FS)) / FS
    force = 10.0 * signal.chirp(t, 5.0, t[-1], 150.0)
    x1 = simulate(force)
    res = estimate_frf(force, x1, FS, 'chirp', nperseg=8192)
    good = (res.coherence > 0.95) & (res.freq > 10) & (res.freq < 140)
    assert good.sum() > 100
    assert_allclose(np.abs(res.H[good]), np.abs(sampled_frf(res.freq[good])), rtol=0.1)


def test_peak_reduction_between_damping_levels(random_record):
    force, x1 = random_record
    x1_damped = simulate(force, 4 * ZETA)
    low = find_resonances(estimate_frf(force, x1, FS, nperseg=16384), fmin=5, fmax=150)
    high = find_resonances(estimate_frf(force, x1_damped, FS, nperseg=16384), fmin=5,
                           fmax=150)
    rows = peak_reductions(low, high)
    assert len(rows) == 2
    # SDOF-like peaks scale with 1/zeta: 4x damping lowers each peak by about 12 dB
    assert_allclose([r.reduction_db for r in rows], [20 * np.log10(4)] * 2, atol=1.5)


def test_amplitude_spectrum_recovers_sine_amplitude():
    t = np.arange(int(20 * FS)) / FS
    stroke = 2e-3 * np.sin(2 * np.pi * 40.0 * t)  # m
    freq, amp = amplitude_spectrum(stroke, FS, nperseg=4000)
    k = np.argmax(amp)
    assert_allclose(freq[k], 40.0)
    assert_allclose(amp[k], 2e-3, rtol=0.01)  # bin-centred sine: Hann amplitude is exact


@pytest.mark.parametrize('bad', [
    {'excitation': 'hammer'}, {'fs': -1.0}, {'u': np.zeros(100)}, {'u': np.ones(5)}])
def test_bad_arguments_raise_value_error(bad):
    kwargs = {'u': np.ones(100), 'y': np.ones(100), 'fs': FS, 'excitation': 'random'}
    kwargs.update(bad)
    if len(kwargs['u']) != len(kwargs['y']):
        kwargs['y'] = np.ones(len(kwargs['u']))
    with pytest.raises(ValueError):
        estimate_frf(**kwargs)


def test_analyze_cli_end_to_end(tmp_path, random_record, capsys):
    import csv

    from fixtures.cdr import encode_joint_state, encode_wrench_stamped
    from pentapod_sim.cli.analyze import main
    from pentapod_sim.recording import BagWriter
    force, x1 = random_record
    n = 16384 * 4
    with BagWriter(tmp_path / 'run', run_info={'scenario': 'random'}) as writer:
        writer.add_topic('/pentapod/excitation', 'geometry_msgs/msg/WrenchStamped')
        writer.add_topic('/pentapod/tcp_state', 'sensor_msgs/msg/JointState')
        for k in range(n):
            t_ns = k * 1_000_000  # 1 kHz
            writer.write('/pentapod/excitation', encode_wrench_stamped(t_ns, [force[k], 0, 0]),
                         t_ns)
            writer.write('/pentapod/tcp_state',
                         encode_joint_state(t_ns, ['tcp_x'], [x1[k]], [0.0]), t_ns)
    out = tmp_path / 'analysis'
    code = main(['--out', str(out), 'frf', str(tmp_path / 'run'),
                 '--input', '/pentapod/excitation.force.x',
                 '--output', '/pentapod/tcp_state.position.tcp_x', '--nperseg', '16384',
                 '--fmax', '150'])
    assert code == 0
    assert 'peak' in capsys.readouterr().out
    suffixes = sorted(p.suffix for p in out.iterdir())
    assert suffixes == ['.csv', '.csv', '.png', '.uff']
    peaks_csv = next(p for p in out.iterdir() if p.name.endswith('_peaks.csv'))
    with open(peaks_csv, newline='') as handle:
        rows = list(csv.DictReader(handle))
    assert_allclose([float(r['freq_Hz']) for r in rows], F_MODES, rtol=0.01)
    assert_allclose([float(r['damping_ratio']) for r in rows], [ZETA, ZETA], rtol=0.15)
    assert main(['info', str(tmp_path / 'run')]) == 0
    assert 'scenario = random' in capsys.readouterr().out
    assert main(['info', str(tmp_path / 'nothing')]) == 1  # BagError -> exit code 1
