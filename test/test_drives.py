"""
The feed drives in the loop: the rotor-link mechanics, the cascade, statics and discretisation.

The drive seen from the strut against the closed form of a link in series with a servo-held
rotor; the machine with its drives keeps the FE model's static compliance (a static FE solve);
the exact discretisation of the coupled plant against a dense matrix exponential; the sampled
cascade converging to the continuous one; HAC-LAC restoring the static stiffness that IFF
alone takes away.
"""
import dataclasses

import numpy as np
import pytest
from scipy.signal import cont2discrete
from statespace_fixtures import all_modes, small_model

from pentapod_sim.errors import ConfigError, PortError
from pentapod_sim.plant import drives as plant_drives
from pentapod_sim.plant import ports, reduction
from pentapod_sim.plant.build import from_modal_data
from pentapod_sim.plant.drives import DrivenPlant, DriveParams, link_stiffness, load_drives
from pentapod_sim.plant.model import PlantModel
from pentapod_sim.sim.drives import FeedDrives, servo_impedance
from pentapod_sim.sim.law_models import iff
from pentapod_sim.sim.loop_frf import modal_form, SampledLoop
from pentapod_sim.sim.loop_poles import continuous_loop_system

PARAMS = DriveParams(rotor_mass=300.0, velocity_bandwidth_hz=80.0, velocity_reset_time=0.01,
                     position_gain=50.0, current_bandwidth_hz=1000.0, delay_steps=1)
M_STRUT, K_S, K_A = 60.0, 5.0e6, 4.0e8


def strut_on_link() -> PlantModel:
    """A strut mass on its drive link k_a (to a fixed gimbal) and on a structure spring k_s."""
    w = np.sqrt((K_S + K_A) / M_STRUT)
    phi = 1 / np.sqrt(M_STRUT)
    return PlantModel([w], [0.0], [[phi]], [[phi], [-K_A * phi]], [[0.0], [0.0]],
                      [[0.0], [1.0]], ['strut1_drive_force'],
                      ['strut1_drive_displacement', 'strut1_force'], ['N'], ['m', 'N'],
                      [''], ['', ''])


def test_config_file_loads_and_the_link_is_read_from_the_ports():
    params = load_drives()
    assert params.velocity_gain == pytest.approx(params.rotor_mass * 2 * np.pi
                                                 * params.velocity_bandwidth_hz)
    assert link_stiffness(strut_on_link(), 1) == pytest.approx(K_A, rel=1e-12)
    with pytest.raises(PortError, match='strut2_force'):
        link_stiffness(strut_on_link(), 2)


def test_drive_seen_from_the_strut_is_the_closed_form():
    """Strut motion per force on the strut: 1 / (m s^2 + k_s + k_a Z / (k_a + Z))."""
    plant = DrivenPlant(strut_on_link(), PARAMS, struts=(1,))
    a, b, c_y = continuous_loop_system(plant, [FeedDrives(PARAMS, (1,)).continuous()])
    freq = np.array([0.5, 8.0, 27.0, 90.0, 184.0, 700.0])
    s = 2j * np.pi * freq
    j, o = plant.input_names.index('strut1_drive_force'), 0
    got = np.array([c_y[o] @ np.linalg.solve(sf * np.eye(a.shape[0]) - a, b[:, j])
                    for sf in s])
    expected = 1 / (M_STRUT * s ** 2 + K_S + servo_impedance(PARAMS, K_A, freq))
    np.testing.assert_allclose(got, expected, rtol=1e-9)
    # statically the rotor is held: the link is as stiff as the locked FE model's
    assert servo_impedance(PARAMS, K_A, [1e-6])[0].real == pytest.approx(K_A, rel=1e-6)


