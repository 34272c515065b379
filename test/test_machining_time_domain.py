"""
Regenerative milling in the time domain and chatter seen in its record.

The cutting process is checked against the static force law written out, the one-period delay
against the exact delayed displacement, and leaving the cut against the chip two feeds thick
that the next pass then meets. The issue's "done when" on a small modal model: runs at 0.8x
and 1.2x of the zero-order limiting depth at a chosen speed come out stable and chattering,
without and with a TCP damper (pentapod_damper.laws.tcp_damper, the damper node's law).
"""
import math

import numpy as np
import pytest

from pentapod_damper.laws import tcp_damper
from pentapod_sim.errors import ConfigError, RunError
from pentapod_sim.machining.chatter import detect_chatter, poincare_section
from pentapod_sim.machining.cutting_process import (
    CuttingConditions,
    CuttingProcess,
    simulate_cut,
)
from pentapod_sim.machining.lobes import milling_limit
from pentapod_sim.machining.milling_cut import MillingCut
from pentapod_sim.machining.semi_discretisation import critical_depth
from pentapod_sim.machining.tcp_frf import (
    plant_poles,
    resonance_grid,
    tcp_frf,
    tcp_plant,
    TcpMode,
)

PLANT = tcp_plant([TcpMode(600.0, 0.02, 6e6, (1.0, 0.0)), TcpMode(660.0, 0.03, 8e6, (0.0, 1.0))])
CUT = MillingCut.from_immersion(4, 8e8, 0.3, 0.5, 'down')
SPEED = 7000.0                                       # rpm, a lobe where SD and zero order agree
PERIOD = 60.0 / (4 * SPEED)


def _rigid_forces(cond, n_steps, dt):
    process = CuttingProcess(cond, dt)
    return np.array([process.answer(k, [0.0, 0.0]) for k in range(n_steps)])


def test_rigid_tool_force_is_the_static_force_law():
    cut = MillingCut.from_immersion(3, 7e8, 0.25, 0.6, 'up', feed_angle=0.4)
    cond = CuttingConditions(cut, 6000.0, 2e-3, 1e-4, edge_tangential=2e4, edge_radial=3e4)
    dt = 60.0 / (3 * 6000.0) / 64.3
    forces = _rigid_forces(cond, 500, dt)
    rot = cut.rotation()
    for k in (0, 37, 123, 401):
        total = np.zeros(2)
        for j in range(3):
            phi = (2 * math.pi * 6000.0 / 60.0 * k * dt + 2 * math.pi * j / 3) % (2 * math.pi)
            if cut.entry_angle <= phi <= cut.exit_angle and math.sin(phi) > 0:
                h = 1e-4 * math.sin(phi)
                ft, fr = 2e-3 * (7e8 * h + 2e4), 2e-3 * (0.25 * 7e8 * h + 3e4)
                total += [-ft * math.cos(phi) - fr * math.sin(phi),
                          ft * math.sin(phi) - fr * math.cos(phi)]
        np.testing.assert_allclose(forces[k], rot @ total, rtol=1e-12, atol=1e-9)


def test_the_delay_is_one_tooth_period_interpolated():
    """Chip = feed sin + (r(t) - r(t - T)) . n for a smooth r, T not a whole number of steps."""
    cut = MillingCut(2, 1e9, 0.3, 0.0, math.pi)
    cond = CuttingConditions(cut, 9000.0, 1e-4, 2e-4)          # vibration << feed: always in cut
    dt = cond.tooth_period / 87.37
    process = CuttingProcess(cond, dt, record_steps=600)

    def r(t):
        return 1e-6 * np.array([np.sin(2 * math.pi * 310 * t), np.cos(2 * math.pi * 170 * t)])
    for k in range(600):
        process.answer(k, r(k * dt))
    for k in range(200, 600, 37):
        t = k * dt
        for j in range(2):
            phi = (2 * math.pi * 9000.0 / 60.0 * t + math.pi * j) % (2 * math.pi)
            if not 0.05 < phi < math.pi - 0.05:
                continue
            n = np.array([math.sin(phi), math.cos(phi)])
            exact = 2e-4 * math.sin(phi) + (r(t) - r(t - cond.tooth_period)) @ n
            assert process.recorded_chip[k, j] == pytest.approx(exact, abs=2e-9), (k, j)


def test_leaving_the_cut_leaves_the_surface_for_the_next_tooth():
    """One tooth; pulled back by 3 feeds for a revolution: no chip, then two feeds' chip."""
    cut = MillingCut(1, 1e9, 0.3, 0.0, math.pi)
    cond = CuttingConditions(cut, 6000.0, 1e-3, 1e-4)
    steps = 100
    process = CuttingProcess(cond, cond.tooth_period / steps, record_steps=3 * steps)
    for k in range(3 * steps):
        back = -3e-4 if steps <= k < 2 * steps else 0.0
        process.answer(k, [back, 0.0])
    inside = [k for k in range(steps) if 10 < k < 40]
    sin = np.sin(2 * math.pi * np.array(inside) / steps)
    np.testing.assert_allclose(process.recorded_chip[inside], (1e-4 * sin)[:, None], rtol=1e-9)
    assert not process.recorded_in_cut[[k + steps for k in inside]].any()
    np.testing.assert_allclose(process.recorded_force[[k + steps for k in inside]], 0.0)
    np.testing.assert_allclose(process.recorded_chip[[k + 2 * steps for k in inside]],
                               (2e-4 * sin)[:, None], rtol=1e-9)


