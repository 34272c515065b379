"""Truncation check of sampled loops against python-control and stepped simulations (no ROS)."""
import dataclasses
import logging

import control
import numpy as np
import pytest
import scipy.linalg
from statespace_fixtures import small_model

from fixtures.demo_model import demo_model
from pentapod_damper.laws import ProofMassActuator, strut_bending_damper, tcp_damper
from pentapod_damper.study.analytic import discrete_frf
from pentapod_sim.errors import ConfigError, PortError, RunError
from pentapod_sim.plant.build import load_reduction_config, plant_from_fe
from pentapod_sim.plant.check_model import (
    check_f_max,
    check_model_from_fe,
    load_or_build_check_model,
)
from pentapod_sim.sim.closed_loop import simulate
from pentapod_sim.sim.stability import (
    check_loop,
    controller_of,
    DiscreteController,
    loop_matrix,
    plant_radius,
    STABLE,
    TRUNCATION,
    UNCHECKED,
    UNSTABLE,
    UnstableLoopError,
)
from pentapod_sim.sim.stepping import DiscretePlant

DT = 1.0 / 2000.0


@pytest.fixture(scope='module')
def plant():
    return demo_model(n_modes=5, f_min=30.0, f_max=400.0, zeta=0.01, feedthrough=2e-8,
                      inputs=['tcp_force_x', 'tcp_force_y', 'strut1_axial_force', 'pma_force_y'])


def lowpass_with_delay(gain: float, corner_hz: float, dt: float) -> DiscreteController:
    """u_k = -gain * w_{k-1}, w a first-order (ZOH) low-pass of the TCP x velocity."""
    pole = np.exp(-2 * np.pi * corner_hz * dt)
    # states: w (filtered velocity), v_prev (one-sample delay of w)
    a = np.array([[pole, 0.0], [1.0, 0.0]])
    b = np.array([[1.0 - pole], [0.0]])
    c = np.array([[0.0, -gain]])
    return DiscreteController(['tcp_velocity_x'], ['tcp_force_x'], a, b, c, [[0.0]])


def python_control_radius(plant, controllers, dt):
    """Max |eig| of control.feedback of the lockstep plant and the controllers (positive)."""
    sys = plant.discretize(dt)
    n, m = sys.nstates, sys.ninputs
    # y_k = C x_k + D u_{k-1}: the feed-through as a one-step-delayed state
    lockstep = control.ss(np.block([[sys.A, np.zeros((n, m))], [np.zeros((m, n + m))]]),
                          np.vstack([sys.B, np.eye(m)]), np.hstack([sys.C, sys.D]),
                          np.zeros((sys.noutputs, m)), dt)
    total = None
    for ctrl in controllers:
        sel_in = np.array([[1.0 if o == s else 0.0 for o in plant.output_names]
                           for s in ctrl.sensor_ports])
        sel_out = np.array([[1.0 if i == a else 0.0 for a in ctrl.actuator_ports]
                            for i in plant.input_names])
        k = control.ss(ctrl.a, ctrl.b, ctrl.c, ctrl.d, dt) if ctrl.n_states else \
            control.ss([], [], [], ctrl.d, dt)
        part = control.ss([], [], [], sel_out, dt) * k * control.ss([], [], [], sel_in, dt)
        total = part if total is None else control.parallel(total, part)
    loop = control.feedback(lockstep, total, sign=+1)
    return np.max(np.abs(np.linalg.eigvals(loop.A)))


@pytest.mark.parametrize('case', ['static', 'dynamic', 'static_on_feedthrough'])
def test_spectral_radius_equals_python_control_feedback(plant, case):
    laws = {'static': [controller_of(tcp_damper(['x', 'y'], 2.0e3))],
            'dynamic': [lowpass_with_delay(4.0e3, 150.0, DT),
                        controller_of(tcp_damper(['y'], 1.0e3))],
            # a law reading a displacement output sees D u_{k-1}: augmented state
            'static_on_feedthrough': [DiscreteController.static(
                ['tcp_displacement_x'], ['tcp_force_x'], [[-2.0e5]])]}[case]
    ours, _ = plant_radius(plant, laws, DT)
    assert ours == pytest.approx(python_control_radius(plant, laws, DT), rel=1e-9)


