"""
The new damping laws against independent references: closed forms and python-control loops.

IFF on one mode against the cubic of its root locus and Preumont's optimum; the lag law's
static stiffness loss; PPF's static stability limit g G(0) < 1; every law's discrete model
against python-control's discretisation of its transfer function; sampled loops against
``control.feedback`` of the zero-order-hold plant; the stepped laws and the PMA's linear model
against their own ``step``.
"""
import control
import numpy as np
import pytest

from fixtures.demo_model import demo_model
from pentapod_damper.laws import (
    band_pass_velocity,
    integral_force_feedback,
    lag_displacement_feedback,
    positive_position_feedback,
    ProofMassActuator,
)
from pentapod_damper.node_parameters import damper_laws
from pentapod_sim.errors import ConfigError
from pentapod_sim.plant.model import PlantModel
from pentapod_sim.sim import law_models as lm
from pentapod_sim.sim.closed_loop import closed_loop_system, excitation_matrix, simulate
from pentapod_sim.sim.loop_frf import SampledLoop
from pentapod_sim.sim.loop_poles import continuous_loop_system
from pentapod_sim.sim.stepping import DiscretePlant

M, K_S, K_A = 50.0, 2.0e6, 6.0e6        # kg, N/m: structure spring, active strut's spring


def one_mode(zeta: float = 0.0) -> PlantModel:
    """A mass on a spring k_s with an active strut (spring k_a, force u, load cell F)."""
    w = np.sqrt((K_S + K_A) / M)
    phi = 1 / np.sqrt(M)
    names_out = ['strut1_drive_displacement', 'strut1_force', 'tcp_displacement_x',
                 'strut1_drive_velocity']
    c_disp = np.array([[phi], [-K_A * phi], [phi], [0.0]])
    c_vel = np.array([[0.0], [0.0], [0.0], [phi]])
    d = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 0.0], [0.0, 0.0]])
    return PlantModel([w], [zeta], [[phi, phi]], c_disp, c_vel, d,
                      ['strut1_drive_force', 'tcp_force_x'], names_out, ['N', 'N'],
                      ['m', 'N', 'm', 'm/s'], ['', ''], [''] * 4)


def _poles(plant, law):
    a, _, _ = continuous_loop_system(plant, [law.continuous()])
    return np.linalg.eigvals(a)


def test_iff_poles_are_the_roots_of_the_closed_form_cubic():
    g = 300.0
    law = lm.iff(['strut1_force'], ['strut1_drive_force'], g)
    w_p2, w_z2 = (K_S + K_A) / M, K_S / M
    expected = np.roots([1.0, g, w_p2, g * w_z2])
    np.testing.assert_allclose(np.sort_complex(_poles(one_mode(), law)),
                               np.sort_complex(expected), rtol=1e-9)


def test_iff_best_damping_is_preumonts_optimum():
    w_p, w_z = np.sqrt((K_S + K_A) / M), np.sqrt(K_S / M)
    gains = np.geomspace(0.3, 3, 400) * w_p * np.sqrt(w_p / w_z)
    zeta = []
    for g in gains:
        s = _poles(one_mode(), lm.iff(['strut1_force'], ['strut1_drive_force'], g))
        s = s[np.abs(s.imag) > 1e-9]
        zeta.append(np.min(-s.real / np.abs(s)))
    best = int(np.argmax(zeta))
    assert zeta[best] == pytest.approx((w_p - w_z) / (2 * w_z), rel=1e-4)
    assert gains[best] == pytest.approx(w_p * np.sqrt(w_p / w_z), rel=0.01)


def test_lag_law_takes_its_stiffness_off_the_port_statically():
    plant = one_mode()
    k_lag = 0.3 * (K_S + K_A)
    law = lm.lag_displacement(['strut1_drive_displacement'], ['strut1_drive_force'], k_lag,
                              20.0)
    loop = SampledLoop(plant, [law.discrete(1e-4)], 1e-4)
    assert loop.static('tcp_displacement_x', 'tcp_force_x') == pytest.approx(
        1 / (K_S + K_A - k_lag), rel=1e-9)
    # above the corner the law is a Maxwell element: it only removes energy
    assert np.all(_poles(plant, law).real < 0)


@pytest.mark.parametrize('ratio, stable', [(0.98, True), (1.02, False)])
def test_ppf_is_stable_below_unit_static_loop_gain(ratio, stable):
    g = ratio * (K_S + K_A)                      # 1 / G(0) of the collocated displacement
    law = lm.ppf(['strut1_drive_displacement'], ['strut1_drive_force'], g, 30.0, 0.3)
    assert bool(np.all(_poles(one_mode(), law).real < 0)) is stable


