"""Tests of the sparse FE model assembly (pentapod_sim.fe.assembly)."""
import dataclasses

import numpy as np
import pytest
import scipy.linalg as sla
import scipy.sparse.linalg as spla

from pentapod_sim.errors import ConfigError, UnreachablePoseError
from pentapod_sim.fe.assembly import build_model, GROUPS
from pentapod_sim.fe.beam import rhs_section
from pentapod_sim.fe.geometry import inverse_kinematics, layout_from_params
from pentapod_sim.fe.machine_data import load_machine, load_positions

COARSE = 0.35                                     # m, element size for dense eigen checks


@pytest.fixture(scope='module')
def machine():
    return load_machine()


@pytest.fixture(scope='module')
def model(machine):
    return build_model(machine, 'P1')


@pytest.fixture(scope='module')
def free_coarse(machine):
    return build_model(machine, 'P2', element_size=COARSE, installed=False)


def _skew(v):
    return np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])


def test_named_points_of_the_contract_exist(model):
    names = {'tcp', 'spindle_nose', 'pma_mount'}
    for i in range(1, 6):
        names |= {f'strut{i}_wp_end', f'strut{i}_rear_end', f'strut{i}_at_bp', f'bp_ring{i}',
                  f'wp_joint{i}'}
    assert names <= set(model.points)
    for name in names:
        assert model.point(name).shape == (6, model.n_dof)
        assert model.point_positions[name].shape == (3,)
    with pytest.raises(KeyError, match='unknown point'):
        model.point('nose')


def test_groups_sum_to_k_and_matrices_symmetric(model):
    assert set(model.stiffness_groups) == set(GROUPS)
    total = sum(model.stiffness_groups.values())
    scale = abs(model.K).max()
    assert abs(total - model.K).max() <= 1e-12 * scale
    assert abs(model.K - model.K.T).max() <= 1e-12 * scale
    assert abs(model.M - model.M.T).max() <= 1e-12 * abs(model.M).max()
    for name, group in model.stiffness_groups.items():
        assert group.nnz > 0, name


