"""PMA stroke and force requirements against single-DOF closed forms (no ROS)."""
import numpy as np
import pytest

from pentapod_damper.study.pma import (
    bounded_stroke,
    highpass_response,
    pma_design,
    requirement_row,
)
from pentapod_sim.plant.model import PlantModel

AMP = 10.0


def one_mass(mass: float, f_n: float, zeta: float) -> PlantModel:
    """Mass on a spring; TCP force and PMA act on it, TCP displacement and mount velocity."""
    b = 1.0 / np.sqrt(mass)
    return PlantModel([2 * np.pi * f_n], [zeta], [[b, b]], [[b], [0.0]], [[0.0], [b]],
                      [[0.0, 0.0], [0.0, 0.0]], ['tcp_force_x', 'pma_force_x'],
                      ['tcp_displacement_x', 'pma_mount_velocity_x'], ['N', 'N'],
                      ['m', 'm/s'], ['f', 'p'], ['x', 'v'])


def closed_form(mass, f_n, zeta, m_a, g, f_hp, freq):
    """Harmonic balance: M x'' + c x' + k x = F - m_a g H v; proof mass a_m = g H v."""
    w = 2 * np.pi * freq
    k, c = mass * (2 * np.pi * f_n) ** 2, 2 * zeta * mass * 2 * np.pi * f_n
    h = highpass_response(freq, f_hp)
    v = 1j * w * AMP / (k - w ** 2 * mass + 1j * w * (c + m_a * g * h))
    x_mount = v / (1j * w)
    x_mass = g * h * v / (1j * w) ** 2
    return np.abs(x_mass - x_mount), m_a * g * np.abs(h * v), np.abs(x_mount)


@pytest.mark.parametrize('f_hp', [0.0, 5.0])
def test_stroke_and_force_equal_the_single_dof_harmonic_balance(f_hp):
    mass, f_n, zeta, m_a, g = 40.0, 25.0, 0.002, 5.0, 4000.0
    design = pma_design(one_mass(mass, f_n, zeta), 'x', m_a, g, f_hp)
    freq = np.array([0.3, 2.0, 10.5, 24.0, 25.0, 80.0, 390.0])
    stroke, force = design.stroke_force(freq, AMP)
    ref_stroke, ref_force, ref_x = closed_form(mass, f_n, zeta, m_a, g, f_hp, freq)
    np.testing.assert_allclose(stroke, ref_stroke, rtol=1e-9)
    np.testing.assert_allclose(force, ref_force, rtol=1e-9)
    np.testing.assert_allclose(np.abs(design.tcp(freq)) * AMP, ref_x, rtol=1e-9)


def test_stroke_tends_to_force_over_proof_mass_w2_where_the_damper_dominates():
    """With b = m_a g >> |k / w - w M| and g >> w the proof mass takes the whole force."""
    mass, f_n, m_a, g = 2.0, 20.0, 0.5, 1.0e5
    design = pma_design(one_mass(mass, f_n, 0.01), 'x', m_a, g)
    freq = np.array([150.0, 200.0, 300.0])
    stroke, force = design.stroke_force(freq, AMP)
    np.testing.assert_allclose(stroke, AMP / (m_a * (2 * np.pi * freq) ** 2), rtol=5e-3)
    np.testing.assert_allclose(force, AMP, rtol=2e-2)


def test_highpass_bounds_the_stroke_by_the_static_deflection():
    """Far below the corner the proof mass stands still: stroke -> F / k; ideal: ~ F g / (k w)."""
    mass, f_n, m_a, g = 40.0, 25.0, 5.0, 4000.0
    k = mass * (2 * np.pi * f_n) ** 2
    ideal = pma_design(one_mass(mass, f_n, 0.002), 'x', m_a, g)
    filtered = pma_design(one_mass(mass, f_n, 0.002), 'x', m_a, g, 5.0)
    f = np.array([1e-3])
    assert filtered.stroke_force(f, AMP)[0][0] == pytest.approx(AMP / k, rel=0.03)
    assert ideal.stroke_force(f, AMP)[0][0] == pytest.approx(
        AMP / k * g / (2 * np.pi * 1e-3), rel=1e-3)
    worst = bounded_stroke(filtered, AMP, 400.0)
    dense = np.geomspace(1e-3, 400.0, 400_001)
    assert worst.value == pytest.approx(filtered.stroke_force(dense, AMP)[0].max(), rel=1e-6)
    with pytest.raises(ValueError, match='without bound'):
        bounded_stroke(ideal, AMP, 400.0)


def test_requirement_row_reports_band_worst_cases_and_stated_frequencies():
    mass, f_n, m_a, g = 40.0, 25.0, 5.0, 4000.0
    design = pma_design(one_mass(mass, f_n, 0.002), 'x', m_a, g)
    grid = np.linspace(0.5, 400.0, 4000)
    row = requirement_row(design, AMP, (2.0, 400.0), (10.0, 400.0), (10.5,), grid)
    # the ideal law's stroke grows towards low frequency: the worst case is the band edge
    assert row['at_hz'] == 2.0
    dense = np.linspace(10.0, 400.0, 1_000_001)
    stroke, force = design.stroke_force(dense, AMP)
    assert row['band_max_stroke_mm'] == pytest.approx(stroke.max() * 1e3, rel=1e-6)
    assert row['band_max_force_N'] == pytest.approx(force.max(), rel=1e-6)
    ref_stroke, ref_force, _ = closed_form(mass, f_n, 0.002, m_a, g, 0.0, np.array([10.5]))
    assert row['stroke_mm_at_10.5_hz'] == pytest.approx(ref_stroke[0] * 1e3, rel=1e-9)
    assert row['force_N_at_10.5_hz'] == pytest.approx(ref_force[0], rel=1e-9)
    assert row['free_mass_stroke_mm_at_10.5_hz'] == pytest.approx(
        AMP / (m_a * (2 * np.pi * 10.5) ** 2) * 1e3, rel=1e-12)