@pytest.mark.parametrize('law', [
    lm.iff(['y'], ['u'], 250.0, 12.0, lm.Dynamics(2, 400.0, 0.7, 1)),
    lm.band_pass(['y'], ['u'], 80.0, 5.0, 150.0, lm.Dynamics(delay_steps=2)),
    lm.lag_displacement(['y'], ['u'], 3e5, 40.0, lm.Dynamics(1, 800.0, hold='zoh')),
    lm.ppf(['y'], ['u'], 2e5, 27.0, 0.2, lm.Dynamics(delay_steps=1)),
], ids=['iff', 'band-pass', 'lag', 'ppf'])
def test_discrete_law_equals_python_control_discretisation(law):
    dt, dyn = 1 / 5000, law.dynamics
    num, den = law.tf
    cont = control.tf(list(num), list(den)) * law.gains[0]
    if dyn.order:
        w = 2 * np.pi * dyn.bandwidth_hz
        cont = cont * (control.tf([w], [1, w]) if dyn.order == 1
                       else control.tf([w * w], [1, 2 * dyn.damping * w, w * w]))
    reference = control.sample_system(cont, dt, method=dyn.hold)
    model = law.discrete(dt)
    mine = control.ss(model.a, model.b, model.c, model.d, dt)
    freq = np.array([1.0, 27.0, 130.0, 900.0])
    z = np.exp(2j * np.pi * freq * dt)
    expected = reference(z) * z ** -dyn.delay_steps
    np.testing.assert_allclose(mine(z), expected, rtol=1e-9)


def test_delay_output_is_z_to_the_minus_n():
    law = lm.band_pass(['a', 'b'], ['u', 'v'], [3.0, 4.0], 2.0, 90.0).discrete(1e-3)
    late = lm.delay_output(law, 3)
    z = np.exp(2j * np.pi * 7.0 * 1e-3)

    def frf(c):
        return c.c @ np.linalg.solve(z * np.eye(c.a.shape[0]) - c.a, c.b) + c.d
    np.testing.assert_allclose(frf(late), frf(law) * z ** -3, rtol=1e-12)


@pytest.mark.parametrize('make', [
    lambda dt: integral_force_feedback([1], 400.0, 30.0, dt, lm.Dynamics(delay_steps=1)),
    lambda dt: lag_displacement_feedback('bending', [2], 1e5, 25.0, dt),
    lambda dt: band_pass_velocity('chord', [1], 900.0, 4.0, 120.0, dt),
    lambda dt: positive_position_feedback('bending', [1], 3e4, 27.0, 0.3, dt),
], ids=['iff', 'lag', 'band-pass', 'ppf'])
def test_sampled_loop_equals_the_loop_equation(make):
    """Closed loop of a random collocated plant: SampledLoop against the loop equation."""
    dt = 1 / 5000
    law = make(dt)
    plant = _with_force_ports(demo_model(8, inputs=['tcp_force_x'] + law.actuator_ports,
                                         seed=4), law)
    loop = SampledLoop(plant, [law.discrete_model()], dt)
    sys_d = plant.discretize(dt)
    model = law.discrete_model()
    ctrl = control.ss(model.a, model.b, model.c, model.d, dt)
    sensors = [plant.output_names.index(n) for n in law.sensor_ports]
    actuators = [plant.input_names.index(n) for n in law.actuator_ports]
    # the lockstep rule y_k = C x_k + D u_k-1: the plant seen at z is C (zI - A)^-1 B + D / z,
    # the law is python-control's evaluation of its state space; y = (I - G K)^-1 G u_ext
    i, o = plant.input_names.index('tcp_force_x'), plant.output_names.index(
        'tcp_displacement_x')
    freq = np.array([20.0, 41.0, 77.0, 180.0])
    z = np.exp(2j * np.pi * freq * dt)
    expected = []
    for zf in z:
        g = (sys_d.C @ np.linalg.solve(zf * np.eye(sys_d.A.shape[0]) - sys_d.A, sys_d.B)
             + sys_d.D / zf)
        k = ctrl(zf) if ctrl.ninputs > 1 or ctrl.noutputs > 1 else np.atleast_2d(ctrl(zf))
        kk = np.zeros((g.shape[1], g.shape[0]), dtype=complex)
        kk[np.ix_(actuators, sensors)] = k
        closed = np.linalg.solve(np.eye(g.shape[0]) - g @ kk, g)
        expected.append(closed[o, i])
    np.testing.assert_allclose(loop.output('tcp_displacement_x', 'tcp_force_x')(freq),
                               expected, rtol=1e-6)