def test_static_laws_give_the_radius_of_the_study_loop(plant):
    laws = [tcp_damper(['x'], 3.0e3), ProofMassActuator(['y'], 2.0, 800.0, DT)]
    ours, _ = plant_radius(plant, [controller_of(law) for law in laws], DT)
    disc = discrete_frf(plant, laws, DT, [10.0], 'tcp_force_x')
    assert ours == pytest.approx(disc.spectral_radius, rel=1e-12)


def test_radius_of_one_damped_mode_is_the_closed_form():
    """Open loop: |exp(p dt)| = exp(-zeta w dt) for the lowest-decay mode."""
    model = demo_model(n_modes=3, f_min=50.0, f_max=200.0, zeta=0.02, inputs=['tcp_force_x'])
    rho, freq = plant_radius(model, [], DT)
    w = 2 * np.pi * 50.0
    assert rho == pytest.approx(np.exp(-0.02 * w * DT), rel=1e-12)
    assert freq == pytest.approx(50.0 * np.sqrt(1 - 0.02 ** 2), rel=1e-9)
    dense = np.abs(np.linalg.eigvals(model.discrete_matrices(DT)[0])).max()
    assert rho == pytest.approx(dense, rel=1e-12)


@pytest.fixture(scope='module')
def truncated():
    """Small FE model: plant with its modes below 200 Hz, check model with all of them."""
    fe = small_model()
    cfg = load_reduction_config()
    plant, _ = plant_from_fe(fe, dataclasses.replace(cfg, modes_f_max=200.0))
    return plant, check_model_from_fe(fe, cfg, 2000.0)


def _modes_below(f_max: float) -> int:
    """The small FE model's modes below f_max [Hz], from a dense eigenvalue solve."""
    fe = small_model()
    lam = scipy.linalg.eigh(fe.K.toarray(), fe.M.toarray(), eigvals_only=True)
    return int(np.count_nonzero(lam < (2 * np.pi * f_max) ** 2))


def test_stiff_high_modes_make_a_truncated_loop_unstable(truncated):
    """Collocated bending feedback at 1 kHz: stable on the plant's modes, unstable on all."""
    plant, check = truncated
    assert plant.n_modes < check.n_modes == _modes_below(2000.0)
    law = strut_bending_damper([1], 1.0e4)
    result = check_loop(plant, check, [controller_of(law)], 1e-3, policy='warn')
    assert result.verdict == TRUNCATION
    assert result.plant_margin > 0 > result.check_margin
    with pytest.raises(UnstableLoopError, match='stable only thanks to truncation'):
        check_loop(plant, check, [controller_of(law)], 1e-3, policy='refuse')
    # independent confirmation: step both loops from the same kick
    n = 3000
    for model, grows in ((plant, False), (check, True)):
        core = DiscretePlant(model.discretize(1e-3), max_state_norm=1e3)
        kick = np.zeros((n, len(core.input_names)))
        kick[0, core.input_names.index('strut1_bending_moment_2')] = 1.0
        law.reset()
        if grows:
            with pytest.raises(RunError, match='unstable'):
                simulate(core, [law], kick)
        else:
            y = simulate(core, [law], kick).output('strut1_bending_rate_2')
            assert np.abs(y[-300:]).max() < np.abs(y).max()


def test_verdicts_and_policies(truncated, caplog):
    plant, check = truncated
    low = [controller_of(strut_bending_damper([1], 10.0))]
    assert check_loop(plant, check, low, 1e-3).verdict == STABLE
    high = [controller_of(strut_bending_damper([1], 1.0e5))]
    with caplog.at_level(logging.WARNING, logger='pentapod_sim.sim.stability'):
        result = check_loop(plant, check, high, 1e-3, policy='warn', label='too much')
    assert result.verdict == UNSTABLE and result.plant_radius > 1
    assert 'too much' in caplog.text and 'unstable' in caplog.text
    with pytest.raises(ConfigError, match="got 'ignore'"):
        check_loop(plant, check, low, 1e-3, policy='ignore')
    alone = check_loop(plant, None, low, 1e-3, policy='refuse')    # no FE model behind it
    assert alone.verdict == UNCHECKED and alone.check_modes == 0
    with pytest.raises(UnstableLoopError, match='unstable'):
        check_loop(plant, None, high, 1e-3, policy='refuse')