def test_sampled_cascade_converges_to_the_continuous_one():
    plant = DrivenPlant(strut_on_link(), PARAMS, struts=(1,))
    freq = np.array([10.0, 60.0])
    s = 2j * np.pi * freq
    a, b, c_y = continuous_loop_system(plant, [FeedDrives(PARAMS, (1,)).continuous()])
    cont = np.array([c_y[0] @ np.linalg.solve(sf * np.eye(a.shape[0]) - a, b[:, 0])
                     for sf in s])
    errors = []
    for rate in (5e3, 5e4):
        params = dataclasses.replace(PARAMS, delay_steps=0)
        loop = SampledLoop(plant, [FeedDrives(params, (1,)).discrete(1 / rate)], 1 / rate)
        errors.append(np.max(np.abs(loop.output('strut1_drive_displacement',
                                                'strut1_drive_force')(freq) - cont)
                             / np.abs(cont)))
    assert errors[1] < errors[0] / 5 and errors[1] < 1e-2


@pytest.mark.parametrize('expm_states', [10_000, 4])
def test_exact_discretisation_of_the_coupled_plant(monkeypatch, expm_states):
    """Both paths (dense exponential, eigenvectors) against scipy's cont2discrete."""
    monkeypatch.setattr(plant_drives, 'EXPM_STATES', expm_states)
    plant = DrivenPlant(strut_on_link(), PARAMS, struts=(1,))
    a, b, c, d = plant.state_matrices()
    a_d, b_d, *_ = cont2discrete((a, b, c, d), 2e-4, method='zoh')
    mine = plant.discrete_matrices(2e-4)
    np.testing.assert_allclose(mine[0], a_d, atol=1e-9)
    np.testing.assert_allclose(mine[1], b_d, rtol=1e-7, atol=1e-16)


@pytest.fixture(scope='module')
def fe_plant():
    """Every mode of the small FE model with drive links, and the model."""
    model = small_model(3)
    omega, phi = all_modes(model)
    points = {**model.points, **ports.load_points(model.points, model.stiffness_groups)}
    names_in = ['tcp_force_x'] + [f'strut{i}_drive_force' for i in range(1, 6)]
    names_out = (['tcp_displacement_x'] + [f'strut{i}_drive_displacement' for i in range(1, 6)]
                 + [f'strut{i}_force' for i in range(1, 6)])
    plant = from_modal_data(omega / (2 * np.pi), ports.modal_points(points, phi),
                            model.strut_frames, names_in, names_out, 0.001)
    return model, plant


def test_machine_with_drives_keeps_the_static_fe_compliance(fe_plant):
    model, plant = fe_plant
    b = ports.input_matrix(ports.ports(model.points, model.strut_frames, ['tcp_force_x']))
    c, _ = ports.output_matrices(ports.ports(model.points, model.strut_frames,
                                             ['tcp_displacement_x']))
    exact = reduction.static_compliance(model.K, b, c)[0, 0]
    driven = DrivenPlant(plant, PARAMS)
    for feedback in (FeedDrives(PARAMS), FeedDrives(PARAMS, iff_gain=300.0, iff_omega=3.0)):
        loop = SampledLoop(driven, [feedback.discrete(1e-4)], 1e-4)
        assert loop.spectral_radius < 1
        assert loop.static('tcp_displacement_x', 'tcp_force_x') == pytest.approx(exact,
                                                                                 rel=1e-7)


def test_iff_alone_softens_the_link_statically(fe_plant):
    """IFF with omega_i: the link keeps k_a / (1 + g / omega_i) statically (Maxwell + spring)."""
    _, plant = fe_plant
    g, w_i = 300.0, 30.0
    law = iff([f'strut{i}_force' for i in range(1, 6)],
              [f'strut{i}_drive_force' for i in range(1, 6)], g, w_i)
    soft = SampledLoop(plant, [law.discrete(1e-4)], 1e-4).static('tcp_displacement_x',
                                                                    'tcp_force_x')
    base = SampledLoop(plant, [], 1e-4).static('tcp_displacement_x', 'tcp_force_x')
    assert soft > 1.01 * base


