"""
The growth rate that sizes the cutting runs: Floquet multipliers of the sampled loop with the cut.

The case: one TCP mode (50 Hz, 4 %, 10 kHz), half-immersion down-milling at 1829 rpm (tooth
passing 122 Hz, 2.45 times the mode), where the chatter (45 Hz) and its image by the tooth
passing (77 Hz) both lie on the mode. The averaged (zero-order) loop ignores the coupling of
the two and predicts the growth at 1.2x of its limit three times too fast; the Floquet rate of
the time-varying loop is what a simulated cut (the nonlinear cutting process, stepped as the
lockstep testbed steps it) measures. Independent of the code under test: the simulated cut
and the closed-form tooth-period mean of the force (Altintas' directional factors).
"""
import math

import numpy as np
import pytest

from pentapod_sim.errors import ConfigError
from pentapod_sim.machining.chatter import detect_chatter
from pentapod_sim.machining.cutting_model import averaged_stiffness
from pentapod_sim.machining.cutting_process import MIN_STEPS_PER_TOOTH, simulate_cut
from pentapod_sim.machining.loop_lobes import (
    check_runs,
    loop_lobes,
    RUN_MIN_TOOTH_PERIODS,
    RUN_SETTLE_SHARE,
)
from pentapod_sim.machining.materials import load_machining
from pentapod_sim.machining.sampled_floquet import (
    check_speed,
    sampled_floquet,
    step_stiffness,
    whole_step_speed,
)
from pentapod_sim.machining.tcp_frf import tcp_plant, TcpMode

PLANT = tcp_plant([TcpMode(50.0, 0.04, 2e6, (1.0, 0.3))])
DT = 1e-4
OPERATION = 'aluminium_half_down'


def test_the_step_forces_average_to_the_zero_order_matrix():
    """Mean of K_k over a tooth period = a N K_t / (4 pi) R [alpha] R^T (rectangle rule)."""
    table = load_machining()
    steps = 5000
    cond = table.conditions(OPERATION, 60.0 / (4 * steps * DT), 1e-3)
    mean = step_stiffness(cond, DT, steps).mean(axis=0)
    ref = averaged_stiffness(cond)
    np.testing.assert_allclose(mean, ref, rtol=0, atol=1e-3 * np.abs(ref).max())


def test_speeds_are_moved_to_whole_steps_per_tooth_period():
    for speed in (1829.0, 1e5):
        steps = 60.0 / (4 * whole_step_speed(speed, 4, DT) * DT)
        assert steps == pytest.approx(round(steps), abs=1e-9)
        assert round(steps) >= MIN_STEPS_PER_TOOTH
    cond = load_machining().conditions(OPERATION, 1829.0, 1e-3)
    with pytest.raises(ConfigError, match='whole number'):
        sampled_floquet(PLANT, [], cond, DT)


@pytest.fixture(scope='module')
def point():
    table = load_machining()
    lobes = loop_lobes(PLANT, [], DT, table, [OPERATION], np.linspace(1000, 3000, 400),
                       'one mode').operations[OPERATION]
    return check_runs(PLANT, [], DT, table, lobes, speed=1829.0)


def test_the_runs_last_three_e_foldings_of_growth_and_two_of_decay(point):
    """At least 40 tooth periods after the settling quarter (the fit of the verdict)."""
    below, above = point.runs
    assert point.speed == check_speed(1829.0, 4, DT)
    assert below.growth_rate < 0 < above.growth_rate
    for run in point.runs:
        cond = run.conditions(load_machining())
        assert run.growth_rate == sampled_floquet(PLANT, [], cond, DT).growth_rate
        active = max((3.0 if run.growth_rate > 0 else 2.0) / abs(run.growth_rate),
                     RUN_MIN_TOOTH_PERIODS * cond.tooth_period)
        assert run.duration == pytest.approx(active / (1 - RUN_SETTLE_SHARE))
    assert above.duration * (1 - RUN_SETTLE_SHARE) * above.growth_rate == pytest.approx(3.0)
    assert below.duration * (1 - RUN_SETTLE_SHARE) * below.growth_rate == pytest.approx(-2.0)
    # the case: the averaged loop predicts a growth three times too fast above the limit
    assert above.averaged_rate > 2.5 * above.growth_rate
    assert above.kind == 'hopf'
    angle = abs(math.atan2(above.multiplier.imag, above.multiplier.real))
    assert 0.6 * math.pi < angle < 0.9 * math.pi        # chatter between f_tooth/4 and /2


def test_a_simulated_cut_grows_at_the_floquet_rate_not_the_averaged_one(point):
    """Measured over the linear part of the cut (before the vibration saturates)."""
    table = load_machining()
    for run in point.runs:
        cond = run.conditions(table)
        span = 2.0 / abs(run.averaged_rate) / (1 - RUN_SETTLE_SHARE)   # the old rule's run
        cut = simulate_cut(PLANT, cond, DT, span)
        verdict = detect_chatter(cut.time, cut.displacement, cond.spindle_speed, 4,
                                 RUN_SETTLE_SHARE * span)
        measured = verdict.growth_rate
        assert abs(measured - run.growth_rate) < 0.5 * abs(measured - run.averaged_rate), (
            run.factor, measured, run.growth_rate, run.averaged_rate)
        assert measured == pytest.approx(run.growth_rate, rel=0.15)


@pytest.mark.parametrize('off_grid', [False, True])
def test_a_check_speed_keeps_the_engagement_periodic(off_grid):
    """
    At a whole number of steps per tooth period the entry angle falls on samples.

    On the grid, the rounding of the tooth angle decides irregularly whether a tooth cuts
    there; at :func:`check_speed` every revolution after the first (whose step 0 has the teeth
    exactly at their pitch angles) engages the teeth at the same samples.
    """
    table = load_machining()
    speed = (check_speed if off_grid else whole_step_speed)(1829.0, 4, DT)
    revolution = 4 * round(60.0 / (4 * speed * DT))
    cut = simulate_cut(PLANT, table.conditions(OPERATION, speed, 1e-3), DT, 1000 * revolution * DT)
    patterns = {cut.engaged[i:i + revolution].tobytes()
                for i in range(revolution, cut.engaged.shape[0] - revolution + 1, revolution)}
    assert (len(patterns) == 1) == off_grid, len(patterns)