def _with_force_ports(plant: PlantModel, law) -> PlantModel:
    """The demo plant plus the load cells a law reads (``-k`` times its drive displacement)."""
    missing = [s for s in law.sensor_ports if s not in plant.output_names]
    if not missing:
        return plant
    rows = [plant.c_disp[plant.output_names.index(s.replace('_force', '_drive_displacement'))]
            * -3e6 for s in missing]
    d_rows = [[1.0 if a == s.replace('_force', '_drive_force') else 0.0
               for a in plant.input_names] for s in missing]
    return PlantModel(plant.omega, plant.zeta, plant.b, np.vstack([plant.c_disp, rows]),
                      np.vstack([plant.c_vel, np.zeros((len(missing), plant.n_modes))]),
                      np.vstack([plant.d, d_rows]), plant.input_names,
                      plant.output_names + missing, plant.input_units,
                      plant.output_units + ['N'] * len(missing), plant.input_descriptions,
                      plant.output_descriptions + missing)


def test_stepped_law_steps_its_discrete_model():
    dt = 1 / 3000
    law = integral_force_feedback([1, 2], 500.0, 20.0, dt, lm.Dynamics(2, 300.0, 0.7, 1))
    law.set_gain(0.5)
    model = law.discrete_model()
    y = np.random.default_rng(0).standard_normal((50, 2))
    ctrl = control.ss(model.a, model.b, model.c, model.d, dt)
    expected = control.forced_response(ctrl, U=y.T).outputs.T
    np.testing.assert_allclose([law.step(v) for v in y], expected, rtol=1e-10, atol=1e-14)


def test_pma_linear_model_is_what_it_steps():
    dt = 1 / 5000
    law = ProofMassActuator(['x', 'z'], 5.0, 4000.0, dt, highpass_hz=5.0)
    model = law.discrete_model()
    v = np.random.default_rng(1).standard_normal((80, 2)) * 1e-4
    ctrl = control.ss(model.a, model.b, model.c, model.d, dt)
    expected = control.forced_response(ctrl, U=v.T).outputs.T
    np.testing.assert_allclose([law.step(x) for x in v], expected, rtol=1e-10, atol=1e-12)
    assert ProofMassActuator(['x'], 5.0, 4000.0, dt, stroke_limit=1e-3).discrete_model() is None


def test_damper_node_options_build_the_laws_and_run_them_offline_as_the_loop_says():
    """A damper node's lag and band-pass options: the lockstep run equals the sampled loop."""
    dt = 1 / 5000
    laws = damper_laws({'lag_struts': [1], 'lag_stiffness': [2e4, 3e4], 'lag_corner_hz': 40.0,
                        'lag_gain': 0.5, 'bandpass_struts': [2], 'bandpass_gain': 20.0,
                        'delay_steps': 1, 'sample_rate': 5000.0}, 'node damper')
    assert list(laws) == ['lag_gain', 'bandpass_gain']
    inputs = ['tcp_force_x'] + [p for law in laws.values() for p in law.actuator_ports]
    plant = DiscretePlant(demo_model(8, inputs=inputs, seed=7).discretize(dt))
    force = np.zeros((400, 1))
    force[0] = 100.0
    run = simulate(plant, list(laws.values()), excitation_matrix(plant, ['tcp_force_x'], force,
                                                                 400))
    loop = closed_loop_system(plant, list(laws.values()))
    z, expected = np.zeros(loop.a.shape[0]), []
    e = excitation_matrix(plant, ['tcp_force_x'], force, 400)
    for k in range(400):
        expected.append(loop.c_y @ z)
        z = loop.a @ z + loop.b @ e[k]
    np.testing.assert_allclose(run.y, expected, rtol=1e-9, atol=1e-18)


def test_damper_node_option_mistakes_are_named():
    with pytest.raises(ConfigError, match='node d: lag_stiffness has 3 values'):
        damper_laws({'lag_struts': [1, 2], 'lag_stiffness': [1.0, 2.0, 3.0]}, 'node d')
    with pytest.raises(ConfigError, match='band-pass: high-pass corner 200.0 Hz must be below'):
        damper_laws({'bandpass_struts': [1], 'bandpass_highpass_hz': 200.0}, 'node d')
    laws = damper_laws({'iff_struts': [3], 'iff_gain': 0.0}, 'node d')
    laws['iff_gain'].gains = np.full(1, 250.0)        # what the node does on `ros2 param set`
    assert laws['iff_gain'].discrete_model().d == pytest.approx(
        250.0 * integral_force_feedback([3], 1.0, 10.0, 1 / 5000.0).discrete_model().d)
