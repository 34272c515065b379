"""
Pentapod joint layout, inverse and forward kinematics and reachability.

Frames and conventions (SI units, angles in rad):

* Machine frame: z up, origin on the floor on the machine axis.
* Pose ``(x, y, z, a, b)``: TCP position [m] and the spindle orientation
  ``R = R_y(b) @ R_x(a)``; the platform frame has its origin at the TCP and its z axis along
  the spindle axis (pointing from the tool into the spindle). Rotation about the spindle axis
  is not a machine axis (it is left free by the kinematics).
* Each WP joint sits on a ring of radius ``r`` about the spindle axis at height ``h`` above the
  TCP and turns with the strut about that axis, so every strut line lies in a plane through
  the spindle axis (the layout of LinuxCNC ``pentakins``, formula only).
* Strut ``i`` (1..5, index ``i - 1``) runs from its BP joint ``b_i`` on the frame to its WP
  joint ``w_i``; ``e1 = (w_i - b_i) / L_i``, ``e2`` = the horizontal cardan axis
  ``normalize(z x e1)`` and ``e3 = e1 x e2``.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
import scipy.optimize

from pentapod_sim.errors import UnreachablePoseError
from pentapod_sim.fe.machine_data import MachineParams

N_STRUTS = 5
Array = npt.NDArray[np.float64]


def rotation(a: float, b: float) -> Array:
    """
    Return the platform orientation ``R_y(b) @ R_x(a)``.

    Parameters
    ----------
    a, b : float
        Tilt about the machine x axis and then about the y axis [rad].
    """
    ca, sa, cb, sb = np.cos(a), np.sin(a), np.cos(b), np.sin(b)
    r_x = np.array([[1.0, 0.0, 0.0], [0.0, ca, -sa], [0.0, sa, ca]])
    r_y = np.array([[cb, 0.0, sb], [0.0, 1.0, 0.0], [-sb, 0.0, cb]])
    return r_y @ r_x


@dataclass(frozen=True)
class Layout:
    """
    Joint layout of the machine.

    Attributes
    ----------
    bp_joints : (5, 3) ndarray
        BP joint centres in the machine frame [m].
    wp_radius : (5,) ndarray
        Radius of each WP joint ring about the spindle axis [m].
    wp_height : (5,) ndarray
        Height of each WP joint above the TCP along the spindle axis [m].
    stroke_min, stroke_max : (5,) ndarray
        Limits of the active length (BP joint to WP joint) of each strut [m].
    bp_angle_max, wp_angle_max : float
        Limits of the BP cardan angles and of the WP joint angle [rad].
    home_pose : (5,) ndarray
        Pose at which all joint angles are zero [m, m, m, rad, rad].
    """

    bp_joints: Array
    wp_radius: Array
    wp_height: Array
    stroke_min: Array
    stroke_max: Array
    bp_angle_max: float
    wp_angle_max: float
    home_pose: Array


def layout_from_params(machine: MachineParams) -> Layout:
    """Build the joint :class:`Layout` from machine parameters."""
    bp = machine.bp_joints
    ang = np.asarray(bp.angles)
    bp_xyz = np.column_stack([bp.radius * np.cos(ang), bp.radius * np.sin(ang),
                              np.asarray(bp.z)])
    nose = machine.platform.tcp_below_nose
    return Layout(bp_joints=bp_xyz,
                  wp_radius=np.full(N_STRUTS, machine.wp_joints.radius),
                  wp_height=nose + np.asarray(machine.wp_joints.height),
                  stroke_min=np.asarray(machine.struts.stroke_min, dtype=float),
                  stroke_max=np.asarray(machine.struts.stroke_max, dtype=float),
                  bp_angle_max=bp.angle_max, wp_angle_max=machine.wp_joints.angle_max,
                  home_pose=machine.home_pose.as_array())


@dataclass(frozen=True)
class StrutState:
    """
    Inverse-kinematics result for one pose.

    Attributes
    ----------
    pose : (5,) ndarray
        x, y, z [m], a, b [rad].
    rotation : (3, 3) ndarray
        Platform orientation (columns = platform axes in the machine frame).
    wp_joints : (5, 3) ndarray
        WP joint centres in the machine frame [m].
    lengths : (5,) ndarray
        Active strut lengths, BP joint to WP joint [m].
    frames : (5, 3, 3) ndarray
        Per strut the rows e1, e2, e3 (see module docstring).
    bp_angles : (5, 2) ndarray
        Cardan angles at the BP joints about the home axes e2 and e3 [rad].
    wp_angles : (5, 2) ndarray
        WP joint angles: in-plane elevation change from home and out-of-plane angle [rad].
    """

    pose: Array
    rotation: Array
    wp_joints: Array
    lengths: Array
    frames: Array
    bp_angles: Array
    wp_angles: Array


def _strut_frames(e1: Array) -> Array:
    """Rows e1, e2 = normalize(z x e1), e3 = e1 x e2 for each strut direction."""
    e2 = np.cross(np.array([0.0, 0.0, 1.0]), e1)
    norm = np.linalg.norm(e2, axis=1)
    if np.any(norm < 1e-6):
        bad = int(np.argmin(norm)) + 1
        raise UnreachablePoseError(f'strut {bad} is vertical; its cardan frame is undefined')
    e2 /= norm[:, None]
    e3 = np.cross(e1, e2)
    return np.stack([e1, e2, e3], axis=1)


#: The strut frame convention (rows e1, e2, e3 from the strut axes e1), public for imported models.
strut_frames = _strut_frames


def _basic_ik(layout: Layout, pose: Array) -> tuple[Array, Array, Array, Array]:
    """Return rotation, WP joint centres, WP ring azimuths (platform frame) and lengths."""
    rot = rotation(pose[3], pose[4])
    p = pose[:3]
    local = (layout.bp_joints - p) @ rot          # rows: R^T (b_i - p)
    radial = np.hypot(local[:, 0], local[:, 1])
    if np.any(radial < 1e-9):
        bad = int(np.argmin(radial)) + 1
        raise UnreachablePoseError(f'BP joint {bad} lies on the spindle axis (singular pose)')
    phi = np.arctan2(local[:, 1], local[:, 0])
    w_local = np.column_stack([layout.wp_radius * np.cos(phi), layout.wp_radius * np.sin(phi),
                               layout.wp_height])
    w = p + w_local @ rot.T
    lengths = np.linalg.norm(w - layout.bp_joints, axis=1)
    return rot, w, phi, lengths


def _elevation(layout: Layout, rot: Array, phi: Array, e1: Array) -> Array:
    """In-plane elevation of -e1 (WP joint towards BP joint) in the platform frame [rad]."""
    d = -(e1 @ rot)                               # platform components of -e1
    d_r = d[:, 0] * np.cos(phi) + d[:, 1] * np.sin(phi)
    return np.arctan2(d[:, 2], d_r)


def inverse_kinematics(layout: Layout, pose: npt.ArrayLike) -> StrutState:
    """
    Compute strut lengths, directions and joint angles for a pose (no limit check).

    Parameters
    ----------
    layout : Layout
        Joint layout.
    pose : (5,) array_like
        x, y, z [m], a, b [rad].

    Returns
    -------
    StrutState
    """
    pose = np.asarray(pose, dtype=float).reshape(5)
    rot, w, phi, lengths = _basic_ik(layout, pose)
    e1 = (w - layout.bp_joints) / lengths[:, None]
    frames = _strut_frames(e1)
    # neutral (home) frame of each BP cardan joint; angles: e1 = R_n2(al1) R_n3(al2) n1
    h_rot, h_w, h_phi, h_len = _basic_ik(layout, layout.home_pose)
    n = _strut_frames((h_w - layout.bp_joints) / h_len[:, None])
    c = np.einsum('ikj,ij->ik', n, e1)            # e1 in the neutral frame (n1, n2, n3)
    al2 = np.arcsin(np.clip(c[:, 1], -1.0, 1.0))
    al1 = np.arctan2(-c[:, 2], c[:, 0])
    elev = _elevation(layout, rot, phi, e1)
    elev0 = _elevation(layout, h_rot, h_phi, n[:, 0])
    d = -(e1 @ rot)
    out_of_plane = np.arcsin(np.clip(-d[:, 0] * np.sin(phi) + d[:, 1] * np.cos(phi), -1, 1))
    return StrutState(pose=pose, rotation=rot, wp_joints=w, lengths=lengths, frames=frames,
                      bp_angles=np.column_stack([al1, al2]),
                      wp_angles=np.column_stack([elev - elev0, out_of_plane]))


def check_reachable(layout: Layout, state: StrutState) -> None:
    """
    Raise if a strut or joint limit is violated.

    Raises
    ------
    UnreachablePoseError
        Naming the strut (1..5), the limit and both values.
    """
    for i in range(N_STRUTS):
        length = state.lengths[i]
        if length < layout.stroke_min[i]:
            raise UnreachablePoseError(
                f'strut {i + 1}: length {length:.4f} m below stroke_min {layout.stroke_min[i]} m '
                f'at pose {state.pose.tolist()}')
        if length > layout.stroke_max[i]:
            raise UnreachablePoseError(
                f'strut {i + 1}: length {length:.4f} m above stroke_max {layout.stroke_max[i]} m '
                f'at pose {state.pose.tolist()}')
        for k in range(2):
            ang = state.bp_angles[i, k]
            if abs(ang) > layout.bp_angle_max:
                raise UnreachablePoseError(
                    f'strut {i + 1}: BP cardan angle {k + 1} = {np.degrees(ang):.2f} deg '
                    f'exceeds bp_joints.angle_max {np.degrees(layout.bp_angle_max):.2f} deg')
        ang = state.wp_angles[i, 0]
        if abs(ang) > layout.wp_angle_max:
            raise UnreachablePoseError(
                f'strut {i + 1}: WP joint angle {np.degrees(ang):.2f} deg exceeds '
                f'wp_joints.angle_max {np.degrees(layout.wp_angle_max):.2f} deg')


def solve_pose(layout: Layout, pose: npt.ArrayLike) -> StrutState:
    """Inverse kinematics followed by :func:`check_reachable`; returns the state."""
    state = inverse_kinematics(layout, pose)
    check_reachable(layout, state)
    return state


def forward_kinematics(layout: Layout, lengths: npt.ArrayLike,
                       guess: npt.ArrayLike | None = None, tol: float = 1e-12) -> Array:
    """
    Find the pose whose active strut lengths equal ``lengths`` (numerical, Newton-type).

    Parameters
    ----------
    layout : Layout
        Joint layout.
    lengths : (5,) array_like
        Active strut lengths [m].
    guess : (5,) array_like, optional
        Start pose; default the home pose.
    tol : float
        Tolerance on the length residual [m].

    Returns
    -------
    (5,) ndarray
        Pose x, y, z [m], a, b [rad].

    Raises
    ------
    UnreachablePoseError
        If the iteration does not converge (no assembly near ``guess``).
    """
    target = np.asarray(lengths, dtype=float).reshape(5)
    start = layout.home_pose if guess is None else np.asarray(guess, dtype=float)

    def residual(pose: Array) -> Array:
        return _basic_ik(layout, pose)[3] - target

    # scipy's hybrid Powell method: a Newton iteration with a trust region and a
    # finite-difference Jacobian; no need to hand-write one.
    sol = scipy.optimize.root(residual, start, method='hybr', tol=tol)
    if not sol.success or np.max(np.abs(residual(sol.x))) > 1e3 * tol + 1e-12:
        raise UnreachablePoseError(f'forward kinematics did not converge for lengths '
                                   f'{target.tolist()}: {sol.message}')
    return sol.x
