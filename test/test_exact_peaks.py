"""Exact FRF peaks against closed forms and dense grids (no ROS)."""
import numpy as np
import pytest

from fixtures.demo_model import demo_model
from pentapod_sim.errors import ConfigError
from pentapod_sim.plant.frf import closed_loop_frf, modal_frf
from pentapod_sim.plant.frf_peaks import exact_peak, maximise_near_poles, plant_pair_frf
from pentapod_sim.plant.model import PlantModel


def one_dof(k: float, m: float, zeta: float) -> PlantModel:
    """Mass m on a spring k with damping ratio zeta, force and displacement at the mass."""
    omega = np.sqrt(k / m)
    b = 1.0 / np.sqrt(m)            # mass-normalised shape
    return PlantModel([omega], [zeta], [[b]], [[b], [0.0]], [[0.0], [b]], [[0.0], [0.0]],
                      ['tcp_force_x'], ['tcp_displacement_x', 'tcp_velocity_x'],
                      ['N'], ['m', 'm/s'], ['f'], ['x', 'v'])


@pytest.mark.parametrize('zeta', [1e-3, 0.02, 0.3])
def test_single_dof_peak_is_the_closed_form(zeta):
    k, m = 2.0e7, 50.0
    plant = one_dof(k, m, zeta)
    frf = plant_pair_frf(plant, 'tcp_displacement_x', 'tcp_force_x')
    wn = np.sqrt(k / m)
    f_peak = wn * np.sqrt(1 - 2 * zeta ** 2) / (2 * np.pi)
    peak = exact_peak(frf, 1.0, 400.0)
    assert peak.value == pytest.approx(1.0 / (k * 2 * zeta * np.sqrt(1 - zeta ** 2)), rel=1e-12)
    assert peak.freq_hz == pytest.approx(f_peak, rel=1e-6)
    # a 0.1 Hz grid misses the top of a 0.1 % peak (half-power bandwidth 0.2 Hz here)
    if zeta == 1e-3:
        grid = np.linspace(0.5, 400.0, 4000)
        assert np.abs(frf(grid)).max() < 0.95 * peak.value


def test_two_mode_peak_matches_a_million_point_grid():
    plant = PlantModel(2 * np.pi * np.array([31.3, 33.9]), [0.004, 0.002],
                       [[0.11], [-0.07]], [[0.11, -0.07]], [[0.0, 0.0]], [[1e-9]],
                       ['tcp_force_x'], ['tcp_displacement_x'], ['N'], ['m'], ['f'], ['x'])
    frf = plant_pair_frf(plant, 'tcp_displacement_x', 'tcp_force_x')
    dense = np.linspace(20.0, 45.0, 1_000_001)
    h = np.abs(modal_frf(plant, dense).pair('tcp_displacement_x', 'tcp_force_x'))
    peak = exact_peak(frf, 20.0, 45.0)
    assert peak.value >= h.max() * (1 - 1e-12)
    assert peak.value == pytest.approx(h.max(), rel=1e-7)
    assert peak.freq_hz == pytest.approx(dense[np.argmax(h)], abs=5e-5)


def test_closed_loop_peak_and_pole_residue_form_match_the_state_space():
    plant = demo_model(n_modes=8, f_min=20.0, f_max=300.0, zeta=0.002, feedthrough=1e-8)
    dampers = {'tcp_force_x': 3.0e3, 'strut2_axial_force': 1.0e4}
    frf = plant_pair_frf(plant, 'tcp_displacement_x', 'tcp_force_x', dampers)
    freq = np.linspace(0.5, 400.0, 997)
    ref = closed_loop_frf(plant, dampers, freq).pair('tcp_displacement_x', 'tcp_force_x')
    np.testing.assert_allclose(frf(freq), ref, rtol=1e-9)
    dense = np.linspace(2.0, 400.0, 1_000_001)
    peak = exact_peak(frf, 2.0, 400.0, grid_hz=freq)
    assert peak.value == pytest.approx(np.abs(frf(dense)).max(), rel=1e-6)
    assert peak.value >= np.abs(frf(dense)).max() * (1 - 1e-12)


def test_band_edge_wins_when_the_function_grows_out_of_the_band():
    """A 1/f function peaks at the lower edge, whatever the poles say."""
    poles = np.array([-1.0 + 2j * np.pi * 50.0])
    peak = maximise_near_poles(lambda f: 1.0 / f, poles, 10.0, 400.0)
    assert peak.freq_hz == 10.0 and peak.value == pytest.approx(0.1)
    with pytest.raises(ConfigError, match='0 <= low < high'):
        maximise_near_poles(lambda f: f, poles, 10.0, 10.0)


def test_the_bound_is_above_the_frf_and_skipping_by_it_keeps_the_peak():
    """The triangle bound holds on dense samples; skipping resonances by it changes nothing."""
    plant = demo_model(40, seed=7)
    dampers = {'tcp_force_x': 3.0e3, 'tcp_force_y': 1.0e3}
    frf = plant_pair_frf(plant, 'tcp_displacement_x', 'tcp_force_x', dampers)
    rng = np.random.default_rng(2)
    for lo in rng.uniform(1.0, 390.0, 40):
        hi = lo + rng.uniform(0.01, 10.0)
        dense = np.abs(frf(np.linspace(lo, hi, 2001))).max()
        assert frf.bound(lo, hi) >= dense
    grid = np.linspace(0.5, 400.0, 800)
    calls = {}

    def counted(tag):
        def fun(f):
            calls[tag] = calls.get(tag, 0) + 1
            return np.abs(frf(f))
        return fun
    every = maximise_near_poles(counted('every'), frf.poles, 2.0, 400.0, grid)
    skipped = maximise_near_poles(counted('skipped'), frf.poles, 2.0, 400.0, grid, frf.bound)
    assert skipped == every == exact_peak(frf, 2.0, 400.0, grid)
    assert calls['skipped'] < calls['every'] / 2, calls      # it skips most searches
