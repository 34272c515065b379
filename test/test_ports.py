"""Ports: names, units, and that each load vector/observation row means what it says."""
import numpy as np
import pytest
from statespace_fixtures import small_model

from pentapod_sim.errors import PortError
from pentapod_sim.plant import ports


@pytest.fixture(scope='module')
def model():
    return small_model(1)


def _displacement(model, moves: dict) -> np.ndarray:
    """DOF vector that gives each named point the 6-vector in ``moves`` (others zero)."""
    u = np.zeros(model.n_dof)
    for name, six in moves.items():
        u += model.points[name].T @ np.asarray(six, float)
    return u


def test_names_match_architecture_counts():
    assert len(ports.INPUT_NAMES) == 3 + 5 * 6 + 3
    assert len(ports.OUTPUT_NAMES) == 6 + 5 * 13 + 3
    assert len(set(ports.INPUT_NAMES + ports.OUTPUT_NAMES)) == 36 + 74
    model = small_model(0)
    points = {**model.points, **ports.load_points(model.points, model.stiffness_groups)}
    kinds = {n: ports.port(points, model.strut_frames, n).kind for n in ports.OUTPUT_NAMES}
    assert set(kinds.values()) == {'displacement', 'velocity', 'load'}
    assert [n for n, k in kinds.items() if k == 'load'] == [f'strut{i}_force' for i in range(1, 6)]


@pytest.mark.parametrize('axis', [0, 1, 2])
def test_tcp_displacement_reads_global_component(model, axis):
    six = np.array([1e-6, -2e-6, 3e-6, 0.01, 0.02, 0.03])
    u = _displacement(model, {'tcp': six, 'pma_mount': [5.0] * 6})
    name = 'tcp_displacement_' + 'xyz'[axis]
    p = ports.port(model.points, model.strut_frames, name)
    assert p.unit == 'm' and p.kind == 'displacement'
    assert p.vector @ u == pytest.approx(six[axis])


@pytest.mark.parametrize('strut', [1, 3, 5])
@pytest.mark.parametrize('k', [2, 3])
def test_strut_bending_is_relative_rotation_about_cardan_axis(model, strut, k):
    e = model.strut_frames[strut - 1]
    theta_wp, theta_rear = 0.004 * e[k - 1] + 0.02 * e[0], 0.001 * e[k - 1]
    other = 0.5 * e[4 - k]   # rotation about the other cardan axis: no bending_k
    u = _displacement(model, {f'strut{strut}_wp_end': np.r_[1.0, 2.0, 3.0, theta_wp + other],
                              f'strut{strut}_rear_end': np.r_[0, 0, 0, theta_rear + other]})
    p = ports.port(model.points, model.strut_frames, f'strut{strut}_bending_{k}')
    assert p.unit == 'rad'
    assert p.vector @ u == pytest.approx(0.003, rel=1e-12)


def test_strut_axial_is_relative_to_cardan_ring(model):
    e1 = model.strut_frames[1, 0]
    lateral = model.strut_frames[1, 1]
    u = _displacement(model, {'strut2_at_bp': np.r_[7e-6 * e1 + 3e-3 * lateral, 0, 0, 0],
                              'bp_ring2': np.r_[2e-6 * e1, 0.1, 0.1, 0.1]})
    p = ports.port(model.points, model.strut_frames, 'strut2_axial_displacement')
    assert p.vector @ u == pytest.approx(5e-6, rel=1e-12)


def test_moment_pair_does_virtual_work_on_bending_only(model):
    # work of the moment pair M on a displacement = M * (e2 . (theta_wp - theta_rear))
    e2 = model.strut_frames[3, 1]
    u = _displacement(model, {'strut4_wp_end': np.r_[0.3, 0.1, 0, 0.2 * e2],
                              'strut4_rear_end': np.r_[0, 0, 0, 0.05 * e2],
                              'tcp': np.ones(6)})
    f = ports.port(model.points, model.strut_frames, 'strut4_bending_moment_2')
    assert f.unit == 'N m' and f.is_input
    assert 100.0 * f.vector @ u == pytest.approx(100.0 * 0.15)


@pytest.mark.parametrize('name', ports.INPUT_NAMES)
def test_every_input_is_collocated_with_its_outputs(model, name):
    f = ports.port(model.points, model.strut_frames, name)
    rate = ports.port(model.points, model.strut_frames, ports.collocated_output(name))
    assert rate.kind == 'velocity'
    np.testing.assert_array_equal(f.vector, rate.vector)


def test_modal_points_give_modal_input_columns(model):
    rng = np.random.default_rng(3)
    phi = rng.normal(size=(model.n_dof, 7))
    fe = ports.port(model.points, model.strut_frames, 'strut5_axial_force')
    modal = ports.port(ports.modal_points(model.points, phi), model.strut_frames,
                       'strut5_axial_force')
    np.testing.assert_allclose(modal.vector, phi.T @ fe.vector, rtol=1e-12)


def test_matrices_split_kinds(model):
    plist = ports.ports(model.points, model.strut_frames,
                        ['tcp_displacement_x', 'tcp_velocity_x'])
    c_disp, c_vel = ports.output_matrices(plist)
    np.testing.assert_array_equal(c_disp[0], plist[0].vector)
    assert not c_disp[1].any() and not c_vel[0].any()
    with pytest.raises(PortError, match='is an output'):
        ports.input_matrix(plist)


def test_unknown_name_lists_known_names(model):
    with pytest.raises(PortError, match="unknown port 'tcp_force_w'; known ports: tcp_force_x"):
        ports.port(model.points, model.strut_frames, 'tcp_force_w')
    with pytest.raises(KeyError):   # PortError is a KeyError
        ports.check_names(['tcp_velocity_x'], 'input')


def test_missing_point_is_named(model):
    points = dict(model.points)
    del points['bp_ring3']
    with pytest.raises(PortError, match="no point 'bp_ring3'"):
        ports.port(points, model.strut_frames, 'strut3_axial_force')


def test_pma_has_no_displacement_output():
    assert ports.collocated_output('pma_force_z') == 'pma_mount_velocity_z'
    with pytest.raises(PortError, match='no collocated'):
        ports.collocated_output('pma_force_z', 'displacement')
