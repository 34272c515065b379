"""
Semi-discretisation against closed forms, the zero-order solution and a published benchmark.

Published benchmark: Insperger & Stepan's 1-DOF milling model (Insperger & Stepan 2004,
"Updated semi-discretization method for periodic delay-differential equations with discrete
delay", Int. J. Numer. Meth. Engng 61: 117-141; used again by Ding et al. 2010, Int. J. Mach.
Tools Manuf. 50: 502-509): K_t = 6e8, K_n = 2e8 N/m^2, N = 2, down-milling, 922 Hz,
zeta = 0.011, m = 0.03993 kg, charts over 5,000-25,000 rpm and 0-10 mm for a/D = 1 and 0.05.
The papers publish charts, not tables; the minima below were read from the MIT-licensed
reproduction of those charts in V0es/milling-analyzer (imgs/aD_1.png, imgs/aD_005.png: a
400 x 200 grid of the zero-order semi-discretisation with k = 40, contour at |mu| = 1), pixel
by pixel along the lower edge of the contour line (1 pixel = 0.027 mm, 40 rpm). Tolerance:
6 % in depth (the chart's 0.05 mm depth grid, the contour interpolation and the line width;
the zero-order variant it plots converges more slowly than the first-order one here) and
0.5 % in speed.
"""
import math

import numpy as np
import pytest
from scipy.optimize import minimize_scalar

from pentapod_sim.errors import ConfigError
from pentapod_sim.machining import semi_discretisation as sd
from pentapod_sim.machining.lobes import milling_limit
from pentapod_sim.machining.milling_cut import MillingCut
from pentapod_sim.machining.semi_discretisation import (
    critical_depth,
    monodromy,
    spectral_radius,
)
from pentapod_sim.machining.tcp_frf import (
    plant_poles,
    resonance_grid,
    tcp_frf,
    tcp_plant,
    TcpMode,
)

BENCH = tcp_plant([TcpMode(922.0, 0.011, 0.03993 * (2 * math.pi * 922.0) ** 2)])

# (a/D, speed window [rpm], chart minimum [mm], its speed [rpm], kind)
CHART_MINIMA = [
    (1.0, (14500, 18500), 0.337, 15847, 'hopf'),
    (1.0, (19000, 21000), 1.287, 19718, 'flip'),
    (0.05, (11000, 13500), 1.721, 12097, 'hopf'),
    (0.05, (17000, 18800), 1.134, 18185, 'flip'),
    (0.05, (19500, 25000), 1.775, 21935, 'hopf'),
]

# Altintas & Budak (1995) end mill, as modal residues [m/(N s)] in x (feed) and y
ALTINTAS_MODES = [
    TcpMode.from_residue(452.77, 0.123718, 9.202966e-05 - 1.862195e-04j, (1.0, 0.0)),
    TcpMode.from_residue(1448.53, 0.01651, -4.181562e-05 - 3.043618e-04j, (1.0, 0.0)),
    TcpMode.from_residue(516.17, 0.0243, -2.3929e-06 - 1.721539e-04j, (0.0, 1.0)),
    TcpMode.from_residue(1407.64, 0.0324, 4.055052e-05 - 3.618808e-04j, (0.0, 1.0)),
]


@pytest.mark.parametrize('immersion, window, depth_mm, speed, kind', CHART_MINIMA)
def test_insperger_benchmark_lobe_minima(immersion, window, depth_mm, speed, kind):
    cut = MillingCut.from_immersion(2, 6e8, 1 / 3, immersion, 'down')
    found = minimize_scalar(
        lambda n: critical_depth(BENCH, cut, n, 3e-3, steps=15, rel_tol=1e-4).depth,
        bounds=window, method='bounded', options={'xatol': 10.0})
    assert found.fun * 1e3 == pytest.approx(depth_mm, rel=0.06)
    assert found.x == pytest.approx(speed, rel=0.005)
    assert critical_depth(BENCH, cut, found.x, 3e-3, steps=15).kind == kind