def test_total_mass_equals_parts_and_hand_sum(machine, model):
    q = np.tile([1.0, 0, 0, 0, 0, 0], model.n_dof // 6)
    for axis in range(3):
        r = np.roll(q, axis)
        assert r @ (model.M @ r) == pytest.approx(sum(model.mass_parts.values()), rel=1e-9)
    # independent hand sums of the struts and lumped parts
    s = machine.struts
    sec = rhs_section(s.section.width, s.section.height, s.section.thickness)
    dens = machine.materials.steel.density
    assert model.mass_parts['struts'] == pytest.approx(sum(s.tube_length) * dens * sec.area)
    assert model.mass_parts['ball_screws'] == pytest.approx(
        sum(s.tube_length) * s.screw_mass_per_length)
    assert model.mass_parts['gimbals'] == pytest.approx(5 * machine.bp_joints.gimbal_mass)
    assert model.mass_parts['platform'] == machine.platform.mass
    assert model.mass_parts['bed'] == machine.frame.bed_mass


def test_rigid_translation_moves_every_point_equally(model):
    d = np.array([1e-3, -2e-3, 0.5e-3])
    q = np.tile(np.concatenate([d, np.zeros(3)]), model.n_dof // 6)
    for name, obs in model.points.items():
        assert obs @ q == pytest.approx(np.concatenate([d, np.zeros(3)]), abs=1e-15), name


def test_platform_points_follow_the_rigid_platform(model):
    rng = np.random.default_rng(1)
    q = rng.standard_normal(model.n_dof)
    cog = model.point('platform_cog') @ q
    x_cog = model.point_positions['platform_cog']
    for name in ['tcp', 'spindle_nose', 'pma_mount'] + [f'wp_joint{i}' for i in range(1, 6)]:
        u = model.point(name) @ q
        r = model.point_positions[name] - x_cog
        assert u[:3] == pytest.approx(cog[:3] + np.cross(cog[3:], r), rel=1e-12)
        assert u[3:] == pytest.approx(cog[3:], rel=1e-12)


def test_free_structure_has_exactly_six_rigid_body_modes(free_coarse):
    k, m = free_coarse.K.toarray(), free_coarse.M.toarray()
    w2, phi = sla.eigh(k, m, subset_by_index=[0, 9])
    assert np.abs(w2[:6]).max() < 1e-6 * w2[6]
    assert w2[6] > (2 * np.pi * 1.0) ** 2
    # each zero mode moves all named points as one rigid body
    x_tcp = free_coarse.point_positions['tcp']
    for j in range(6):
        u_tcp = free_coarse.point('tcp') @ phi[:, j]
        for name in ('bed', 'strut3_rear_end', 'bp_ring5', 'wp_joint1'):
            u = free_coarse.point(name) @ phi[:, j]
            r = free_coarse.point_positions[name] - x_tcp
            size = np.abs(u_tcp).max()
            assert u[3:] == pytest.approx(u_tcp[3:], abs=1e-6 * size)
            assert u[:3] == pytest.approx(u_tcp[:3] - _skew(r) @ u_tcp[3:], abs=1e-6 * size)


def test_installed_machine_is_positive_definite(machine):
    fe = build_model(machine, 'P1', element_size=COARSE)
    ev_k = sla.eigh(fe.K.toarray(), fe.M.toarray(), eigvals_only=True, subset_by_index=[0, 0])
    assert ev_k[0] > (2 * np.pi * 5.0) ** 2
    assert np.linalg.eigvalsh(fe.M.toarray()).min() > 0.0


def test_spindle_rotation_needs_wp_joint_torsion(machine):
    soft = dataclasses.replace(
        machine, wp_joints=dataclasses.replace(machine.wp_joints, torsion_stiffness=1e-6))
    fe = build_model(soft, 'P1', element_size=COARSE)
    w2, phi = sla.eigh(fe.K.toarray(), fe.M.toarray(), subset_by_index=[0, 0])
    assert w2[0] < (2 * np.pi * 0.05) ** 2          # a mechanism without joint torsion
    rot = fe.point('tcp') @ phi[:, 0]
    axis = fe.point_positions['spindle_nose'] - fe.point_positions['tcp']
    axis /= np.linalg.norm(axis)
    assert abs(rot[3:] @ axis) > 0.99 * np.linalg.norm(rot[3:])


def test_struts_remeshed_per_pose(machine):
    layout = layout_from_params(machine)
    for name in ('P1', 'P2'):
        pose = load_positions()[name]
        fe = build_model(machine, pose, element_size=0.2)
        state = inverse_kinematics(layout, pose)
        assert fe.strut_frames == pytest.approx(state.frames)
        for i in range(5):
            p = fe.point_positions
            at_bp, rear = p[f'strut{i + 1}_at_bp'], p[f'strut{i + 1}_rear_end']
            wp_end = p[f'strut{i + 1}_wp_end']
            assert at_bp == pytest.approx(layout.bp_joints[i])
            assert np.linalg.norm(rear - at_bp) == pytest.approx(
                machine.struts.tube_length[i] - state.lengths[i])
            assert np.linalg.norm(wp_end - rear) == pytest.approx(machine.struts.tube_length[i])


def test_refinement_grows_dof_and_converges(machine):
    coarse = build_model(machine, 'P1', element_size=0.2)
    fine = build_model(machine, 'P1', element_size=0.05)
    assert fine.n_dof > 3 * coarse.n_dof
    f = [np.sqrt(spla.eigsh(fe.K, 8, fe.M, sigma=0, return_eigenvectors=False)) for fe in
         (coarse, fine)]
    assert np.sort(f[0]) == pytest.approx(np.sort(f[1]), rel=2e-3)


def test_bad_pose_and_position_name(machine):
    with pytest.raises(UnreachablePoseError, match='stroke_max'):
        build_model(machine, [0.0, 0.0, -0.5, 0.0, 0.0])
    with pytest.raises(ConfigError, match="unknown position 'P9'"):
        build_model(machine, 'P9')


def test_calibration_targets_of_the_default_model(model):
    """Frame x mode near 27 Hz, vertical frame mode near 67 Hz, BP-joint axial modes 70-110."""
    w2, phi = spla.eigsh(model.K, 30, model.M, sigma=0)
    f = np.sqrt(w2) / (2 * np.pi)
    bed = model.point('bed')[:3] @ phi
    energy = {g: np.einsum('ij,ij->j', phi, model.stiffness_groups[g] @ phi) / w2
              for g in GROUPS}
    frame_energy = energy['frame'] + energy['installation']
    frame_like = frame_energy > 0.8
    x_modes = f[frame_like & (np.abs(bed[0]) > 0.5 * np.abs(bed).max(axis=0))]
    # the vertical frame mode mixes with strut bending near 67 Hz (struts 1/2 and 5 bend at
    # 30-70 Hz): it may split into neighbours, each with a smaller frame + foot energy share
    z_modes = f[(frame_energy > 0.4) & (np.abs(bed[2]) > 0.5 * np.abs(bed).max(axis=0))]
    assert 25.0 < x_modes.min() < 29.0
    assert np.any((z_modes > 62.0) & (z_modes < 72.0))
    assert f.min() > 15.0
    axial = f[energy['bp_joints'] > 0.2]
    assert axial.size >= 2 and 70.0 < axial.min() and axial.min() < 110.0


def test_joint_springs_act_along_the_strut_frame(machine, model):
    """Moving one joint node along/about e1, e2, e3 stores exactly the parameter stiffness."""
    bp, fd, wp = machine.bp_joints, machine.feed_drives, machine.wp_joints
    cases = [('gimbal', 'bp_joints', [bp.needle_axial_stiffness, bp.needle_cardan1_stiffness,
                                      bp.needle_cardan2_stiffness, bp.torsion_stiffness, 0, 0]),
             ('gimbal', 'feed_drives', [fd.nut_axial_stiffness, fd.guide_lateral_stiffness,
                                        fd.guide_lateral_stiffness, fd.torsion_stiffness,
                                        fd.bending_stiffness, fd.bending_stiffness]),
             ('strut{}_wp_end', 'wp_joints', [wp.axial_stiffness, wp.lateral_stiffness,
                                              wp.lateral_stiffness, wp.torsion_stiffness, 0, 0])]
    for i in range(1, 6):
        frame = model.strut_frames[i - 1]
        for node, group, stiffness in cases:
            name = node.format(i) if '{' in node else f'{node}{i}'
            obs = model.point(name)
            k_group = model.stiffness_groups[group]
            for j in range(6):
                d = np.zeros(6)
                d[3 * (j // 3):3 * (j // 3) + 3] = frame[j % 3]
                q = obs.T @ d                         # this node alone moves by d
                assert q @ (k_group @ q) == pytest.approx(stiffness[j], rel=1e-9,
                                                          abs=1e-6), (name, group, j)
