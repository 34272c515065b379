"""
The feed drives and HAC-LAC as the testbed runs them, without ROS.

The damper node's law (``drive_struts``) is ``FeedDrives.discrete(dt)``; with the drives alone
a constant TCP force settles at the FE model's static TCP displacement on the plant with the
drives' rotors (the velocity loop's integral holds each rotor); the truncation check with
``drives`` closes the loop on plant and check model with their rotors and refuses a drive
delay that makes it unstable (radius as python-control's closed loop); a multi-rate plant with
drives is the single-rate loop; bad drive settings are named.
"""
import dataclasses

import numpy as np
import pytest

from fixtures.drives_plant import drives_plant
from pentapod_damper.node_parameters import damper_laws
from pentapod_sim.errors import ConfigError
from pentapod_sim.plant import ports, reduction
from pentapod_sim.plant.drives import drives_path, DriveSet, load_drives
from pentapod_sim.sim.closed_loop import excitation_matrix, simulate
from pentapod_sim.sim.controllers import controller_of
from pentapod_sim.sim.drives import FeedDrives
from pentapod_sim.sim.law_models import Dynamics
from pentapod_sim.sim.loop_frf import SampledLoop
from pentapod_sim.sim.multirate import MultiRatePlant
from pentapod_sim.sim.stability import check_loop, UnstableLoopError

RATE = 5000.0
HAC_LAC = {'drive_struts': [1, 2, 3, 4, 5], 'drive_iff_gain': 150.0, 'drive_iff_omega': 2.3,
           'filter_order': 2, 'bandwidth_hz': 500.0}


def test_the_node_law_is_the_feed_drives_cascade():
    law = damper_laws(dict(HAC_LAC, sample_rate=RATE))['drive_iff_gain']
    mine = law.discrete_model()
    ref = FeedDrives(load_drives(), (1, 2, 3, 4, 5), 150.0, 2.3,
                     Dynamics(2, 500.0)).discrete(1 / RATE)
    assert list(mine.sensor_ports) == list(ref.sensor_ports)
    assert list(mine.actuator_ports) == [f'strut{i}_motor_force' for i in range(1, 6)]
    for m in 'abcd':
        assert np.array_equal(getattr(mine, m), getattr(ref, m)), m
    alone = damper_laws({'drive_struts': [2], 'sample_rate': RATE})['drive_iff_gain']
    assert alone.sensor_ports == ['strut2_motor_position', 'strut2_motor_velocity']


def test_drives_alone_hold_the_static_fe_compliance():
    """A constant TCP force: the TCP settles where the FE model's static solve puts it."""
    model, plant = drives_plant(zeta=0.05)
    b = ports.input_matrix(ports.ports(model.points, model.strut_frames, ['tcp_force_x']))
    c, _ = ports.output_matrices(ports.ports(model.points, model.strut_frames,
                                             ['tcp_displacement_x']))
    exact = reduction.static_compliance(model.K, b, c)[0, 0]
    driven = DriveSet(load_drives()).on(plant)
    core = MultiRatePlant.from_model(driven, RATE)
    laws = list(damper_laws({'drive_struts': [1, 2, 3, 4, 5], 'sample_rate': RATE}).values())
    static = SampledLoop(driven, [controller_of(law) for law in laws], 1 / RATE).static(
        'tcp_displacement_x', 'tcp_force_x')
    assert static == pytest.approx(exact, rel=1e-7)
    steps = int(1.5 * RATE)
    run = simulate(core, laws, excitation_matrix(core, ['tcp_force_x'],
                                                 np.full((steps, 1), 100.0), steps))
    y = run.output('tcp_displacement_x')
    assert y[-1] == pytest.approx(100.0 * exact, rel=1e-6)
    assert abs(y[10] - y[-1]) > 1e-2 * abs(y[-1])      # from rest: it had to settle
    # the motor encoders hold their rotors at 0
    assert np.abs(run.output('strut1_motor_position')[-1]) < 1e-6 * abs(y[-1])


