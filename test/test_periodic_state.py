"""Periodic steady state of a sampled loop: closed form of one mode, a long run from rest."""
import math

import control
import numpy as np
import pytest

from pentapod_sim.errors import ConfigError
from pentapod_sim.sim.controllers import DiscreteController, loop_system
from pentapod_sim.sim.periodic_state import (
    load_initial_state,
    plant_periodic_state,
    save_initial_state,
    start_with_laws_at_rest,
)
from pentapod_sim.sim.stepping import DiscretePlant

DT = 1e-3


def _modes(freqs, zetas, dt=DT, feedthrough=0.0):
    """Unit-mass modes [q; dq] driven by one force, displacement and velocity out (ZOH)."""
    w, z = 2 * np.pi * np.asarray(freqs), np.asarray(zetas)
    m = len(w)
    a = np.block([[np.zeros((m, m)), np.eye(m)], [-np.diag(w ** 2), -np.diag(2 * z * w)]])
    b = np.r_[np.zeros(m), np.ones(m)][:, None]
    c = np.vstack([np.r_[np.ones(m), np.zeros(m)], np.r_[np.zeros(m), np.ones(m)]])
    d = np.array([[feedthrough], [0.0]])
    sys = control.c2d(control.ss(a, b, c, d, inputs=['f'], outputs=['disp', 'vel']), dt, 'zoh')
    return DiscretePlant(sys)


def test_one_mode_under_a_sine_is_the_closed_form():
    """x_k = Re(X e^{j W k}): amplitude and phase of the 2x2 discrete mode at the line."""
    plant = _modes([20.0], [0.001])
    n, line = 500, 9                        # 0.5 s period, 18 Hz line
    w = 2 * np.pi * line / n
    u = np.cos(w * np.arange(n))[:, None]
    state = plant_periodic_state(plant, [], u)
    # X = (e^{jW} I - A)^-1 B: the phasor of the state under e^{jWk}
    phasor = np.linalg.solve(np.exp(1j * w) * np.eye(2) - plant.a, plant.b[:, 0])
    np.testing.assert_allclose(state.plant_state, phasor.real, rtol=1e-9,
                               atol=1e-12 * np.abs(phasor).max())
    # its displacement over the period is the sine of that amplitude and phase
    plant.reset(state.plant_state, state.u_previous)
    disp = []
    for k in range(n):
        disp.append(plant.outputs()[0])
        plant.advance(u[k])
    h = phasor[0]
    expected = abs(h) * np.cos(w * np.arange(n) + np.angle(h))
    np.testing.assert_allclose(disp, expected, atol=1e-9 * abs(h))
    np.testing.assert_allclose(plant.x, state.plant_state, atol=1e-9 * abs(h))
    assert state.closure < 1e-9
    # the continuous mode's amplitude, which the sampled one approaches (dt << period)
    f = line / (n * DT)
    cont = 1 / abs((2 * np.pi * 20.0) ** 2 - (2 * np.pi * f) ** 2
                   + 2j * 0.001 * (2 * np.pi * 20.0) * (2 * np.pi * f))
    assert abs(h) == pytest.approx(cont, rel=0.02)


def _closed_loop_run(plant, ctrl, u, periods):
    """Step plant and controller from rest (lockstep: u_k answers y_k) for whole periods."""
    plant.reset()
    xc = np.zeros(ctrl.n_states)
    sensors = [plant.output_names.index(p) for p in ctrl.sensor_ports]
    col = plant.input_names.index(ctrl.actuator_ports[0])
    n = len(u)
    for k in range(periods * n):
        y = plant.outputs()[sensors]
        effort = ctrl.c @ xc + ctrl.d @ y
        xc = ctrl.a @ xc + ctrl.b @ y
        total = u[k % n].copy()
        total[col] += effort[0]
        plant.advance(total)
    return plant.x.copy(), plant.u_prev.copy(), xc


def test_a_long_run_from_rest_ends_in_the_periodic_state():
    """Three modes, a law with a state reading a port with feed-through (augmented loop)."""
    plant = _modes([12.0, 31.0, 47.0], [0.02, 0.01, 0.03], feedthrough=1e-4)
    # velocity feedback through a first-order low-pass (one state), plus displacement gain
    pole = math.exp(-2 * math.pi * 200.0 * DT)
    ctrl = DiscreteController(['vel', 'disp'], ['f'], [[pole]], [[1 - pole, 0.0]],
                              [[-8.0]], [[0.0, -50.0]])
    n = 250                                    # 0.25 s: lines at 4 Hz
    rng = np.random.default_rng(3)
    k = np.arange(1, 30)
    u = np.sum(np.cos(2 * np.pi * np.outer(np.arange(n), k) / n
                      + rng.uniform(0, 2 * np.pi, k.size)), axis=1)[:, None]
    state = plant_periodic_state(plant, [ctrl], u)
    # slowest loop mode decays by e^-1 in about 1 s: 60 s of steps leave ~1e-20 of the start
    x, u_prev, xc = _closed_loop_run(plant, ctrl, u, 240)
    scale = np.abs(x).max()
    np.testing.assert_allclose(state.plant_state, x, atol=1e-9 * scale)
    np.testing.assert_allclose(state.u_previous, u_prev, atol=1e-9 * np.abs(u_prev).max())
    np.testing.assert_allclose(state.loop_state[plant.n_states:plant.n_states + 1], xc,
                               atol=1e-9 * np.abs(xc).max())
    assert np.abs(x).max() > 1e-6             # the test drives the loop


