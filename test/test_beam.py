"""Tests of the Timoshenko beam element against closed-form results (pentapod_sim.fe.beam)."""
import numpy as np
import pytest
import scipy.linalg as sla

from pentapod_sim.errors import ConfigError
from pentapod_sim.fe import beam

E, G, RHO = 2.1e11, 8.08e10, 7850.0
LENGTH = 4.0
TUBE = beam.tube_section(0.05, 0.003)            # slender: L / radius of gyration ~ 240


def _line(n_el, direction=(1.0, 0.0, 0.0), orient=(0.0, 1.0, 0.0), sec=TUBE, kappa=5 / 6,
          length=LENGTH):
    """Dense K, M of a straight beam of n_el equal elements along direction."""
    d = np.asarray(direction, float) / np.linalg.norm(direction)
    x = np.outer(np.linspace(0.0, length, n_el + 1), d)
    lens, axes = beam.local_axes(x[:-1], x[1:], orient)
    k, m = beam.local_matrices(lens, E, G, RHO, sec.area, sec.iy, sec.iz, sec.torsion, kappa)
    k, m = beam.to_global(k, axes), beam.to_global(m, axes)
    n = 6 * (n_el + 1)
    big_k, big_m = np.zeros((n, n)), np.zeros((n, n))
    for e in range(n_el):
        s = slice(6 * e, 6 * e + 12)
        big_k[s, s] += k[e]
        big_m[s, s] += m[e]
    return big_k, big_m


def _freqs(k, m, count):
    w2 = sla.eigh(k, m, eigvals_only=True, subset_by_index=[0, count - 1])
    return np.sqrt(np.abs(w2)) / (2 * np.pi)


def _bending(beta_l, sec=TUBE):
    return beta_l ** 2 / (2 * np.pi * LENGTH ** 2) * np.sqrt(E * sec.iy / (RHO * sec.area))


def test_rhs_section_against_hand_values():
    s = beam.rhs_section(0.10, 0.13, 0.006)
    assert s.area == pytest.approx(0.10 * 0.13 - 0.088 * 0.118)
    assert s.iy == pytest.approx((0.10 * 0.13 ** 3 - 0.088 * 0.118 ** 3) / 12)
    assert s.iz == pytest.approx((0.13 * 0.10 ** 3 - 0.118 * 0.088 ** 3) / 12)
    # Bredt: J = 4 A_m^2 t / perimeter of the mid-line
    assert s.torsion == pytest.approx(4 * (0.094 * 0.124) ** 2 * 0.006 / (2 * (0.094 + 0.124)))
    with pytest.raises(ConfigError, match='invalid RHS'):
        beam.rhs_section(0.1, 0.1, 0.06)


def test_element_symmetric_and_six_rigid_modes():
    lens, axes = beam.local_axes([[0.1, 0.2, 0.3]], [[0.9, -0.4, 1.1]], [0.0, 0.0, 1.0])
    k, m = beam.local_matrices(lens, E, G, RHO, TUBE.area, TUBE.iy, TUBE.iz, TUBE.torsion, 5 / 6)
    kg, mg = beam.to_global(k, axes)[0], beam.to_global(m, axes)[0]
    assert kg == pytest.approx(kg.T, rel=1e-12, abs=1e-6)
    assert mg == pytest.approx(mg.T, rel=1e-12, abs=1e-15)
    ev = np.linalg.eigvalsh(kg)
    assert np.sum(np.abs(ev) < 1e-8 * ev.max()) == 6
    assert np.linalg.eigvalsh(mg).min() > 0.0
    # rigid rotation about an arbitrary point produces no elastic forces
    x = np.array([[0.1, 0.2, 0.3], [0.9, -0.4, 1.1]])
    theta = np.array([0.3, -0.7, 0.2])
    u = np.concatenate([np.concatenate([np.cross(theta, p - [1, 1, 1]), theta]) for p in x])
    assert np.abs(kg @ u).max() < 1e-9 * np.abs(kg).max() * np.abs(u).max()
    # translational mass = rho A L in every direction
    t = np.tile([1.0, 0, 0, 0, 0, 0], 2)
    assert t @ mg @ t == pytest.approx(RHO * TUBE.area * lens[0], rel=1e-12)


def test_cantilever_bending_frequencies():
    k, m = _line(40)
    f = _freqs(k[6:, 6:], m[6:, 6:], 4)
    expected = _bending(1.875104)
    # circular tube: two equal first modes (y and z), then the second pair
    assert f[:2] == pytest.approx([expected] * 2, rel=5e-3)
    assert f[2:4] == pytest.approx([_bending(4.694091)] * 2, rel=5e-3)