def _control_radius(driven, ctrl, dt: float) -> float:
    """Largest |pole| of the sampled loop built by python-control (sign +)."""
    import control
    sys_p = driven.discretize(dt)
    outs, ins = list(driven.output_names), list(driven.input_names)
    pick = np.zeros((len(ctrl.sensor_ports), len(outs)))
    pick[np.arange(len(ctrl.sensor_ports)), [outs.index(p) for p in ctrl.sensor_ports]] = 1
    put = np.zeros((len(ins), len(ctrl.actuator_ports)))
    put[[ins.index(p) for p in ctrl.actuator_ports], np.arange(len(ctrl.actuator_ports))] = 1
    k = control.ss(ctrl.a, ctrl.b @ pick, put @ ctrl.c, put @ ctrl.d @ pick, dt)
    return float(np.abs(np.linalg.eigvals(control.feedback(sys_p, k, sign=1).A)).max())


@pytest.mark.parametrize('delay,stable', [(1, True), (15, False)])
def test_loop_check_with_drives_on_plant_and_check_model(delay, stable):
    """Plant: the 60 lowest modes; check model: all 186, both with the rotors."""
    _, full = drives_plant()
    _, plant = drives_plant(n_modes=60)
    params = dataclasses.replace(load_drives(), delay_steps=delay)
    drives, dt = DriveSet(params), 1 / RATE
    ctrl = controller_of(damper_laws(dict(HAC_LAC, sample_rate=RATE,
                                          drive_file=str(_yaml(params))))['drive_iff_gain'])
    result = check_loop(plant, full, [ctrl], dt, 'warn', drives=drives)
    assert result.check_modes == 186 and result.plant_modes == 60
    assert result.plant_radius == pytest.approx(_control_radius(drives.on(plant), ctrl, dt),
                                                abs=1e-9)
    assert result.check_radius == pytest.approx(_control_radius(drives.on(full), ctrl, dt),
                                                abs=1e-9)
    if stable:
        assert check_loop(plant, full, [ctrl], dt, 'refuse', drives=drives).check_radius < 1
    else:
        assert result.check_radius > 1.01
        with pytest.raises(UnstableLoopError, match='unstable'):
            check_loop(plant, full, [ctrl], dt, 'refuse', drives=drives)


_FILES: dict = {}


def _yaml(params) -> str:
    """A drives file of ``params`` (kept for the session)."""
    import tempfile
    if params not in _FILES:
        f = tempfile.NamedTemporaryFile('w', suffix='.yaml', delete=False)
        f.write(''.join(f'{field.name}: {getattr(params, field.name)}\n'
                        for field in dataclasses.fields(params) if field.name != 'source'))
        f.close()
        _FILES[params] = f.name
    return _FILES[params]


def test_bad_drive_settings_are_named():
    assert drives_path('drives.yaml').is_file()          # a bare name: the config folder
    with pytest.raises(ConfigError, match="drives file 'nope.yaml' not found"):
        drives_path('nope.yaml')
    with pytest.raises(ConfigError, match=r'distinct numbers 1\.\.5, got \[1, 7\]'):
        DriveSet(load_drives(), (1, 7))
    with pytest.raises(ConfigError, match="drives file 'missing.yaml' not found"):
        damper_laws({'drive_struts': [1], 'drive_file': 'missing.yaml', 'sample_rate': RATE})


def test_a_multi_rate_plant_with_drives_is_the_single_rate_loop():
    """Substeps N: the ZOH over the exchange step, so the same loop to rounding."""
    _, plant = drives_plant()
    driven = DriveSet(load_drives()).on(plant)
    laws = list(damper_laws(dict(HAC_LAC, sample_rate=RATE)).values())
    steps = 400
    force = np.random.default_rng(2).standard_normal((steps, 1)) * 50.0
    runs = []
    for substeps in (1, 4):
        core = MultiRatePlant.from_model(driven, RATE, substeps)
        for law in laws:
            law.reset()
        runs.append(simulate(core, laws, excitation_matrix(core, ['tcp_force_x'], force,
                                                           steps)))
    scale = np.abs(runs[0].y).max(axis=0) + 1e-300
    assert np.abs(runs[0].y).max() > 0
    assert (np.abs(runs[1].y - runs[0].y) / scale).max() < 1e-8