def test_an_unstable_loop_has_no_periodic_state():
    plant = _modes([20.0], [0.001])
    push = DiscreteController.static(['vel'], ['f'], [[+5.0]])   # negative damping
    with pytest.raises(ConfigError, match='not asymptotically stable'):
        plant_periodic_state(plant, [push], np.ones((10, 1)))


def test_initial_state_files_round_trip_and_wrong_ones_are_named(tmp_path):
    plant = _modes([20.0], [0.01])
    state = plant_periodic_state(plant, [], np.cos(np.arange(100) * 0.2)[:, None])
    path = save_initial_state(tmp_path / 'x0.npz', state)
    x0, u = load_initial_state(path, 2, 1)
    np.testing.assert_array_equal(x0, state.plant_state)
    np.testing.assert_array_equal(u, state.u_previous)
    with pytest.raises(ConfigError, match=r'needs \(4,\)'):
        load_initial_state(path, 4, 1)
    bad = tmp_path / 'bad.npz'
    bad.write_text('not a zip')
    with pytest.raises(ConfigError, match='not readable'):
        load_initial_state(bad, 2, 1)
    other = tmp_path / 'other.npz'
    np.savez(other, y=np.zeros(2))
    with pytest.raises(ConfigError, match="no array 'x'"):
        load_initial_state(other, 2, 1)


def _run_from(plant, ctrl, u, x0, u_prev, periods):
    """Plant from (x0, u_prev), the law from rest; the TCP displacement of every step."""
    plant.reset(x0, u_prev)
    xc = np.zeros(ctrl.n_states)
    out = []
    for k in range(periods * len(u)):
        y = plant.outputs()
        out.append(y[0])
        y = y[[1, 0]]                         # the law's sensors: vel, disp
        effort = ctrl.c @ xc + ctrl.d @ y
        xc = ctrl.a @ xc + ctrl.b @ y
        plant.advance(u[k % len(u)] + effort)
    return np.array(out)


def test_a_plant_start_for_laws_at_rest_leaves_only_the_laws_fast_transient():
    """
    Lightly damped modes, a slow-ish law filter: the shifted plant start is periodic at once.

    The plain periodic plant state with the law at rest leaves a transient that rings in the
    0.1 %-damped modes; the shifted start leaves only the law's own (fast) decay.
    """
    plant = _modes([12.0, 31.0, 47.0], [0.001, 0.001, 0.001], feedthrough=1e-4)
    pole = math.exp(-2 * math.pi * 100.0 * DT)        # 100 Hz low-pass: 1.6 ms
    ctrl = DiscreteController(['vel', 'disp'], ['f'], [[pole]], [[1 - pole, 0.0]],
                              [[-0.5]], [[0.0, 0.0]])
    n = 250
    k = np.arange(1, 30)
    u = np.sum(np.cos(2 * np.pi * np.outer(np.arange(n), k) / n
                      - np.pi * k * (k - 1) / k.size), axis=1)[:, None]
    state = plant_periodic_state(plant, [ctrl], u)
    loop = loop_system(plant.a, plant.b, plant.c, plant.d, plant.input_names,
                       plant.output_names, [ctrl])
    shifted = start_with_laws_at_rest(loop, plant.n_states, state)
    plain = _run_from(plant, ctrl, u, state.plant_state, state.u_previous, 3)
    better = _run_from(plant, ctrl, u, shifted.plant_state, shifted.u_previous, 3)
    peak = np.abs(plain).max()
    # after the law's own transient (its first period): periods 2 and 3
    plain_diff = np.abs(plain[2 * n:] - plain[n:2 * n]).max() / peak
    better_diff = np.abs(better[2 * n:] - better[n:2 * n]).max() / peak
    assert plain_diff > 1e-4                  # the law's zero start rings in the modes
    assert better_diff < 1e-3 * plain_diff, (plain_diff, better_diff)
    assert not np.array_equal(shifted.plant_state, state.plant_state)
