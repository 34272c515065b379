"""Actuator/sensor dynamics of the damper laws: low-pass, delay, and the loop that models them."""
import numpy as np
import pytest
import scipy.signal

from fixtures.demo_model import demo_model
from pentapod_damper.laws import Dynamics, strut_axial_damper, tcp_damper, ViscousDamper
from pentapod_damper.node_parameters import damper_laws
from pentapod_damper.scenario_laws import continuous_dampers
from pentapod_damper.study.analytic import discrete_frf
from pentapod_sim.errors import ConfigError
from pentapod_sim.sim.closed_loop import closed_loop_system, simulate
from pentapod_sim.sim.stepping import DiscretePlant

DT = 1.0 / 2000.0


@pytest.fixture(scope='module')
def plant():
    return demo_model(n_modes=6, f_min=30.0, f_max=400.0, zeta=0.01, feedthrough=2e-8,
                      inputs=['tcp_force_x', 'tcp_force_y', 'strut1_axial_force'])


@pytest.mark.parametrize('hold', ['foh', 'zoh'])
def test_first_order_lowpass_pole_is_exp_minus_w_dt(hold):
    fc = 150.0
    a, b, c, d = Dynamics(1, fc, hold=hold).siso(DT)
    pole = np.exp(-2 * np.pi * fc * DT)
    assert a.shape == (1, 1) and a[0, 0] == pytest.approx(pole, rel=1e-14)
    assert (c @ np.linalg.solve(np.eye(1) - a, b) + d)[0, 0] == pytest.approx(1.0)   # dc gain
    if hold == 'zoh':       # held input: x_{k+1} = p x_k + (1 - p) y_k, output x_k
        assert b[0, 0] * c[0, 0] == pytest.approx(1.0 - pole) and d[0, 0] == 0.0
    else:                   # input linear between samples: the step y_k enters at once
        ramp = 1.0 - (1.0 - pole) / (2 * np.pi * fc * DT)      # response to a unit ramp
        assert d[0, 0] == pytest.approx(ramp, rel=1e-12)


def test_second_order_lowpass_poles_are_exp_s_dt():
    fc, zeta = 200.0, 0.3
    w = 2 * np.pi * fc
    a, *_ = Dynamics(2, fc, zeta, hold='zoh').siso(DT)
    np.testing.assert_allclose(Dynamics(2, fc, zeta).siso(DT)[0], a)      # same poles with foh
    s = np.roots([1.0, 2 * zeta * w, w * w])
    np.testing.assert_allclose(np.sort_complex(np.linalg.eigvals(a)),
                               np.sort_complex(np.exp(s * DT)), rtol=1e-12)


def test_delay_shifts_the_signal_by_n_samples():
    law = ViscousDamper(['tcp_force_x'], 3.0, Dynamics(delay_steps=3), DT)
    y = np.random.default_rng(1).standard_normal(20)
    u = np.array([law.step(np.array([v]))[0] for v in y])
    np.testing.assert_array_equal(u[:3], 0.0)
    np.testing.assert_allclose(u[3:], -3.0 * y[:-3], rtol=0, atol=0)


def _dlsim(plant, laws, excitation):
    """Response of the analytic closed-loop state space (scipy dlsim) to the excitation."""
    core = DiscretePlant(plant.discretize(DT))
    a, b, c_y, c_u, augmented = closed_loop_system(core, laws)
    n_in = b.shape[1]
    c = np.vstack([c_y, c_u])
    d = np.vstack([np.zeros((c_y.shape[0], n_in)), np.eye(n_in)])
    _, out, _ = scipy.signal.dlsim((a, b, c, d, DT), excitation)
    y, u = out[:, :c_y.shape[0]], out[:, c_y.shape[0]:]
    if not augmented and core.has_feedthrough:
        y = y + np.vstack([np.zeros((1, n_in)), u[:-1]]) @ core.d.T
    return y, u


@pytest.mark.parametrize('dyn', [Dynamics(1, 120.0), Dynamics(2, 250.0, 0.4, 1),
                                 Dynamics(1, 300.0, hold='zoh'),
                                 Dynamics(0, 0.0, delay_steps=2)], ids=str)
def test_stepped_loop_equals_the_analytic_state_space(plant, dyn):
    laws = [tcp_damper(['x', 'y'], 2500.0, dyn, DT), strut_axial_damper([1], 4.0e4)]
    core = DiscretePlant(plant.discretize(DT))
    rng = np.random.default_rng(3)
    excitation = np.zeros((3000, len(core.input_names)))
    excitation[:, core.input_names.index('tcp_force_x')] = rng.standard_normal(3000)
    stepped = simulate(core, laws, excitation)
    y, u = _dlsim(plant, laws, excitation)
    for ref, got in ((y, stepped.y), (u, stepped.u)):
        scale = np.abs(ref).max()
        np.testing.assert_allclose(got, ref, rtol=0, atol=1e-10 * scale)