def test_steps_in_order_and_enough_steps_per_tooth():
    cond = CuttingConditions(CUT, SPEED, 1e-3, 1e-4)
    process = CuttingProcess(cond, PERIOD / 60)
    process.answer(0, [0.0, 0.0])
    with pytest.raises(RunError, match='step 2 answered, expected step 1'):
        process.answer(2, [0.0, 0.0])
    with pytest.raises(ConfigError, match=r'spans only 10.0 plant steps .* at least 23333 Hz'):
        CuttingProcess(cond, PERIOD / 10)


def _limit(dampers=None):
    frf = tcp_frf(PLANT, resonance_grid(plant_poles(PLANT), 50.0, 3000.0), dampers)
    env = milling_limit(frf, CUT).envelope([SPEED])
    return env.depth[0], env.chatter_freq[0]


@pytest.mark.parametrize('gain', [0.0, 150.0])
def test_runs_below_and_above_the_predicted_limit_are_stable_and_chatter(gain):
    dampers = {'tcp_force_x': gain, 'tcp_force_y': gain} if gain else None
    laws = [tcp_damper(['x', 'y'], gain)] if gain else []
    depth, chatter_freq = _limit(dampers)
    if not gain:
        timed = critical_depth(PLANT, CUT, SPEED, 2 * depth, steps=20).depth
        assert timed == pytest.approx(depth, rel=0.06)      # the zero order holds here
    verdicts = []
    for factor in (0.8, 1.2):
        run = simulate_cut(PLANT, CuttingConditions(CUT, SPEED, factor * depth, 1e-4),
                           PERIOD / 100, 250 * PERIOD, laws)
        verdicts.append(detect_chatter(run.time, run.displacement, SPEED, 4,
                                       settle=50 * PERIOD, engaged=run.engaged,
                                       in_cut=run.in_cut))
    stable, chatter = verdicts
    assert stable.verdict == 'stable' and stable.growth_rate < 0
    assert chatter.is_chatter and chatter.off_harmonic_share > 0.1
    aliases = chatter_freq + chatter.tooth_freq * np.arange(-3, 4)
    assert np.min(np.abs(aliases - chatter.chatter_freq)) < 0.03 * chatter_freq


def test_synthetic_records():
    tooth, fs = 400.0, 20000.0
    t = np.arange(int(0.5 * fs)) / fs
    forced = sum(a * np.sin(2 * math.pi * k * tooth * t + k) for k, a in ((1, 3e-6), (2, 1e-6),
                                                                        (3, 4e-7)))
    base = {'spindle_speed': tooth * 60 / 4, 'teeth': 4, 'settle': 0.05}
    assert detect_chatter(t, forced, **base).verdict == 'stable'
    decaying = forced + 2e-6 * np.exp(-30 * t) * np.sin(2 * math.pi * 555.0 * t)
    quiet = detect_chatter(t, decaying, **base)
    assert quiet.verdict == 'stable' and quiet.growth_rate == pytest.approx(-30, rel=0.05)
    growing = forced + 1e-8 * np.exp(25 * t) * np.sin(2 * math.pi * 555.0 * t)
    loud = detect_chatter(t, growing, **base)
    assert loud.verdict == 'chatter' and loud.chatter_freq == pytest.approx(555.0, abs=3)
    assert loud.growth_rate == pytest.approx(25, rel=0.05)
    onset = forced + 1e-9 * np.exp(6 * t) * np.sin(2 * math.pi * 555.0 * t)  # still tiny
    early = detect_chatter(t, onset, **base)
    assert early.off_harmonic_share < 1e-4 and early.verdict == 'chatter'
    doubling = forced + 2e-6 * np.sin(2 * math.pi * 1.5 * tooth * t)      # saturated flip
    flip = detect_chatter(t, doubling, **base)
    assert flip.verdict == 'chatter' and flip.chatter_freq == pytest.approx(600.0, abs=3)
    times, section = poincare_section(t, doubling, 1 / tooth, start=0.1 + 0.3 / tooth)
    assert np.ptp(section[0::2]) < 1e-8 < np.ptp(section)          # two alternating points


def test_tool_left_the_cut_is_read_from_the_engagement():
    tooth, fs = 400.0, 20000.0
    t = np.arange(4000) / fs
    engaged = np.ones((t.size, 4), dtype=bool)
    in_cut = engaged.copy()
    in_cut[::7] = False
    v = detect_chatter(t, np.sin(2 * math.pi * tooth * t), tooth * 15, 4, engaged=engaged,
                       in_cut=in_cut)
    assert v.verdict == 'tool left the cut' and v.left_cut_share == pytest.approx(1 / 7, 0.02)
    with pytest.raises(ConfigError, match='both'):
        detect_chatter(t, np.sin(t), tooth * 15, 4, engaged=engaged)