def test_zero_depth_multipliers_are_the_free_decay_over_a_tooth_period():
    cut = MillingCut.from_immersion(3, 6e8, 0.3, 0.5, 'up')
    speed = 9000.0
    period = 60.0 / (3 * speed)
    decay = math.exp(-0.011 * 2 * math.pi * 922.0 * period)
    assert spectral_radius(BENCH, cut, speed, 0.0) == pytest.approx(decay, rel=1e-10)
    mu = np.linalg.eigvals(monodromy(BENCH, cut, speed, 0.0))
    top = mu[np.argsort(-np.abs(mu))[:2]]
    wd = 2 * math.pi * 922.0 * math.sqrt(1 - 0.011 ** 2)
    np.testing.assert_allclose(np.sort(np.angle(top)),
                               np.sort(np.array([-1, 1]) * np.angle(np.exp(1j * wd * period))),
                               atol=1e-9)


def test_the_averaged_problem_is_the_zero_order_solution(monkeypatch):
    """SD with every interval's force matrix replaced by its mean = the zero-order lobes."""
    plant = tcp_plant(ALTINTAS_MODES)
    cut = MillingCut.from_immersion(4, 796e6, 0.212, 0.5, 'up')
    frf = tcp_frf(plant, resonance_grid(plant_poles(plant), 1.0, 5000.0))
    speeds = np.array([5000.0, 9000.0, 13000.0, 16000.0])
    zero_order = milling_limit(frf, cut).envelope(speeds).depth
    timed = [critical_depth(plant, cut, n, 3e-3, steps=30).depth for n in speeds]
    original = sd._interval_forces
    monkeypatch.setattr(sd, '_interval_forces', lambda c, k: np.broadcast_to(
        original(c, k).mean(axis=0), (k, 2, 2)))
    averaged = [critical_depth(plant, cut, n, 3e-3, steps=30).depth for n in speeds]
    np.testing.assert_allclose(averaged, zero_order, rtol=0.01)
    # the time variation the zero-order solution drops moves this example's limit by up to
    # 38 % (13,000 rpm: 1.96 mm against 1.42 mm; a time-domain run agrees with 1.96)
    assert max(abs(np.array(timed) / zero_order - 1)) > 0.2


def test_zero_order_agrees_where_it_is_valid_and_not_at_low_immersion():
    """High immersion, many teeth: within 5 %; a/D = 0.05, 2 teeth: a flip lobe it misses."""
    plant = tcp_plant([TcpMode(600.0, 0.02, 6e6, (1.0, 0.0)),
                       TcpMode(660.0, 0.03, 8e6, (0.0, 1.0))])
    frf = tcp_frf(plant, resonance_grid(plant_poles(plant), 50.0, 3000.0))
    cut = MillingCut.from_immersion(6, 8e8, 0.3, 1.0, 'down')
    speeds = np.array([4000.0, 6000.0, 9000.0])
    zero_order = milling_limit(frf, cut).envelope(speeds).depth
    timed = [critical_depth(plant, cut, n, 2 * z, steps=20).depth
             for n, z in zip(speeds, zero_order)]
    np.testing.assert_allclose(timed, zero_order, rtol=0.05)
    low = MillingCut.from_immersion(2, 6e8, 1 / 3, 0.05, 'down')
    bench_frf = tcp_frf(BENCH, resonance_grid(plant_poles(BENCH), 100.0, 3000.0))
    predicted = milling_limit(bench_frf, low).envelope([18186.0]).depth[0]
    flip = critical_depth(BENCH, low, 18186.0, predicted, steps=20)
    assert flip.kind == 'flip' and flip.depth < 0.3 * predicted


def test_more_intervals_change_the_limit_little():
    cut = MillingCut.from_immersion(2, 6e8, 1 / 3, 0.05, 'down')
    depths = [critical_depth(BENCH, cut, 21921.0, 3e-3, intervals=k, steps=15).depth
              for k in (20, 40, 80)]
    assert abs(depths[1] / depths[2] - 1) < 0.005
    assert abs(depths[0] - depths[2]) > abs(depths[1] - depths[2])


def test_bad_inputs_are_named():
    cut = MillingCut.from_immersion(2, 6e8, 1 / 3, 0.5, 'down')
    with pytest.raises(ConfigError, match='speed > 0 rpm'):
        monodromy(BENCH, cut, -100.0, 1e-3)
    with pytest.raises(ConfigError, match='depth_max > 0'):
        critical_depth(BENCH, cut, 1000.0, 0.0)
    assert critical_depth(BENCH, cut, 10000.0, 1e-6, steps=3).depth == math.inf