def _mass_normalised_norm(x: np.ndarray, n_modes: int, m_r: float, k_a: np.ndarray) -> float:
    """sqrt(|q, dq|^2 + m_r |x_m|^2 + m_r |v_m|^2 + m_r |F_m / k_a|^2), written out."""
    n, r = 2 * n_modes, k_a.size
    modal, x_m, v_m, f_m = x[:n], x[n:n + r], x[n + r:n + 2 * r], x[n + 2 * r:]
    return float(np.sqrt(modal @ modal + m_r * (x_m @ x_m + v_m @ v_m)
                         + m_r * np.sum((f_m / k_a) ** 2)))


def _step(core, laws, force: float) -> None:
    y = core.outputs()
    u = np.zeros(len(core.input_names))
    u[core.input_index['tcp_force_x']] = force
    for law in laws:
        u[[core.input_index[p] for p in law.actuator_ports]] += law.step(
            y[[core.output_index[p] for p in law.sensor_ports]])
    core.advance(u)


def test_the_divergence_guard_holds_the_rotors_as_tightly_as_the_modes():
    """
    Default max_state_norm with drives: normal runs go on, diverging ones stop.

    A 10 kN TCP force step (a heavy cut: the motors hold kN, above the bound in N) runs; a
    drive delay that makes the loop unstable is stopped at the first step whose
    mass-normalised state norm exceeds the bound.
    """
    from pentapod_sim.errors import RunError
    from pentapod_sim.plant.drives import link_stiffness
    from pentapod_sim.sim.stepping import DEFAULT_MAX_STATE_NORM
    _, plant = drives_plant()
    params = load_drives()
    k_a = np.array([link_stiffness(plant, i) for i in range(1, 6)])
    n = 2 * plant.n_modes
    core = MultiRatePlant.from_model(DriveSet(params).on(plant), RATE)
    assert core.max_state_norm == DEFAULT_MAX_STATE_NORM
    laws = list(damper_laws({'drive_struts': [1, 2, 3, 4, 5], 'sample_rate': RATE}).values())
    force_peak = 0.0
    for _ in range(int(0.5 * RATE)):
        _step(core, laws, 1.0e4)
        force_peak = max(force_peak, float(np.abs(core.x[n + 10:]).max()))
        assert core.state_norm() == pytest.approx(
            _mass_normalised_norm(core.x, plant.n_modes, params.rotor_mass, k_a), rel=1e-12)
    assert force_peak > 2 * DEFAULT_MAX_STATE_NORM          # kN of motor force, in N
    assert np.linalg.norm(core.x[:n]) < 1e-2 * DEFAULT_MAX_STATE_NORM
    # unstable drives (15 samples of delay, test_loop_check_with_drives_...): stopped
    slow = dataclasses.replace(params, delay_steps=15)
    core = MultiRatePlant.from_model(DriveSet(slow).on(plant), RATE)
    laws = list(damper_laws({'drive_struts': [1, 2, 3, 4, 5], 'sample_rate': RATE,
                             'drive_file': _yaml(slow)}).values())
    norms = []
    with pytest.raises(RunError, match='exceeds max_state_norm'):
        for _ in range(int(2 * RATE)):
            _step(core, laws, 100.0)
            norms.append(_mass_normalised_norm(core.x, plant.n_modes, slow.rotor_mass, k_a))
    stop = _mass_normalised_norm(core.x, plant.n_modes, slow.rotor_mass, k_a)
    assert stop > DEFAULT_MAX_STATE_NORM and max(norms, default=0.0) <= DEFAULT_MAX_STATE_NORM
    assert len(norms) > 100              # it grew from rest: not stopped by the motor force in N
