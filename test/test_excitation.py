"""Excitation signals against their definitions."""
import numpy as np
from numpy.testing import assert_allclose
import pytest
import scipy.signal

from pentapod_sim.errors import ConfigError
from pentapod_sim.sim.excitation import Excitation, ExcitationSpec

DT = 1e-4


def test_sine_with_delay_and_duration():
    sig = Excitation(ExcitationSpec('sine', 7.0, [0, 0, 2], frequency=33.0, start_delay=0.01,
                                    duration=0.05), DT)
    f = sig.series(1000)
    assert_allclose(f[:, :2], 0.0)
    k = np.arange(1000)
    tau = (k - 100) * DT
    expected = np.where((k >= 100) & (k < 600), 7.0 * np.sin(2 * np.pi * 33.0 * tau), 0.0)
    assert_allclose(f[:, 2], expected, atol=1e-12)


def test_impulse_area_and_width():
    sig = Excitation(ExcitationSpec('impulse', 500.0, [1, 1, 0], pulse_width=3e-4), DT)
    f = sig.series(20)
    magnitude = np.linalg.norm(f, axis=1)
    assert_allclose(magnitude[:3], 500.0)
    assert_allclose(magnitude[3:], 0.0)
    assert_allclose(f[0, 0], 500.0 / np.sqrt(2))
    assert sig.magnitude(0) * DT * 3 == pytest.approx(0.15)    # impulse [N s]


def test_step():
    sig = Excitation(ExcitationSpec('step', -3.0, [0, 1, 0], start_delay=2 * DT), DT)
    assert_allclose(sig.series(5)[:, 1], [0, 0, -3, -3, -3])


def test_chirp_is_linear_sweep():
    f0, f1, T = 10.0, 200.0, 0.5
    sig = Excitation(ExcitationSpec('chirp', 2.0, [1, 0, 0], f_start=f0, f_end=f1,
                                    duration=T), DT)
    tau = np.arange(int(T / DT)) * DT
    expected = 2.0 * np.sin(2 * np.pi * (f0 * tau + (f1 - f0) * tau ** 2 / (2 * T)))
    assert_allclose(sig.series(tau.size)[:, 0], expected, atol=1e-9)


def test_random_is_seeded_band_limited_with_rms():
    spec = ExcitationSpec('random', 25.0, [1, 0, 0], f_start=50.0, f_end=400.0, duration=2.0,
                          seed=4)
    a = Excitation(spec, DT).series(20000)[:, 0]
    b = Excitation(spec, DT).series(20000)[:, 0]
    assert_allclose(a, b)
    assert np.sqrt(np.mean(a ** 2)) == pytest.approx(25.0, rel=1e-12)
    freq, psd = scipy.signal.welch(a, fs=1 / DT, nperseg=4096)
    inside = (freq >= 40) & (freq <= 500)
    assert psd[inside].sum() / psd.sum() > 0.99
    other = Excitation(ExcitationSpec('random', 25.0, [1, 0, 0], f_start=50.0, f_end=400.0,
                                      duration=2.0, seed=5), DT).series(100)
    assert not np.allclose(other[:, 0], a[:100])


@pytest.mark.parametrize(('spec', 'match'), [
    (ExcitationSpec('hammer'), 'hammer'),
    (ExcitationSpec('sine', frequency=6000.0), 'frequency'),
    (ExcitationSpec('chirp'), 'finite duration'),
    (ExcitationSpec('random', duration=1.0, f_start=300.0, f_end=100.0), 'f_start'),
    (ExcitationSpec(direction=[0, 0, 0]), 'direction'),
    (ExcitationSpec(start_delay=-1.0), 'start_delay'),
])
def test_bad_specs_are_named(spec, match):
    with pytest.raises(ConfigError, match=match):
        Excitation(spec, DT)
