"""
FRFs without leakage: synchronous averaging of periodic records and the stepped-sine line fit.

Reference: the sampled 2-DOF chain (ZOH), simulated in the time domain by scipy.signal.dlsim,
against its closed-form discrete FRF ``C (zI - A)^-1 B + D`` at ``z = exp(j w dt)``.
"""
from modal_systems import multisine, TwoDof
import numpy as np
import pytest
import scipy.signal

from pentapod_sim.analysis.frf.periodic import synchronous_frf
from pentapod_sim.analysis.frf.stepped_sine import stepped_sine_frf

DT = 1e-3  # s


def sampled(system):
    """ZOH-sampled (A, B, C, D) of the 2-DOF chain (outputs: both displacements [m])."""
    a, b, c, d, _ = scipy.signal.cont2discrete((system.a, system.b, system.c_out,
                                                np.zeros((2, 1))), DT, method='zoh')
    return a, b, c, d


def discrete_frf(abcd, freq):
    """(2, F) closed-form FRF of the sampled system at ``freq`` [Hz]."""
    a, b, c, d = abcd
    z = np.exp(1j * 2 * np.pi * np.asarray(freq) * DT)
    return np.array([(c @ np.linalg.solve(zk * np.eye(len(a)) - a, b) + d)[:, 0] for zk in z]).T


def simulate(abcd, u, x0=None):
    a, b, c, d = abcd
    _, y, _ = scipy.signal.dlsim((a, b, c, d, DT), u, x0=x0)
    return y.T


def steady_state(abcd, u_period):
    """Initial state of the periodic steady state: x0 = (I - A^P)^-1 x_P(zero start)."""
    a, b, _, _ = abcd
    x = np.zeros(len(a))
    for uk in u_period:
        x = a @ x + b[:, 0] * uk
    return np.linalg.solve(np.eye(len(a)) - np.linalg.matrix_power(a, len(u_period)), x)


def test_synchronous_average_is_the_closed_form_frf_at_the_lines():
    system = TwoDof(zeta=(0.001, 0.02))
    abcd = sampled(system)
    period = 2000
    bins = np.arange(4, 201, 3)  # 2, 3.5, ... 100 Hz
    u_period = multisine(period, bins, rms=10.0)
    u = np.tile(u_period, 4)
    y = simulate(abcd, u, steady_state(abcd, u_period))
    lines = bins / (period * DT)
    expected = discrete_frf(abcd, lines)
    for out in range(2):
        res = synchronous_frf(u, y[out], DT, period, settle_periods=0, lines_hz=lines,
                              input_unit='N', output_unit='m')
        np.testing.assert_allclose(res.freq, lines)
        np.testing.assert_allclose(res.H, expected[out], rtol=1e-8)
        assert res.n_averages == 4 and res.unit == 'm/N'
        assert np.all(res.transient < 1e-8 * np.abs(expected[out]))
    # default lines: every bin that carries input, the same set
    res = synchronous_frf(u, y[0], DT, period, settle_periods=0)
    np.testing.assert_allclose(res.freq, lines)


def test_transient_error_flags_an_unsettled_start():
    """From rest, the 0.1 % mode (time constant 6.6 s) is far from periodic in the first 8 s."""
    system = TwoDof(zeta=(0.001, 0.02))
    abcd = sampled(system)
    period = 2000
    bins = np.arange(4, 201)
    u_period = multisine(period, bins)
    u = np.tile(u_period, 24)
    y = simulate(abcd, u)[0]
    expected = discrete_frf(abcd, bins / (period * DT))[0]
    early = synchronous_frf(u, y, DT, period, settle_periods=0, lines_hz=bins / (period * DT))
    late = synchronous_frf(u, y, DT, period, settle_periods=20, lines_hz=bins / (period * DT))
    peak = int(np.argmax(np.abs(expected)))
    err_early = np.abs(early.H - expected)
    err_late = np.abs(late.H - expected)
    assert err_late[peak] < 0.2 * err_early[peak]
    # the estimate sees the transient where the error is, and is of the error's size
    assert early.transient[peak] > 0.3 * err_early[peak]
    assert late.transient[peak] < 0.5 * early.transient[peak]


def test_noise_error_matches_the_scatter_of_the_estimate():
    """Normalised errors |H - H_true| / noise_std have mean square 1 (complex Gaussian)."""
    system = TwoDof(zeta=(0.01, 0.02))
    abcd = sampled(system)
    period = 1000
    bins = np.arange(5, 101)
    u_period = multisine(period, bins)
    n_periods = 16
    u = np.tile(u_period, n_periods)
    y = simulate(abcd, u, steady_state(abcd, u_period))[0]
    rng = np.random.default_rng(4)
    y_noisy = y + 0.05 * np.std(y) * rng.standard_normal(len(y))
    u_noisy = u + 0.02 * rng.standard_normal(len(u))
    lines = bins / (period * DT)
    res = synchronous_frf(u_noisy, y_noisy, DT, period, settle_periods=0, lines_hz=lines)
    ratio = np.abs(res.H - discrete_frf(abcd, lines)[0]) / res.noise_std
    assert 0.7 < np.mean(ratio ** 2) < 1.4
    # steady state: transient error / noise error is Rayleigh with median 2 sqrt(ln 2) = 1.67
    assert 1.3 < np.median(res.transient / res.noise_std) < 2.1


def test_stepped_sine_fit_matches_the_closed_form():
    system = TwoDof(zeta=(0.02, 0.05))  # slowest time constant 0.33 s
    abcd = sampled(system)
    lines = np.array([10.0, 20.0, 24.0, 24.5, 30.0, 49.5, 70.0])
    settle, window = 3000, 2000  # steps
    u, windows, step = [], [], 0
    for f in lines:
        t = np.arange(settle + window) * DT
        u.append(5.0 * np.sin(2 * np.pi * f * t))
        windows.append((f, step + settle, step + settle + window))
        step += settle + window
    u = np.concatenate(u)
    y = simulate(abcd, u)
    res = stepped_sine_frf(u, y[1], DT, windows, 'N', 'm')
    expected = discrete_frf(abcd, lines)[1]
    np.testing.assert_allclose(res.freq, lines)
    np.testing.assert_allclose(res.H, expected, rtol=2e-3)
    unsettled = stepped_sine_frf(u, y[1], DT, [(f, a - settle, b - settle) for f, a, b in windows])
    err = np.abs(unsettled.H - expected)
    worst = int(np.argmax(err))
    assert err[worst] > 10 * np.abs(res.H - expected)[worst]
    assert unsettled.transient[worst] > 0.3 * err[worst]
    assert np.all(res.transient < 0.1 * unsettled.transient[worst])


def test_bad_records_give_clear_errors():
    u = np.sin(np.arange(3000) * 0.1)
    with pytest.raises(ValueError, match='need at least 2'):
        synchronous_frf(u, u, DT, 1000, settle_periods=2)
    with pytest.raises(ValueError, match='would leak'):
        synchronous_frf(u, u, DT, 1000, settle_periods=0, lines_hz=[10.5])
    with pytest.raises(ValueError, match='does not lie in the record'):
        stepped_sine_frf(u, u, DT, [(10.0, 2000, 4000)])