def test_check_model_keeps_the_plant_ports_and_static_gain(truncated):
    plant, check = truncated
    sub = plant.select(['tcp_force_x'], ['tcp_displacement_x'])
    result = check_loop(sub, check, [], 1e-3)
    assert result.check_modes == _modes_below(2000.0) and result.plant_modes == plant.n_modes
    # both carry the exact static compliance: modes' dc gains plus the residual in d
    for model in (plant, check):
        i, o = model.input_names.index('tcp_force_x'), model.output_names.index(
            'tcp_displacement_x')
        static = model.d[o, i] + np.sum(model.c_disp[o] * model.b[:, i] / model.omega ** 2)
        assert static == pytest.approx(plant.meta['static_compliance_full'][o][i], rel=1e-9)


def test_controller_description_round_trips_and_bad_input_is_named(plant):
    ctrl = lowpass_with_delay(4.0e3, 150.0, DT)
    back = DiscreteController.from_json(ctrl.to_json())
    for name in 'abcd':
        np.testing.assert_array_equal(getattr(back, name), getattr(ctrl, name))
    assert back.sensor_ports == ctrl.sensor_ports
    with pytest.raises(ConfigError, match='shape'):
        DiscreteController(['tcp_velocity_x'], ['tcp_force_x'], [[0.5]], [[1.0, 2.0]],
                           [[1.0]], [[0.0]])
    with pytest.raises(ConfigError, match='not a controller description'):
        DiscreteController.from_json('{"a": []}')
    with pytest.raises(ConfigError, match='no linear discrete model'):
        controller_of(ProofMassActuator(['x'], 1.0, 100.0, DT, stroke_limit=0.01))
    a, b, c, d = plant.discrete_matrices(DT)
    with pytest.raises(PortError, match='pma_mount_velocity_z'):
        loop_matrix(a, b, c, d, plant.input_names, plant.output_names,
                    [DiscreteController.static(['pma_mount_velocity_z'], ['tcp_force_x'],
                                               [[1.0]])])


def test_check_cut_off_rule():
    assert check_f_max(3000.0) == 6000.0
    assert check_f_max(1000.0) == 5000.0
    assert check_f_max(1000.0, 8000.0) == 8000.0
    with pytest.raises(ConfigError, match='sample_rate'):
        check_f_max(0.0)


@pytest.mark.slow
def test_check_model_is_cached(tmp_path):
    first, origin = load_or_build_check_model('P1', 1500.0, tmp_path)
    assert origin.startswith('built') and first.frequencies_hz.max() < 1500.0
    assert first.frequencies_hz.max() > 1400.0
    second, origin = load_or_build_check_model('P1', 1500.0, tmp_path)
    assert origin.startswith('loaded cached')
    assert second.content_hash() == first.content_hash()


@pytest.mark.slow
def test_statespace_closed_loop_refuses_a_loop_stable_only_thanks_to_truncation(tmp_path,
                                                                                 capsys):
    from pentapod_sim.cli.statespace import main
    common = ['closed-loop', '--position', 'P1', '--sample-rate', '3000', '--on-unstable',
              'refuse']
    assert main([*common, '--out', str(tmp_path / 'a'), '--damper',
                 'strut1_bending_moment_2=1000']) != 0
    assert 'stable only thanks to truncation' in capsys.readouterr().err
    assert not (tmp_path / 'a').exists()           # refused before writing anything
    assert main([*common, '--out', str(tmp_path / 'b'), '--damper', 'tcp_force_y=2e4']) == 0
    text = capsys.readouterr().out
    assert 'sampled loop at 3000 Hz is stable;' in text and 'below 6000 Hz' in text
    assert (tmp_path / 'b' / 'closed_loop_tcp_displacement_y_tcp_force_y_P1.png').exists()
