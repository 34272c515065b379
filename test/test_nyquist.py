"""
The loop check from frequency responses (no ROS).

The generalised Nyquist criterion against the eigenvalues of the sampled loop, and a
controller identified from an offline run against its own model.

The small FE model of statespace_fixtures has a plant of its modes below 200 Hz and a check
model of all 156 modes below 2 kHz; sampled at 1 kHz, strut bending dampers of growing gain
go from stable to stable only thanks to truncation to unstable (test_stability.py).
"""
import dataclasses

import numpy as np
import pytest
import scipy.signal
from statespace_fixtures import small_model

from pentapod_damper.laws import ProofMassActuator, strut_bending_damper, tcp_damper
from pentapod_sim.analysis.frf.mimo import mimo_frf
from pentapod_sim.plant.build import load_reduction_config, plant_from_fe
from pentapod_sim.plant.check_model import check_model_from_fe
from pentapod_sim.sim.closed_loop import simulate
from pentapod_sim.sim.controllers import loop_matrix, with_delay
from pentapod_sim.sim.disturbance import PortNoise
from pentapod_sim.sim.nyquist import controller_frf, nyquist_check, SampledPlantFrf
from pentapod_sim.sim.stability import check_loop, controller_of, STABLE, TRUNCATION, UNSTABLE
from pentapod_sim.sim.stepping import DiscretePlant

DT = 1e-3


@pytest.fixture(scope='module')
def models():
    fe = small_model()
    cfg = load_reduction_config()
    plant, _ = plant_from_fe(fe, dataclasses.replace(cfg, modes_f_max=200.0))
    check = check_model_from_fe(fe, cfg, 2000.0).select(plant.input_names, plant.output_names)
    return plant, check


def _outside(plant, ctrl):
    """Eigenvalues of the sampled loop outside the unit circle (the independent count)."""
    a, b, c, d = plant.discrete_matrices(DT)
    lam = np.linalg.eigvals(loop_matrix(a, b, c, d, plant.input_names, plant.output_names,
                                        [ctrl]))
    return int(np.sum(np.abs(lam) > 1.0))


LAWS = {
    'bending 10': lambda: strut_bending_damper([1], 10.0),
    'bending 1e4': lambda: strut_bending_damper([1], 1.0e4),
    'bending 3e3 struts 1, 2': lambda: strut_bending_damper([1, 2], 3.0e3),
    'tcp 3e3': lambda: tcp_damper(['x', 'y'], 3.0e3),
    'tcp 1e5': lambda: tcp_damper(['x', 'y'], 1.0e5),
    'tcp 1e7': lambda: tcp_damper(['x'], 1.0e7),
    'pma': lambda: ProofMassActuator(['x'], 5.0, 4000.0, DT),
}


@pytest.mark.parametrize('delay', [0, 1, 2])
@pytest.mark.parametrize('law', list(LAWS))
def test_nyquist_counts_the_unstable_eigenvalues_of_the_loop(models, law, delay):
    """Closed-loop poles outside the unit circle: -winding number = eigenvalue count."""
    ctrl = controller_of(LAWS[law]())
    for plant in models:
        result = nyquist_check(plant, ctrl.sensor_ports, ctrl.actuator_ports,
                               controller_frf(ctrl, DT), DT, delay)
        assert result.resolved, (law, delay, plant.n_modes)
        assert result.unstable_poles == _outside(plant, with_delay(ctrl, delay)), \
            (law, delay, plant.n_modes)


def test_the_plant_frf_is_the_state_space_one(models):
    """The modal ZOH sum equals C (zI - A)^-1 B + D / z of the dense discrete matrices."""
    plant, _ = models
    ins, outs = ['strut1_bending_moment_2', 'tcp_force_x'], ['strut1_bending_rate_2',
                                                             'tcp_displacement_x']
    sub = plant.select(ins, outs)
    a, b, c, d = sub.discrete_matrices(DT)
    theta = np.array([0.01, 0.3, 1.7, 3.0])
    z = np.exp(1j * theta)
    dense = np.array([c @ np.linalg.solve(zk * np.eye(a.shape[0]) - a, b) + d / zk for zk in z])
    assert np.allclose(SampledPlantFrf(plant, ins, outs, DT)(theta), dense, rtol=1e-9,
                       atol=1e-12 * np.abs(dense).max())


def test_one_damped_mode_margin_is_the_closed_form():
    """One mode, static gain: sigma_min(I - K P) on the grid reaches min |1 - K P(z)|."""
    from fixtures.demo_model import demo_model
    plant = demo_model(n_modes=1, f_min=50.0, f_max=50.0, zeta=0.02, inputs=['tcp_force_x'])
    ctrl = controller_of(tcp_damper(['x'], 300.0))
    result = nyquist_check(plant, ctrl.sensor_ports, ctrl.actuator_ports,
                           controller_frf(ctrl, DT), DT)
    theta = np.linspace(0, np.pi, 200001)
    p = SampledPlantFrf(plant, ['tcp_force_x'], ['tcp_velocity_x'], DT)(theta)[:, 0, 0]
    assert result.verdict == STABLE
    assert result.margin == pytest.approx(np.abs(1.0 + 300.0 * p).min(), rel=1e-4)