def test_bad_drive_values_are_named(tmp_path):
    path = tmp_path / 'drives.yaml'
    path.write_text('rotor_mass: -3\nvelocity_bandwidth_hz: 80\nvelocity_reset_time: 0.01\n'
                    'position_gain: 50\ncurrent_bandwidth_hz: 1000\ndelay_steps: 1\n')
    with pytest.raises(ConfigError, match='rotor_mass = -3.0 kg: must be > 0'):
        load_drives(path)
    with pytest.raises(ConfigError, match='at least one strut'):
        FeedDrives(PARAMS, ())
    with pytest.raises(ConfigError, match=r'distinct numbers 1\.\.5, got \[1, 7\]'):
        FeedDrives(PARAMS, (1, 7))


def _control_closed_loop(plant, controllers, dt):
    """The sampled loop built by python-control: ZOH plant, controllers fed back (sign +)."""
    import control
    sys_p = plant.discretize(dt)
    outs, ins = list(plant.output_names), list(plant.input_names)
    loop = None
    for ctrl in controllers:
        pick_y = np.zeros((len(ctrl.sensor_ports), len(outs)))
        pick_y[np.arange(len(ctrl.sensor_ports)), [outs.index(p) for p in ctrl.sensor_ports]] = 1
        put_u = np.zeros((len(ins), len(ctrl.actuator_ports)))
        put_u[[ins.index(p) for p in ctrl.actuator_ports], np.arange(len(ctrl.actuator_ports))] = 1
        k = control.ss(ctrl.a, ctrl.b @ pick_y, put_u @ ctrl.c, put_u @ ctrl.d @ pick_y, dt)
        loop = k if loop is None else control.parallel(loop, k)
    return control.feedback(sys_p, loop, sign=1)


def test_hac_lac_loop_modal_form_against_python_control(fe_plant):
    """
    The pole-residue form of a loop with the drives' rotors: poles and FRF as python-control's.

    The loop mixes the links' 4e8 N/m with metres (matrix entries ~1e10); the modal form's
    Schur decomposition without balancing moved eigenvalues by up to 0.2 and reported a
    spurious unstable pole for HAC-LAC at P1 (modulus 1.23, the loop's largest 0.99991).
    """
    _, plant = fe_plant
    driven = DrivenPlant(plant, PARAMS)
    dt = 2e-4
    ctrl = FeedDrives(PARAMS, iff_gain=150.0, iff_omega=2.3).discrete(dt)
    loop = SampledLoop(driven, [ctrl], dt)
    reference = _control_closed_loop(driven, [ctrl], dt)
    poles = np.linalg.eigvals(reference.A)
    assert loop.spectral_radius == pytest.approx(np.abs(poles).max(), abs=1e-9)
    nonzero = loop.lam[np.abs(loop.lam) > 1e-8]
    assert max(np.min(np.abs(poles - p)) for p in nonzero) < 1e-6
    freq = np.array([3.0, 11.0, 27.0, 95.0, 410.0, 1200.0])
    o, j = (driven.output_names.index('tcp_displacement_x'),
            driven.input_names.index('tcp_force_x'))
    expected = np.array([reference(np.exp(2j * np.pi * f * dt))[o, j] for f in freq])
    got = loop.output('tcp_displacement_x', 'tcp_force_x')(freq)
    np.testing.assert_allclose(got, expected, rtol=1e-6)

    # the same loop in other units (states scaled by 1e-6 .. 1e6: entries up to 1e13, as
    # the P1 loop's 1e10): the modal form's poles and resolvent are unchanged
    scale = 10.0 ** np.random.default_rng(1).uniform(-6, 6, reference.A.shape[0])
    a = reference.A * scale[:, None] / scale[None, :]
    lam, left, right, nil = modal_form(a)
    assert np.abs(lam).max() == pytest.approx(np.abs(poles).max(), abs=1e-9)
    col, row = reference.B[:, j] * scale, reference.C[o] / scale
    for f in freq:
        z = np.exp(2j * np.pi * f * dt)
        r, col_n = right(col.astype(complex))
        modal = np.sum(left(row) * r / (z - lam[:r.size]))
        fir = nil(row, col_n)
        modal += np.sum(fir * z ** -(np.arange(fir.size) + 1.0))
        dense = row @ np.linalg.solve(z * np.eye(a.shape[0]) - a, col)
        assert modal == pytest.approx(dense, rel=1e-6)