def test_free_free_bending_frequencies():
    k, m = _line(40, direction=(1.0, 2.0, -0.5), orient=(0.0, 0.0, 1.0))
    f = _freqs(k, m, 10)
    assert f[:6] == pytest.approx(np.zeros(6), abs=1e-3 * f[6])
    assert f[6:8] == pytest.approx([_bending(4.730041)] * 2, rel=5e-3)
    assert f[8:10] == pytest.approx([_bending(7.853205)] * 2, rel=5e-3)


def test_axial_and_torsion_frequencies():
    k, m = _line(60)
    axial = [0, 3]                                 # ux and rx of every node
    dofs = np.concatenate([np.arange(6 * j + axial[0], 6 * j + axial[0] + 1)
                           for j in range(1, 61)])
    f_ax = _freqs(k[np.ix_(dofs, dofs)], m[np.ix_(dofs, dofs)], 2)
    c = np.sqrt(E / RHO)
    assert f_ax == pytest.approx([c / (4 * LENGTH), 3 * c / (4 * LENGTH)], rel=5e-3)
    dofs = dofs + 3
    f_t = _freqs(k[np.ix_(dofs, dofs)], m[np.ix_(dofs, dofs)], 2)
    ct = np.sqrt(G * TUBE.torsion / (RHO * (TUBE.iy + TUBE.iz)))
    assert f_t == pytest.approx([ct / (4 * LENGTH), 3 * ct / (4 * LENGTH)], rel=5e-3)


def test_timoshenko_shear_deflection_of_stocky_cantilever():
    """One element reproduces P L^3 / (3 E I) + P L / (kappa G A) exactly."""
    sec = beam.rhs_section(0.2, 0.3, 0.02)
    length, force, kappa = 0.5, 1.0e4, 5 / 6
    k, _ = _line(1, sec=sec, kappa=kappa, length=length)
    kf = k[6:, 6:]
    for dof, inertia in ((1, sec.iz), (2, sec.iy)):
        f = np.zeros(6)
        f[dof] = force
        tip = np.linalg.solve(kf, f)[dof]
        expected = (force * length ** 3 / (3 * E * inertia)
                    + force * length / (kappa * G * sec.area))
        assert tip == pytest.approx(expected, rel=1e-10)


def _timoshenko_simply_supported(k_wave, sec, inertia, kappa):
    """Lowest root omega^2 of the Timoshenko beam's 2x2 characteristic determinant."""
    ka = kappa * G * sec.area
    # det [[ka k^2 - rho A w2, -ka k], [-ka k, E I k^2 + ka - rho I w2]] = 0, a quadratic in w2
    a2 = RHO * sec.area * RHO * inertia
    a1 = -(RHO * sec.area * (E * inertia * k_wave ** 2 + ka) + RHO * inertia * ka * k_wave ** 2)
    a0 = ka * k_wave ** 2 * (E * inertia * k_wave ** 2 + ka) - (ka * k_wave) ** 2
    return np.sqrt(np.min(np.roots([a2, a1, a0]).real)) / (2 * np.pi)


@pytest.mark.parametrize('mode', [1, 2])
def test_stocky_simply_supported_beam_matches_timoshenko_theory(mode):
    """Shear and rotary inertia matter here (L / h = 4): checks the phi-dependent terms."""
    sec, kappa, length = beam.rhs_section(0.3, 0.4, 0.03), 5 / 6, 1.6
    k, m = _line(80, sec=sec, kappa=kappa, length=length)
    n = k.shape[0]
    fixed = [0, 1, 2, 3, n - 5, n - 4]             # pins: ux, uy, uz, rx at 0; uy, uz at L
    keep = np.setdiff1d(np.arange(n), fixed)
    f = _freqs(k[np.ix_(keep, keep)], m[np.ix_(keep, keep)], 12)
    k_wave = mode * np.pi / length
    for inertia in (sec.iy, sec.iz):
        expected = _timoshenko_simply_supported(k_wave, sec, inertia, kappa)
        euler = k_wave ** 2 * np.sqrt(E * inertia / (RHO * sec.area)) / (2 * np.pi)
        assert expected < 0.95 * euler                  # the case is really non-slender
        assert np.min(np.abs(f / expected - 1.0)) < 5e-3


def test_orientation_parallel_to_axis_is_rejected():
    with pytest.raises(ConfigError, match='parallel to the element axis'):
        beam.local_axes([[0, 0, 0]], [[0, 0, 1]], [0, 0, 2])
