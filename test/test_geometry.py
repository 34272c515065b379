"""Tests of the pentapod kinematics (pentapod_sim.fe.geometry)."""
import numpy as np
import pytest

from pentapod_sim.errors import UnreachablePoseError
from pentapod_sim.fe.geometry import (
    forward_kinematics,
    inverse_kinematics,
    layout_from_params,
    rotation,
    solve_pose,
)
from pentapod_sim.fe.machine_data import load_machine, load_positions


@pytest.fixture(scope='module')
def layout():
    return layout_from_params(load_machine())


def test_rotation_is_ry_times_rx():
    a, b = 0.3, -0.2
    r = rotation(a, b)
    assert r @ r.T == pytest.approx(np.eye(3), abs=1e-14)
    # the spindle axis (platform z) after tilting a about x, then b about y
    z_after_a = np.array([0.0, -np.sin(a), np.cos(a)])
    expected = np.array([z_after_a[0] * np.cos(b) + z_after_a[2] * np.sin(b), z_after_a[1],
                         -z_after_a[0] * np.sin(b) + z_after_a[2] * np.cos(b)])
    assert r[:, 2] == pytest.approx(expected, abs=1e-14)


def test_home_pose_hand_computed_lengths(layout):
    state = inverse_kinematics(layout, layout.home_pose)
    # untilted: WP joint i at radius r towards its BP joint, height z_tcp + h_i
    b = layout.bp_joints
    horiz = np.hypot(b[:, 0], b[:, 1]) - layout.wp_radius
    vert = b[:, 2] - (layout.home_pose[2] + layout.wp_height)
    assert state.lengths == pytest.approx(np.hypot(horiz, vert), rel=1e-13)
    assert state.bp_angles == pytest.approx(np.zeros((5, 2)), abs=1e-12)
    assert state.wp_angles == pytest.approx(np.zeros((5, 2)), abs=1e-12)


def test_struts_1_and_2_have_lowest_wp_joints(layout):
    low = np.argsort(layout.wp_height)[:2]
    assert sorted(low.tolist()) == [0, 1]


@pytest.mark.parametrize('name', ['P1', 'P2', 'P3', 'P4', 'P5'])
def test_strut_frames_and_plane_through_spindle_axis(layout, name):
    state = solve_pose(layout, load_positions()[name])
    f = state.frames
    for i in range(5):
        assert f[i] @ f[i].T == pytest.approx(np.eye(3), abs=1e-12)
        assert np.linalg.det(f[i]) == pytest.approx(1.0)
        assert f[i, 1, 2] == pytest.approx(0.0, abs=1e-14)   # e2 horizontal
        # the strut line meets the spindle axis: coplanar with it
        axis = state.rotation[:, 2]
        d = layout.bp_joints[i] - state.pose[:3]
        assert np.dot(np.cross(axis, f[i, 0]), d) == pytest.approx(0.0, abs=1e-12)
        assert np.linalg.norm(state.wp_joints[i] - layout.bp_joints[i]) == pytest.approx(
            state.lengths[i])
    assert state.wp_angles[:, 1] == pytest.approx(np.zeros(5), abs=1e-12)


@pytest.mark.parametrize('name', ['P2', 'P3', 'P5'])
def test_forward_kinematics_round_trip(layout, name):
    pose = load_positions()[name]
    lengths = inverse_kinematics(layout, pose).lengths
    found = forward_kinematics(layout, lengths, guess=pose + [0.02, -0.02, 0.03, 0.05, -0.05])
    assert found == pytest.approx(pose, abs=1e-9)
    assert inverse_kinematics(layout, found).lengths == pytest.approx(lengths, abs=1e-11)


def test_unreachable_poses_name_strut_and_limit(layout):
    with pytest.raises(UnreachablePoseError, match=r'strut \d: length .* above stroke_max'):
        solve_pose(layout, [0.0, 0.0, -0.5, 0.0, 0.0])
    with pytest.raises(UnreachablePoseError, match=r'strut 4: length .* below stroke_min'):
        solve_pose(layout, [0.4, -0.1, 0.9, 0.0, 0.0])
    with pytest.raises(UnreachablePoseError, match=r'WP joint angle .* exceeds wp_joints'):
        solve_pose(layout, [0.0, 0.0, 0.85, np.radians(60.0), 0.0])
    tight = layout.__class__(**{**layout.__dict__, 'bp_angle_max': np.radians(5.0)})
    with pytest.raises(UnreachablePoseError, match=r'BP cardan angle \d = .* deg exceeds'):
        solve_pose(tight, load_positions()['P2'])


def test_stroke_limits_apply_per_strut(layout):
    """A limit lowered for strut 5 only rejects P1 with strut 5 named (its length is 1.379 m)."""
    lengths = inverse_kinematics(layout, load_positions()['P1']).lengths
    stroke_max = np.array(layout.stroke_max, dtype=float)
    stroke_max[4] = lengths[4] - 0.01
    tight = layout.__class__(**{**layout.__dict__, 'stroke_max': stroke_max})
    with pytest.raises(UnreachablePoseError, match=r'strut 5: length 1\.37\d+ m above stroke_max'):
        solve_pose(tight, load_positions()['P1'])
    solve_pose(layout, load_positions()['P1'])
