"""Signals for lightly damped structures against closed forms: multisine, chirp, stepped sine."""
import json
import math

import numpy as np
from numpy.testing import assert_allclose, assert_array_equal
import pytest

from pentapod_sim.errors import ConfigError
from pentapod_sim.sim.excitation import Excitation, ExcitationSpec, spec_from_dict, spec_to_dict
from pentapod_sim.sim.excitation_spec import parse_spec_message, spec_message

DT = 2e-4                     # 5 kHz


def magnitudes(sig: Excitation, n: int) -> np.ndarray:
    return sig.series(n) @ sig.direction


def multisine(phases='schroeder', **kw) -> Excitation:
    spec = {'kind': 'multisine', 'amplitude': 40.0, 'direction': [0, 1, 0], 'period': 0.2,
                'f_start': 10.0, 'f_end': 500.0, 'phases': phases, 'start_delay': 0.01}
    return Excitation(ExcitationSpec(**{**spec, **kw}), DT)


def test_multisine_has_energy_on_its_lines_only_with_equal_amplitudes():
    sig = multisine()
    period = sig.period_steps
    assert period == 1000                                   # 0.2 s at 5 kHz
    lines = np.arange(2, 101) * 5.0                         # k / 0.2 s in [10, 500] Hz
    assert_allclose(sig.lines_hz, lines, rtol=1e-12)
    x = magnitudes(sig, sig.first + 3 * period)[sig.first + period:sig.first + 2 * period]
    spectrum = np.abs(np.fft.rfft(x))
    on = np.zeros(spectrum.size, bool)
    on[np.round(lines * period * DT).astype(int)] = True
    assert spectrum[~on].max() < 1e-10 * spectrum[on].min()
    assert_allclose(spectrum[on], spectrum[on][0], rtol=1e-9)    # flat: equal amplitudes
    assert np.max(np.abs(x)) == pytest.approx(40.0, rel=1e-12)  # peak = amplitude


def test_chosen_multisine_lines_and_a_line_off_the_grid():
    sig = multisine(frequencies=[25.0, 80.0, 35.0])
    assert_allclose(sig.lines_hz, [25.0, 35.0, 80.0])
    x = magnitudes(sig, sig.first + sig.period_steps)[sig.first:]
    spectrum = np.abs(np.fft.rfft(x))
    assert sorted(np.argsort(spectrum)[-3:]) == [5, 7, 16]
    assert np.sort(spectrum)[-4] < 1e-10 * spectrum.max()
    with pytest.raises(ConfigError, match='27.5'):
        multisine(frequencies=[25.0, 27.5])


def test_schroeder_crest_factor_is_lower_than_zero_phase_and_reported():
    schroeder, zero, random = (multisine(p) for p in ('schroeder', 'zero', 'random'))
    n_lines = len(zero.lines_hz)
    # zero phase: peak L (all cosines at n = 0), RMS sqrt(L / 2)
    assert zero.crest_factor == pytest.approx(math.sqrt(2 * n_lines), rel=1e-9)
    assert schroeder.crest_factor < 2.0 < random.crest_factor < zero.crest_factor
    for sig in (schroeder, zero, random):
        x = magnitudes(sig, sig.first + sig.period_steps)[sig.first:]
        assert sig.crest_factor == pytest.approx(np.abs(x).max() / np.sqrt(np.mean(x ** 2)))


def test_random_phases_are_seeded():
    a, b = multisine('random', seed=3), multisine('random', seed=3)
    c = multisine('random', seed=4)
    n = a.first + a.period_steps
    assert_array_equal(a.series(n), b.series(n))
    assert not np.allclose(a.series(n), c.series(n))


@pytest.mark.parametrize('kind', ['multisine', 'periodic_chirp'])
def test_periodic_kinds_repeat_exactly_every_period(kind):
    sig = Excitation(ExcitationSpec(kind, 5.0, [1, 0, 0], period=0.05, f_start=20.0,
                                    f_end=900.0, start_delay=3 * DT, duration=0.2), DT)
    period = sig.period_steps
    assert period == 250
    x = magnitudes(sig, 1200)
    assert_array_equal(x[:3], 0.0)
    active = x[3:3 + 1000]                                  # 0.2 s = 4 periods
    assert_array_equal(active[period:], active[:-period])   # x[k + P] == x[k], bit for bit
    assert_array_equal(x[3 + 1000:], 0.0)                   # ends after duration


def test_periodic_chirp_is_a_linear_sweep_within_each_period():
    f0, f1, period = 10.0, 400.0, 0.1
    sig = Excitation(ExcitationSpec('periodic_chirp', 2.0, [0, 0, 1], period=period,
                                    f_start=f0, f_end=f1), DT)
    tau = np.arange(500) * DT
    one = 2.0 * np.sin(2 * np.pi * (f0 * tau + (f1 - f0) * tau ** 2 / (2 * period)))
    assert_allclose(magnitudes(sig, 1500), np.tile(one, 3), atol=1e-9)
    assert sig.settle_periods == 1 and sig.crest_factor == pytest.approx(math.sqrt(2), rel=0.02)