def _identified(plant, law, seconds=6.0):
    """The law's FRF identified from an offline run with white noise on its ports."""
    core = DiscretePlant(plant.discretize(DT))
    noise = PortNoise(law.actuator_ports, 10.0, seed=4)
    n = int(seconds / DT)
    run = simulate(core, [law, noise], np.zeros((n, len(core.input_names))))
    y = np.column_stack([run.output(p) for p in law.sensor_ports])
    u = np.column_stack([run.input(p) - np.array([noise.force(k)[i] for k in range(n)])
                         for i, p in enumerate(law.actuator_ports)])
    return mimo_frf([(y, u)], DT, 256, law.sensor_ports, law.actuator_ports)


@pytest.mark.parametrize('law', ['bending 10', 'bending 1e4', 'bending 3e3 struts 1, 2',
                                 'tcp 3e3', 'pma'])
def test_the_identified_controller_gives_the_exact_verdicts(models, law):
    """Black box (FRF from a run) and exact check (spectral radii): same verdict, +1 sample too."""
    plant, check = models
    made = LAWS[law]()
    frf = _identified(plant, made)
    ctrl = controller_of(LAWS[law]())
    exact_k = controller_frf(ctrl, DT)(frf.freq)
    assert np.abs(frf.H - exact_k).max() < 0.02 * np.abs(exact_k).max()
    assert np.nanmin(frf.coherence) > 0.99          # every bin, DC included
    for delay in (0, 1):
        exact = check_loop(plant, check, [with_delay(ctrl, delay)], DT, policy='warn')
        on = {name: nyquist_check(model, frf.inputs, frf.outputs, frf.at, DT, delay)
              for name, model in (('plant', plant), ('check', check))}
        words = (UNSTABLE if on['plant'].unstable_poles else
                 STABLE if not on['check'].unstable_poles else TRUNCATION)
        assert words == exact.verdict, (law, delay)


def test_a_saturating_controller_shows_in_the_coherence(models):
    """Clipping makes u a nonlinear function of y: the multiple coherence drops."""
    plant, _ = models
    law = tcp_damper(['x'], 2.0e4)
    clipped = dataclasses.replace(law) if dataclasses.is_dataclass(law) else law
    step = clipped.step
    clipped.step = lambda y: np.clip(step(y), -2.0, 2.0)
    frf = _identified(plant, clipped)
    assert np.nanmin(frf.coherence[1:]) < 0.9


def test_mimo_frf_recovers_a_known_filter_pair():
    """Two independent white inputs through a known 2x2 system (two records): H1, coherence."""
    rng = np.random.default_rng(0)
    y = rng.standard_normal((40000, 2))
    b, a = scipy.signal.butter(1, 0.2)
    u = np.column_stack([-3 * scipy.signal.lfilter(b, a, y[:, 0]) + 0.5 * y[:, 1],
                         2.0 * np.concatenate([[0.0], y[:-1, 0]])])
    frf = mimo_frf([(y[:20000], u[:20000]), (y[20000:], u[20000:])], DT, 1024)
    _, h = scipy.signal.freqz(b, a, worN=frf.freq, fs=1 / DT)
    z = np.exp(2j * np.pi * frf.freq * DT)
    inner = slice(None)             # segments are not detrended: every bin is an estimate
    assert np.abs(frf.H[inner, 0, 0] + 3 * h[inner]).max() < 0.02
    assert np.abs(frf.H[inner, 0, 1] - 0.5).max() < 0.02
    assert np.abs(frf.H[inner, 1, 0] - 2 / z[inner]).max() < 0.01
    assert np.abs(frf.H[inner, 1, 1]).max() < 0.01
    assert frf.coherence[inner].min() > 0.99 and frf.n_averages == 2 * 38


def test_port_noise_is_fixed_by_seed_and_step():
    """Any order of steps gives the same values; ports are independent."""
    a, b = PortNoise(['tcp_force_x', 'tcp_force_y'], 3.0, 5), PortNoise(['tcp_force_x',
                                                                         'tcp_force_y'], 3.0, 5)
    late = [a.force(k) for k in (9000, 3, 4096, 3)]
    assert np.array_equal(late[1], late[3]) and np.array_equal(late[0], b.force(9000))
    values = np.array([b.force(k) for k in range(20000)])
    assert values.std(axis=0) == pytest.approx([3.0, 3.0], rel=0.03)
    assert abs(np.corrcoef(values.T)[0, 1]) < 0.03