def test_one_sample_delay_against_a_hand_built_loop(plant):
    """u_k = e_k - b v_{k-1}: stepped by hand on the bare plant, and its loop eigenvalues."""
    gain = 3000.0
    law = tcp_damper(['x'], gain, Dynamics(delay_steps=1), DT)
    core = DiscretePlant(plant.discretize(DT))
    j = core.input_names.index('tcp_force_x')
    v = core.output_names.index('tcp_velocity_x')
    n = 2000
    force = np.random.default_rng(5).standard_normal(n)
    excitation = np.zeros((n, len(core.input_names)))
    excitation[:, j] = force
    with_law = simulate(core, [law], excitation)
    core.reset()
    by_hand = np.zeros(n)
    v_prev = 0.0
    for k in range(n):
        y = core.outputs()
        u = np.zeros(len(core.input_names))
        u[j] = force[k] - gain * v_prev
        by_hand[k] = y[v]
        v_prev = y[v]
        core.advance(u)
    np.testing.assert_allclose(with_law.output('tcp_velocity_x'), by_hand, rtol=0,
                               atol=1e-12 * np.abs(by_hand).max())
    # state [x_k; v_{k-1}]: x_{k+1} = A x_k - b B_j v_{k-1}, v_k = C_v x_k
    a, b, c = core.a, core.b[:, j:j + 1], core.c[v:v + 1]
    hand = np.block([[a, -gain * b], [c, np.zeros((1, 1))]])
    loop = closed_loop_system(core, [law]).a
    np.testing.assert_allclose(np.sort_complex(np.linalg.eigvals(loop)),
                               np.sort_complex(np.linalg.eigvals(hand)), atol=1e-10)


def test_discrete_frf_with_dynamics_is_the_dtft_of_the_stepped_impulse_response(plant):
    laws = [tcp_damper(['x'], 3000.0, Dynamics(2, 150.0, 0.6, 1), DT)]
    core = DiscretePlant(plant.discretize(DT))
    n = 40000
    excitation = np.zeros((n, len(core.input_names)))
    excitation[0, core.input_names.index('tcp_force_x')] = 1.0
    response = simulate(core, laws, excitation)
    freq = np.array([12.0, 33.0, 81.5, 140.0])
    powers = np.exp(2j * np.pi * freq * DT)[None, :] ** -np.arange(n)[:, None]
    ana = discrete_frf(plant, laws, DT, freq, 'tcp_force_x')
    dtft = response.output('tcp_displacement_x') @ powers
    np.testing.assert_allclose(ana.outputs['tcp_displacement_x'], dtft, rtol=1e-6)


def test_laws_with_dynamics_keep_their_nominal_viscous_gain():
    laws = [tcp_damper(['x'], 2000.0, Dynamics(1, 100.0), DT)]
    assert laws[0].linear_gain() is None
    assert continuous_dampers(laws) == {'tcp_force_x': 2000.0}


def test_bad_dynamics_are_refused_naming_the_value():
    with pytest.raises(ConfigError, match='Nyquist'):
        Dynamics(1, 1500.0).siso(DT)
    with pytest.raises(ConfigError, match='order'):
        Dynamics(3, 10.0)
    with pytest.raises(ConfigError, match='delay_steps'):
        Dynamics(delay_steps=-1)
    with pytest.raises(ConfigError, match='sample time'):
        ViscousDamper(['tcp_force_x'], 1.0, Dynamics(1, 10.0))


def test_damper_node_parameters_build_the_dynamics():
    laws = damper_laws({'tcp_directions': ['x'], 'filter_order': 2, 'bandwidth_hz': 300.0,
                        'filter_damping': 0.5, 'delay_steps': 1, 'sample_rate': 2000.0,
                        'chord_struts': [1, 2], 'chord_gain': 5000.0})
    assert list(laws) == ['chord_gain', 'tcp_gain']
    tcp = laws['tcp_gain']
    assert tcp.dynamics == Dynamics(2, 300.0, 0.5, 1) and tcp.dt == pytest.approx(DT)
    assert laws['chord_gain'].actuator_ports == [
        'strut1_chord_force_2', 'strut1_chord_force_3', 'strut2_chord_force_2',
        'strut2_chord_force_3']
    assert tcp.discrete_model().n_states == 3
