"""Damper and proof-mass actuator laws against their closed-form behaviour."""
import numpy as np
from numpy.testing import assert_allclose
import pytest
import scipy.signal

from pentapod_damper.laws import (
    ProofMassActuator,
    strut_axial_damper,
    strut_bending_damper,
    tcp_damper,
    ViscousDamper,
)
from pentapod_sim.errors import ConfigError


def test_viscous_dampers_use_collocated_rates():
    law = strut_bending_damper([2, 5], 300.0)
    assert law.actuator_ports == ['strut2_bending_moment_2', 'strut2_bending_moment_3',
                                  'strut5_bending_moment_2', 'strut5_bending_moment_3']
    assert law.sensor_ports == ['strut2_bending_rate_2', 'strut2_bending_rate_3',
                                'strut5_bending_rate_2', 'strut5_bending_rate_3']
    rates = np.array([0.1, -0.2, 0.3, 0.0])
    assert_allclose(law.step(rates), -300.0 * rates)
    assert_allclose(law.linear_gain() @ rates, -300.0 * rates)
    assert strut_axial_damper([1], 5e4).sensor_ports == ['strut1_axial_velocity']
    assert tcp_damper(['z', 'x'], 1.0).sensor_ports == ['tcp_velocity_z', 'tcp_velocity_x']


@pytest.mark.parametrize(('call', 'match'), [
    (lambda: strut_bending_damper([0], 1.0), 'strut number 0'),
    (lambda: strut_axial_damper([1, 1], 1.0), 'repeat'),
    (lambda: tcp_damper(['w'], 1.0), "'w'"),
    (lambda: ViscousDamper(['tcp_force_x'], -5.0), 'tcp_force_x'),
    (lambda: ProofMassActuator(['x'], 0.0, 1.0, 1e-3), 'proof mass'),
    (lambda: ProofMassActuator(['x'], 1.0, np.nan, 1e-3), 'gain'),
    (lambda: ProofMassActuator(['x'], 1.0, 1.0, 1e-3, highpass_hz=600.0), 'highpass_hz'),
])
def test_bad_parameters_are_named(call, match):
    with pytest.raises(ConfigError, match=match):
        call()


def harmonic_run(law, velocity_amplitude, omega, dt, n):
    """Feed v_k = V cos(omega t_k); return forces on the structure and strokes per step."""
    t = np.arange(n) * dt
    v = velocity_amplitude * np.cos(omega * t)
    forces, strokes, mass_velocity = [], [], []
    for v_k in v:
        forces.append(law.step(np.array([v_k]))[0])
        strokes.append(law.stroke[0])
        mass_velocity.append(law.mass_velocity[0])
    return t, v, np.array(forces), np.array(strokes), np.array(mass_velocity)


def test_pma_ideal_law_harmonic_response():
    """F = -m g v; proof mass w_k = g dt sum v_j (closed-form sum); stroke amplitude."""
    mass, gain, amp, omega, dt, n = 5.0, 4000.0, 1e-3, 2 * np.pi * 40.0, 1e-5, 20000
    law = ProofMassActuator(['x'], mass, gain, dt)
    t, v, force, stroke, w = harmonic_run(law, amp, omega, dt, n)
    assert_allclose(force, -mass * gain * v, rtol=1e-15)
    # w after step k: g dt V sum_{j=0..k} cos(j theta) (Dirichlet kernel), theta = omega dt
    theta, k = omega * dt, np.arange(n)
    w_exact = gain * dt * amp * np.sin((k + 1) * theta / 2) * np.cos(k * theta / 2) / \
        np.sin(theta / 2)
    assert_allclose(w, w_exact, atol=1e-9 * np.abs(w_exact).max())
    # continuous law: stroke = int (w - v) oscillates with amplitude V/omega sqrt(1 + (g/omega)^2)
    basis = np.column_stack([np.ones(n), t, np.cos(omega * t), np.sin(omega * t)])
    coef, *_ = np.linalg.lstsq(basis, stroke, rcond=None)
    expected = amp / omega * np.hypot(1, gain / omega)
    assert np.hypot(coef[2], coef[3]) == pytest.approx(expected, rel=2 * omega * dt)


def test_pma_highpass_follows_filter_response():
    """Steady-state force amplitude and phase equal m g H(e^{j omega dt}) of the filter."""
    mass, gain, f_hp, dt, f = 1.0, 2e4, 10.0, 2e-4, 15.0
    law = ProofMassActuator(['x'], mass, gain, dt, highpass_hz=f_hp)
    assert law.linear_gain() is None
    omega = 2 * np.pi * f
    n = int(2.0 / dt)
    t, v, force, _, _ = harmonic_run(law, 1.0, omega, dt, n)
    sos = scipy.signal.butter(2, f_hp, 'highpass', fs=1 / dt, output='sos')
    _, h = scipy.signal.sosfreqz(sos, worN=[f], fs=1 / dt)
    tail = slice(n // 2, n)
    basis = np.column_stack([np.cos(omega * t[tail]), np.sin(omega * t[tail])])
    coef, *_ = np.linalg.lstsq(basis, -force[tail], rcond=None)
    measured = coef[0] - 1j * coef[1]            # phasor of -F against cos
    assert measured == pytest.approx(mass * gain * h[0], rel=1e-6)


def test_pma_limits_hold():
    """Commanded force clipped to force_limit; the end stop keeps |stroke| <= stroke_limit."""
    dt = 1e-4
    law = ProofMassActuator(['x'], 1.0, 2e4, dt, force_limit=50.0)
    _, _, force, _, _ = harmonic_run(law, 0.01, 2 * np.pi * 5.0, dt, 5000)
    assert np.max(np.abs(force)) == pytest.approx(50.0, rel=1e-12)
    assert law.limit_hits['force'] > 0 and law.limit_hits['stroke'] == 0
    law = ProofMassActuator(['x'], 1.0, 2e4, dt, stroke_limit=1e-3)
    _, _, _, stroke, _ = harmonic_run(law, 0.01, 2 * np.pi * 5.0, dt, 20000)
    assert np.max(np.abs(stroke)) == pytest.approx(1e-3, rel=1e-9)
    assert law.limit_hits['stroke'] > 0
    assert law.linear_gain() is None
