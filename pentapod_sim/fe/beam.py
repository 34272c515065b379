"""
3D Timoshenko beam element (two nodes, 12 DOF) and cross-section helpers.

Stiffness after Przemieniecki with the shear parameter ``phi = 12 E I / (kappa G A L^2)``;
consistent mass with rotary inertia and the same shear parameter (the phi-dependent form of
Przemieniecki / Friedman-Kosmatka). All functions are vectorised over elements: every
argument may be an array of length ``n_elements`` and results are ``(n, 12, 12)`` arrays.

Node DOF order (local and global): ux, uy, uz, rx, ry, rz; element DOFs = node 1 then node 2.
Local axes: x from node 1 to node 2, y from the orientation vector (made orthogonal to x),
z = x cross y. Units: SI (N, m, kg, rad).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from pentapod_sim.errors import ConfigError

Array = npt.NDArray[np.float64]


@dataclass(frozen=True)
class Section:
    """
    Beam cross-section properties.

    Attributes
    ----------
    area : float
        Cross-section area A [m^2].
    iy : float
        Second moment of area about the local y axis (bending in the x-z plane) [m^4].
    iz : float
        Second moment of area about the local z axis (bending in the x-y plane) [m^4].
    torsion : float
        Saint-Venant torsion constant J [m^4].
    """

    area: float
    iy: float
    iz: float
    torsion: float


def rhs_section(width: float, height: float, thickness: float) -> Section:
    """
    Return the properties of a rectangular hollow section.

    Parameters
    ----------
    width : float
        Outer size along the local y axis [m].
    height : float
        Outer size along the local z axis [m].
    thickness : float
        Wall thickness [m]; the torsion constant uses Bredt's thin-wall formula.
    """
    if min(width, height, thickness) <= 0.0 or 2.0 * thickness >= min(width, height):
        raise ConfigError(f'invalid RHS {width!r} x {height!r} x {thickness!r} m')
    wi, hi = width - 2.0 * thickness, height - 2.0 * thickness
    area = width * height - wi * hi
    iy = (width * height ** 3 - wi * hi ** 3) / 12.0
    iz = (height * width ** 3 - hi * wi ** 3) / 12.0
    a_mid = (width - thickness) * (height - thickness)
    perimeter = 2.0 * ((width - thickness) + (height - thickness))
    return Section(area=area, iy=iy, iz=iz, torsion=4.0 * a_mid ** 2 * thickness / perimeter)


def tube_section(outer_diameter: float, thickness: float) -> Section:
    """Return the properties of a circular tube (outer diameter and wall [m])."""
    if min(outer_diameter, thickness) <= 0.0 or 2.0 * thickness > outer_diameter:
        raise ConfigError(f'invalid tube {outer_diameter!r} x {thickness!r} m')
    ro, ri = outer_diameter / 2.0, outer_diameter / 2.0 - thickness
    i = np.pi * (ro ** 4 - ri ** 4) / 4.0
    return Section(area=np.pi * (ro ** 2 - ri ** 2), iy=i, iz=i, torsion=2.0 * i)


def _bending_blocks(ei: Array, length: Array, phi: Array, rho_a: Array,
                    rho_i: Array) -> tuple[Array, Array]:
    """Planar 4x4 stiffness and mass for DOFs (v1, t1, v2, t2) with t = dv/dx."""
    n = len(length)
    L, p = length, phi
    k = np.empty((n, 4, 4))
    c = ei / ((1.0 + p) * L ** 3)
    k[:, 0] = np.stack([12.0 + 0 * L, 6 * L, -12.0 + 0 * L, 6 * L], axis=1)
    k[:, 1] = np.stack([6 * L, (4 + p) * L ** 2, -6 * L, (2 - p) * L ** 2], axis=1)
    k[:, 2] = -k[:, 0]
    k[:, 3] = np.stack([6 * L, (2 - p) * L ** 2, -6 * L, (4 + p) * L ** 2], axis=1)
    k *= c[:, None, None]
    # translational inertia (with shear parameter)
    m11 = 13 / 35 + 7 * p / 10 + p ** 2 / 3
    m12 = (11 / 210 + 11 * p / 120 + p ** 2 / 24) * L
    m13 = 9 / 70 + 3 * p / 10 + p ** 2 / 6
    m14 = -(13 / 420 + 3 * p / 40 + p ** 2 / 24) * L
    m22 = (1 / 105 + p / 60 + p ** 2 / 120) * L ** 2
    m24 = -(1 / 140 + p / 60 + p ** 2 / 120) * L ** 2
    mt = np.stack([np.stack([m11, m12, m13, m14], 1), np.stack([m12, m22, -m14, m24], 1),
                   np.stack([m13, -m14, m11, -m12], 1), np.stack([m14, m24, -m12, m22], 1)], 1)
    mt *= (rho_a * L / (1 + p) ** 2)[:, None, None]
    # rotary inertia
    r11 = 6 / 5 + 0 * p
    r12 = (1 / 10 - p / 2) * L
    r22 = (2 / 15 + p / 6 + p ** 2 / 3) * L ** 2
    r24 = (-1 / 30 - p / 6 + p ** 2 / 6) * L ** 2
    mr = np.stack([np.stack([r11, r12, -r11, r12], 1), np.stack([r12, r22, -r12, r24], 1),
                   np.stack([-r11, -r12, r11, -r12], 1), np.stack([r12, r24, -r12, r22], 1)], 1)
    mr *= (rho_i / ((1 + p) ** 2 * L))[:, None, None]
    return k, mt + mr


def local_matrices(length: npt.ArrayLike, youngs: npt.ArrayLike, shear: npt.ArrayLike,
                   density: npt.ArrayLike, area: npt.ArrayLike, iy: npt.ArrayLike,
                   iz: npt.ArrayLike, torsion: npt.ArrayLike, shear_factor: npt.ArrayLike,
                   added_mass: npt.ArrayLike = 0.0) -> tuple[Array, Array]:
    """
    Return local stiffness and consistent mass matrices of Timoshenko beam elements.

    Parameters
    ----------
    length : (n,) array_like
        Element lengths [m].
    youngs, shear : array_like
        Young's and shear modulus [Pa].
    density : array_like
        Material density [kg/m^3].
    area, iy, iz, torsion : array_like
        Section area [m^2], second moments about local y and z, torsion constant [m^4].
    shear_factor : array_like
        Timoshenko shear factor kappa [-] (shear area = kappa A).
    added_mass : array_like
        Non-structural mass per length [kg/m] (translational inertia only).

    Returns
    -------
    k, m : (n, 12, 12) ndarray
        Stiffness [N/m, N, N m/rad] and mass [kg, kg m, kg m^2] in local coordinates.
    """
    length = np.atleast_1d(np.asarray(length, dtype=float))
    n = len(length)
    b = [np.broadcast_to(np.asarray(v, dtype=float), (n,)) for v in
         (youngs, shear, density, area, iy, iz, torsion, shear_factor, added_mass)]
    e, g, rho, a, i_y, i_z, j, kappa, nsm = b
    if np.any(length <= 0.0):
        raise ConfigError(f'beam element length must be > 0, got min {length.min()!r} m')
    k = np.zeros((n, 12, 12))
    m = np.zeros((n, 12, 12))
    bar = np.array([[1.0, -1.0], [-1.0, 1.0]])
    cons = np.array([[2.0, 1.0], [1.0, 2.0]]) / 6.0
    ax, tor = np.ix_([0, 6], [0, 6]), np.ix_([3, 9], [3, 9])
    k[(slice(None),) + ax] = (e * a / length)[:, None, None] * bar
    m[(slice(None),) + ax] = ((rho * a + nsm) * length)[:, None, None] * cons
    k[(slice(None),) + tor] = (g * j / length)[:, None, None] * bar
    m[(slice(None),) + tor] = (rho * (i_y + i_z) * length)[:, None, None] * cons
    rho_a = rho * a + nsm
    # bending in x-y (v = uy, theta_z = dv/dx)
    phi_y = 12.0 * e * i_z / (kappa * g * a * length ** 2)
    kb, mb = _bending_blocks(e * i_z, length, phi_y, rho_a, rho * i_z)
    idx = np.ix_([1, 5, 7, 11], [1, 5, 7, 11])
    k[(slice(None),) + idx] = kb
    m[(slice(None),) + idx] = mb
    # bending in x-z (w = uz, theta_y = -dw/dx): same blocks with sign flips on rotations
    phi_z = 12.0 * e * i_y / (kappa * g * a * length ** 2)
    kb, mb = _bending_blocks(e * i_y, length, phi_z, rho_a, rho * i_y)
    s = np.array([1.0, -1.0, 1.0, -1.0])
    idx = np.ix_([2, 4, 8, 10], [2, 4, 8, 10])
    k[(slice(None),) + idx] = kb * np.outer(s, s)
    m[(slice(None),) + idx] = mb * np.outer(s, s)
    return k, m


def local_axes(start: npt.ArrayLike, end: npt.ArrayLike,
               orientation: npt.ArrayLike) -> tuple[Array, Array]:
    """
    Return element lengths and local axes.

    Parameters
    ----------
    start, end : (n, 3) array_like
        Node positions [m].
    orientation : (n, 3) or (3,) array_like
        Vector in the local x-y plane, roughly along local y (need not be unit length).

    Returns
    -------
    length : (n,) ndarray
        Element lengths [m].
    axes : (n, 3, 3) ndarray
        Rows are the local x, y, z unit vectors in global coordinates.
    """
    start, end = np.atleast_2d(start), np.atleast_2d(end)
    d = end - start
    length = np.linalg.norm(d, axis=1)
    ex = d / length[:, None]
    v = np.broadcast_to(np.asarray(orientation, dtype=float), ex.shape)
    ez = np.cross(ex, v)
    nz = np.linalg.norm(ez, axis=1)
    if np.any(nz < 1e-9 * np.linalg.norm(v, axis=1)):
        bad = int(np.argmin(nz))
        raise ConfigError(f'beam element {bad}: orientation vector {v[bad].tolist()} is '
                          f'parallel to the element axis {ex[bad].tolist()}')
    ez /= nz[:, None]
    ey = np.cross(ez, ex)
    return length, np.stack([ex, ey, ez], axis=1)


def to_global(k_local: Array, axes: Array) -> Array:
    """
    Rotate element matrices into global coordinates: ``T^T k T`` with T = diag(R, R, R, R).

    Parameters
    ----------
    k_local : (n, 12, 12) ndarray
        Element matrices in local coordinates.
    axes : (n, 3, 3) ndarray
        Rows = local axes in global coordinates (R maps global to local components).
    """
    n = len(axes)
    blocks = k_local.reshape(n, 4, 3, 4, 3)
    # the same 3x3 rotation acts on each of the 4x4 blocks: R^T k_ab R
    out = np.einsum('nji,najbk,nkl->naibl', axes, blocks, axes, optimize=True)
    return out.reshape(n, 12, 12)
