"""
Stability lobes from a TCP FRF: closed forms, the characteristic equation, the lobe envelope.

Independent references: Tlusty's single-mode closed form ``b_lim,min = 2 k zeta (1 + zeta) /
K_f`` (the minimum of Re G is exactly ``-1 / (4 k zeta (1 + zeta))``); the characteristic
equation ``det(I + Lambda [alpha] G) = 0`` with ``Lambda = -N a K_t (1 - e^{-j w T}) / (4 pi)``
evaluated at the lobes' points; directional factors by numerical quadrature; the envelope by a
root search per lobe on the continuous FRF (scipy.optimize.brentq).
"""
import math

import numpy as np
import pytest
from scipy.integrate import quad
from scipy.optimize import brentq

from pentapod_sim.errors import ConfigError
from pentapod_sim.machining.lobes import milling_limit, turning_limit
from pentapod_sim.machining.milling_cut import (
    chip_direction,
    directional_factors,
    engaged_integral,
    force_direction,
    immersion_angles,
    MillingCut,
)
from pentapod_sim.machining.tcp_frf import (
    plant_poles,
    resonance_grid,
    tcp_frf,
    tcp_plant,
    TcpFrf,
    TcpMode,
)

# Insperger & Stepan's 1-DOF benchmark (m = 0.03993 kg, 922 Hz, zeta = 0.011)
BENCH_K = 0.03993 * (2 * math.pi * 922.0) ** 2
BENCH_ZETA = 0.011


def single_mode(freq=922.0, zeta=BENCH_ZETA, k=BENCH_K, direction=(1.0, 0.0)):
    plant = tcp_plant([TcpMode(freq, zeta, k, direction)])
    grid = resonance_grid(plant_poles(plant), 50.0, 4000.0)
    return plant, tcp_frf(plant, grid)


TWO_MODES = [TcpMode(600.0, 0.02, 6e6, (1.0, 0.0)), TcpMode(660.0, 0.03, 8e6, (0.6, 0.8))]


def two_modes():
    """Unequal x and y modes, one of them oblique: cross terms are non-zero."""
    plant = tcp_plant(TWO_MODES)
    return plant, tcp_frf(plant, resonance_grid(plant_poles(plant), 50.0, 3000.0))


@pytest.mark.parametrize('zeta', [0.001, 0.011, 0.05])
def test_turning_minimum_is_tlustys_closed_form(zeta):
    _, frf = single_mode(zeta=zeta)
    k_f = 1e9
    low = turning_limit(frf.along([1.0, 0.0]), frf.freq, k_f).minimum()
    assert low.resolved
    assert low.depth == pytest.approx(2 * BENCH_K * zeta * (1 + zeta) / k_f, rel=1e-6)
    # the grid's points are 1/20 of the half-power half-width apart there
    assert low.freq_hz == pytest.approx(922.0 * math.sqrt(1 + 2 * zeta), rel=zeta / 20)


def test_a_coarse_grid_is_flagged_as_unresolved():
    plant = tcp_plant([TcpMode(922.0, 0.001, BENCH_K)])
    frf = tcp_frf(plant, np.linspace(800.0, 1000.0, 101))        # 2 Hz lines, 1.8 Hz band
    low = turning_limit(frf.along([1.0, 0.0]), frf.freq, 1e9).minimum()
    assert not low.resolved
    assert low.depth > 1.02 * 2 * BENCH_K * 0.001 * 1.001 / 1e9


def _residual(frf_matrix, alpha, gain, depth, period, freq):
    """|det(I + Lambda [alpha] G)| at one lobe point, Lambda of depth and tooth period."""
    lam = -gain * depth * (1 - np.exp(-2j * math.pi * freq * period))
    return abs(np.linalg.det(np.eye(2) + lam * alpha @ frf_matrix))


@pytest.mark.parametrize('immersion, milling, feed_angle, skew', [
    (1.0, 'down', 0.0, 0.0), (0.5, 'up', 0.3, 0.0), (0.1, 'down', 1.2, 0.0),
    (0.5, 'down', 0.5, 0.4)])
def test_lobe_points_solve_the_characteristic_equation(immersion, milling, feed_angle, skew):
    """Also for a non-reciprocal FRF (G_xy != G_yx, as a measured one may be)."""
    _, frf = two_modes()
    cross = skew * (frf.matrix[0, 1] + frf.matrix[0, 0])
    frf = TcpFrf(frf.freq, frf.matrix + np.array([[0, 1], [-1, 0]])[:, :, None] * cross)
    cut = MillingCut.from_immersion(4, 8e8, 0.3, immersion, milling, feed_angle)
    lim = milling_limit(frf, cut)
    g = frf.in_cutting_frame(feed_angle)
    alpha = directional_factors(cut)
    gain = cut.teeth * cut.tangential_coefficient / (4 * math.pi)
    checked = 0
    for lobe in (0, 1, 3):
        speeds = lim.lobe_speeds(lobe)
        for b, i in zip(*np.nonzero(np.isfinite(lim.depth))):
            if i % 37:
                continue
            period = 60.0 / (cut.teeth * speeds[b, i])
            res = _residual(g[:, :, i], alpha, gain, lim.depth[b, i], period, frf.freq[i])
            assert res < 1e-9, (lobe, b, i, res)
            checked += 1
    assert checked > 50