def test_stepped_sine_windows_hold_whole_periods_after_settling():
    requested = [27.0, 31.3, 12.5]
    sig = Excitation(ExcitationSpec('stepped_sine', 3.0, [1, 0, 0], frequencies=requested,
                                    settle_time=0.1, periods_per_line=7, start_delay=0.02), DT)
    windows = sig.stepped_windows()
    assert [w[0] for w in windows] == pytest.approx(list(sig.lines_hz))
    settle, first = round(0.1 / DT), round(0.02 / DT)
    x = magnitudes(sig, windows[-1][2] + 100)
    previous_end = first
    for (f, start, end), wanted in zip(windows, requested):
        n = end - start
        assert start == previous_end + settle               # settled, then measured
        assert f * n * DT == pytest.approx(7.0, abs=1e-9)   # whole periods in whole samples
        assert abs(f - wanted) <= wanted / (2 * n) * (1 + 1e-9)
        spectrum = np.abs(np.fft.rfft(x[start:end]))
        assert np.argmax(spectrum) == 7                     # leakage free: one bin only
        assert np.delete(spectrum, 7).max() < 1e-9 * spectrum[7]
        assert spectrum[7] == pytest.approx(3.0 * n / 2, rel=1e-9)
        previous_end = end
    assert_array_equal(x[windows[-1][2]:], 0.0)             # ends after its last line
    assert np.max(np.abs(np.diff(x[first:windows[-1][2]]))) < 3.0 * 2 * np.pi * 31.3 * DT * 1.01
    again = Excitation(sig.spec, DT)
    assert_array_equal(magnitudes(again, len(x)), x)        # deterministic


def test_stepped_sine_lines_from_the_band():
    sig = Excitation(ExcitationSpec('stepped_sine', f_start=10.0, f_end=20.0, line_spacing=2.5,
                                    settle_time=0.0, periods_per_line=50), DT)
    assert_allclose(sig.lines_hz, [10, 12.5, 15, 17.5, 20], rtol=1 / (2 * 50 / 20 / DT))
    assert sig.period_steps is None and sig.settle_periods == 0
    with pytest.raises(ConfigError, match='duration 0.5 s'):
        Excitation(ExcitationSpec('stepped_sine', f_start=10.0, f_end=20.0, line_spacing=2.5,
                                  duration=0.5), DT)


@pytest.mark.parametrize('width', [2e-3, 4e-3])
def test_half_sine_pulse_spectrum_matches_its_closed_form(width):
    amplitude = 50.0
    sig = Excitation(ExcitationSpec('impulse', amplitude, [1, 0, 0], pulse_width=width,
                                    pulse_shape='half_sine'), DT)
    x = magnitudes(sig, 400)
    assert np.count_nonzero(x) == round(width / DT)
    freq = np.fft.rfftfreq(8192, DT)
    measured = DT * np.abs(np.fft.rfft(x, 8192))            # [N s]
    # continuous half sine A sin(pi t / W), 0 <= t <= W
    closed = (amplitude * 2 * width / np.pi * np.abs(np.cos(np.pi * freq * width))
              / np.abs(1 - (2 * freq * width) ** 2))
    band = freq <= 3 / width
    n = round(width / DT)
    tol = 1.5 * (np.pi / n) ** 2 / 24 * closed[0]           # midpoint rule
    assert np.max(np.abs(measured[band] - closed[band])) < tol
    assert measured[0] == pytest.approx(amplitude * 2 * width / np.pi, rel=(np.pi / n) ** 2 / 20)


def test_pulse_shapes_and_their_crest_factors():
    rect = Excitation(ExcitationSpec('impulse', 8.0, pulse_width=5 * DT), DT)
    hann = Excitation(ExcitationSpec('impulse', 8.0, pulse_width=5 * DT, pulse_shape='hann'), DT)
    assert_allclose(magnitudes(rect, 7), [8, 8, 8, 8, 8, 0, 0])
    s = (np.arange(5) + 0.5) / 5
    assert_allclose(magnitudes(hann, 7)[:5], 8.0 * np.sin(np.pi * s) ** 2)
    assert rect.crest_factor == 1.0
    one = Excitation(ExcitationSpec('impulse', 8.0, pulse_shape='half_sine'), DT)
    assert_allclose(magnitudes(one, 3), [8.0, 0, 0])        # width 0: one sample at the peak


@pytest.mark.parametrize(('changes', 'named'), [
    ({'kind': 'multisine', 'period': 0.00031}, '0.00031'),
    ({'kind': 'periodic_chirp', 'period': -1.0}, 'period'),
    ({'kind': 'multisine', 'f_start': 10.0, 'f_end': 11.0, 'period': 0.05}, 'no multisine line'),
    ({'kind': 'multisine', 'phases': 'flat'}, "'flat'"),
    ({'kind': 'impulse', 'pulse_shape': 'triangle'}, "'triangle'"),
    ({'kind': 'stepped_sine', 'periods_per_line': 0}, 'periods_per_line'),
    ({'kind': 'stepped_sine', 'frequencies': [30.0, 2600.0]}, '2600'),
    ({'kind': 'stepped_sine', 'f_start': 0.0}, 'f_start'),
    ({'kind': 'stepped_sine', 'settle_time': -1.0}, 'settle_time'),
    ({'kind': 'multisine', 'settle_periods': -2}, 'settle_periods'),
])
def test_bad_parameters_are_named(changes, named):
    with pytest.raises(ConfigError, match=named):
        Excitation(ExcitationSpec(**changes), DT)


def test_spec_round_trips_through_json_with_inf():
    spec = ExcitationSpec('stepped_sine', -2.5, [0.0, 0.6, 0.8], frequencies=[27.0, 31.5],
                          settle_time=0.3, periods_per_line=4, seed=9, pulse_shape='hann')
    data = json.loads(json.dumps(spec_to_dict(spec), allow_nan=False))
    assert data['duration'] == 'inf'
    assert spec_from_dict(data) == spec
    assert spec_from_dict({}) == ExcitationSpec()
    back, dt, source = parse_spec_message(spec_message(spec, 5000.0, 'exciter'))
    assert (back, dt, source) == (spec, 1 / 5000.0, 'exciter')
    with pytest.raises(ConfigError, match='frequncy'):
        spec_from_dict({'frequncy': 3.0})
    with pytest.raises(ConfigError, match='periods_per_line'):
        spec_from_dict({'periods_per_line': 2.5})