def test_turning_is_one_direction_milling_with_the_mean_force():
    """Slot, 1-DOF along the feed: the mean force coefficient is N K_n / 4 (Insperger)."""
    _, frf = single_mode()
    k_t, k_n = 6e8, 2e8
    cut = MillingCut.from_immersion(2, k_t, k_n / k_t, 1.0, 'down')
    milling = milling_limit(frf, cut)
    turning = turning_limit(frf.along([1.0, 0.0]), frf.freq, 2 * k_n / 4)
    np.testing.assert_allclose(milling.depth[np.isfinite(milling.depth)],
                               turning.depth[np.isfinite(turning.depth)], rtol=1e-12)
    # the benchmark's zero-order minimum, 8 k zeta (1 + zeta) / (N K_n) = 0.298 mm
    assert milling.minimum().depth == pytest.approx(
        8 * BENCH_K * BENCH_ZETA * (1 + BENCH_ZETA) / (2 * k_n), rel=1e-6)


def test_directional_factors_closed_forms():
    kr = 0.212                                   # Altintas' Al7050, half-immersion up-milling
    up = directional_factors(MillingCut.from_immersion(4, 796e6, kr, 0.5, 'up'))
    np.testing.assert_allclose(up, [[-(1 + kr * math.pi / 2), -(math.pi / 2 + kr)],
                                    [math.pi / 2 - kr, 1 - kr * math.pi / 2]], rtol=1e-12)
    slot = directional_factors(MillingCut(2, 6e8, 1 / 3, 0.0, math.pi))
    np.testing.assert_allclose(slot, [[-math.pi / 3, -math.pi], [math.pi, -math.pi / 3]],
                               atol=1e-12)


@pytest.mark.parametrize('entry, exit_, start, length', [
    (0.3, 1.9, 0.0, 2 * math.pi), (0.0, math.pi, 5.5, 1.5), (2.0, 3.0, -7.0, 0.4),
    (1.0, 2.0, 2.1, 0.5)])
def test_engaged_integral_by_quadrature(entry, exit_, start, length):
    cut = MillingCut(3, 1e9, 0.4, entry, exit_)
    got = engaged_integral(cut, start, start + length)

    def entry_of(phi, i, j):
        engaged = entry <= phi % (2 * math.pi) <= exit_
        return engaged * force_direction(phi, 0.4)[i] * chip_direction(phi)[j]
    edges = np.concatenate([np.arange(-4, 5) * 2 * math.pi + a for a in (entry, exit_)])
    breaks = sorted(p for p in edges if start < p < start + length) or None
    ref = [[quad(entry_of, start, start + length, args=(i, j), limit=200, points=breaks)[0]
            for j in range(2)] for i in range(2)]
    np.testing.assert_allclose(got, ref, atol=1e-8)
    if length >= 2 * math.pi - 1e-12:
        np.testing.assert_allclose(2 * got, directional_factors(cut), atol=1e-12)


def test_rotating_structure_and_feed_together_changes_nothing():
    plant, frf = two_modes()
    theta = 0.7
    rot = np.array([[math.cos(theta), -math.sin(theta)], [math.sin(theta), math.cos(theta)]])
    turned = TcpFrf(frf.freq, np.einsum('ik,klf,jl->ijf', rot, frf.matrix, rot))
    cut = MillingCut.from_immersion(3, 7e8, 0.25, 0.4, 'up')
    base = milling_limit(frf, cut)
    moved = milling_limit(turned, MillingCut.from_immersion(3, 7e8, 0.25, 0.4, 'up', theta))
    np.testing.assert_allclose(np.sort(np.nan_to_num(moved.depth), axis=0),
                               np.sort(np.nan_to_num(base.depth), axis=0), rtol=1e-9)


def _frf_closed_form(modes, f):
    """(2, 2, n) FRF of real modes at frequencies f [Hz], written out."""
    w = 2 * math.pi * np.atleast_1d(np.asarray(f, dtype=float))
    total = np.zeros((2, 2, w.size), dtype=complex)
    for m in modes:
        d = np.asarray(m.direction) / np.linalg.norm(m.direction)
        wn = 2 * math.pi * m.frequency
        total += np.outer(d, d)[:, :, None] * wn ** 2 / m.stiffness / (
            wn ** 2 - w ** 2 + 2j * m.damping_ratio * wn * w)
    return total


def _envelope_by_root_search(modes, cut, speed, lobes=10):
    """Lowest crossing depth at one speed: brentq on the continuous FRF, lobe by lobe."""
    period = 60.0 / (cut.teeth * speed)
    alpha = directional_factors(cut)
    gain = cut.teeth * cut.tangential_coefficient / (4 * math.pi)
    rot = cut.rotation()

    def branch(f, b):
        """Root b of a0 L^2 + a1 L + 1 (ordered by real part) at frequencies f."""
        m = np.einsum('ij,kj,klf,lm->imf', alpha, rot, _frf_closed_form(modes, f), rot)
        a0 = m[0, 0] * m[1, 1] - m[0, 1] * m[1, 0]
        a1 = m[0, 0] + m[1, 1]
        disc = np.sqrt(a1 ** 2 - 4 * a0)
        roots = np.stack([(-a1 + disc) / (2 * a0), (-a1 - disc) / (2 * a0)])
        return np.sort_complex(roots.T).T[b]

    def gap(f, b, k):
        eps = (math.pi - 2 * np.angle(branch(f, b))) % (2 * math.pi)
        return 2 * math.pi * f * period - eps - 2 * math.pi * k
    grid = resonance_grid(plant_poles(tcp_plant(modes)), 50.0, 3000.0, n_base=6000)[::3]
    best = math.inf
    for b in range(2):
        ok = branch(grid, b).real < 0
        for k in range(lobes):
            vals = gap(grid, b, k)
            change = ok[:-1] & ok[1:] & (np.sign(vals[:-1]) != np.sign(vals[1:])) & (
                np.abs(vals[:-1] - vals[1:]) < math.pi)
            for i in np.flatnonzero(change):
                f = brentq(lambda x: gap(x, b, k)[0], grid[i], grid[i + 1], xtol=1e-10)
                lam = branch(f, b)[0]
                best = min(best, -abs(lam) ** 2 / (2 * gain * lam.real))
    return best


def test_envelope_equals_a_root_search_per_speed():
    _, frf = two_modes()
    cut = MillingCut.from_immersion(2, 8e8, 0.3, 0.5, 'down', 0.4)
    speeds = np.array([3000.0, 7300.0, 12100.0, 19000.0])
    env = milling_limit(frf, cut).envelope(speeds)
    ref = [_envelope_by_root_search(TWO_MODES, cut, s) for s in speeds]
    np.testing.assert_allclose(env.depth, ref, rtol=2e-3)


def test_envelope_finds_the_pocket_and_the_lowest_point():
    _, frf = single_mode()
    cut = MillingCut.from_immersion(2, 6e8, 1 / 3, 1.0, 'down')
    env = milling_limit(frf, cut).envelope(np.linspace(5000.0, 25000.0, 4001))
    speed, depth = env.lowest()            # every lobe of one mode dips to the same depth
    assert depth == pytest.approx(2.98e-4, rel=2e-3)
    f_low = 922.0 * math.sqrt(1 + 2 * BENCH_ZETA)
    eps = (3 * math.pi + 2 * np.angle(_frf_closed_form([TcpMode(922.0, BENCH_ZETA, BENCH_K)],
                                                         f_low)[0, 0])) % (2 * math.pi)
    lobe_minima = 60 * f_low / (2 * (np.arange(8) + eps / (2 * math.pi)))
    assert np.min(np.abs(lobe_minima - speed)) < 5.0       # the speed grid's 5 rpm
    pocket_speed, pocket_depth = env.best_pocket()
    assert 13000 < pocket_speed < 14500 and pocket_depth > 10 * depth
    assert np.all(env.lobe[env.speed > 14200] == 1)     # tooth passing 1.1-1.7x below chatter


def test_bad_inputs_are_named():
    with pytest.raises(ConfigError, match='radial immersion'):
        immersion_angles(1.5, 'up')
    with pytest.raises(ConfigError, match="milling = 'side'"):
        immersion_angles(0.5, 'side')
    with pytest.raises(ConfigError, match='teeth = 0'):
        MillingCut(0, 1e9, 0.3, 0.0, 1.0)
    with pytest.raises(ConfigError, match='entry < exit'):
        MillingCut(2, 1e9, 0.3, 2.0, 1.0)
    _, frf = single_mode()
    with pytest.raises(ConfigError, match='increasing and > 0 rpm'):
        turning_limit(frf.along([1, 0]), frf.freq, 1e9).envelope([2000.0, 1000.0])
    with pytest.raises(ConfigError, match='K_f'):
        turning_limit(frf.along([1, 0]), frf.freq, -1.0)
