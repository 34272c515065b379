"""
Flat 6-node triangular shell element: plane-stress membrane plus Reissner-Mindlin plate.

Each triangle of a frame wall is flat. In its own frame (rows e1, e2 in the plane, e3 the
normal) the fields are the membrane displacements u, v, the deflection w, the rotations
theta_x, theta_y of the normal about e1 and e2, and the drilling rotation theta_z about e3, all
quadratic (Lagrange P2 on the three corner and three mid-side nodes). The energies:

* membrane ``t eps^T C eps`` with ``eps = (u_x, v_y, u_y + v_x)`` and C the plane-stress matrix;
* bending ``t^3 / 12 kappa^T C kappa`` with ``beta_x = theta_y``, ``beta_y = -theta_x`` and
  ``kappa = (beta_x,x, beta_y,y, beta_x,y + beta_y,x)``;
* transverse shear ``k_s G t (gamma_x^2 + gamma_y^2)``, ``gamma = grad w + beta``, k_s = 5/6;
* drilling: ``drill G t (theta_z - (v_x - u_y) / 2)^2``, a small penalty (``drill`` = 1e-3 by
  default) tying theta_z to the membrane rotation, so that a node inside a flat wall is not
  singular and perpendicular walls pass moments through their junction (Hughes-Brezzi);
* mass: ``rho t`` on u, v, w and the rotary inertia ``rho t^3 / 12`` on the three rotations.

scikit-fem integrates the scalar forms of these energies element by element (``ElementTriP2``
on a mesh in which every triangle has its own corners, so that every element matrix comes back
separately); this module rotates the element matrices to the global frame and sums them.
Quadratic Mindlin triangles lock only mildly: with walls of 10 mm and elements of 60 mm the
plate frequencies are within 1 % (test/test_shell_frame.py checks a plate and a box beam
against their closed forms).

Node DOF order: ux, uy, uz, rx, ry, rz in the global frame (as the beam elements). SI units.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
import scipy.sparse as sp
import skfem

from pentapod_sim.errors import ConfigError

Array = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]

#: Shear correction factor of a homogeneous plate [-].
SHEAR_FACTOR = 5.0 / 6.0
#: Drilling penalty relative to G t [-]: small enough not to stiffen the walls (the first
#: plate and box-beam frequencies move by < 0.1 % between 1e-4 and 1e-2), large enough to
#: keep K well conditioned.
DRILL = 1.0e-3
#: gmsh's 6-node triangle: mid-side node of each corner pair.
_MID = {(0, 1): 3, (1, 2): 4, (0, 2): 5}


@dataclass(frozen=True)
class ShellMesh:
    """
    Nodes and 6-node triangles of a shell structure.

    Attributes
    ----------
    xyz : (N, 3) ndarray
        Node coordinates [m].
    triangles : (E, 6) ndarray of int
        Node indices per triangle: three corners, then the mid-sides of corner pairs (0, 1),
        (1, 2), (2, 0) (gmsh's order).
    thickness : (E,) ndarray
        Wall thickness of each triangle [m].
    part : (E,) ndarray of int
        Index into ``part_names`` of each triangle.
    part_names : tuple of str
        Name of each part (e.g. 'column', 'wall').
    """

    xyz: Array
    triangles: IntArray
    thickness: Array
    part: IntArray
    part_names: tuple[str, ...]

    @property
    def n_nodes(self) -> int:
        """Number of nodes."""
        return int(self.xyz.shape[0])


def _element_frames(xyz: Array, corners: IntArray) -> Array:
    """(E, 3, 3) rows e1 (corner 0 -> 1), e2, e3 (normal) of each triangle."""
    p0, p1, p2 = (xyz[corners[:, k]] for k in range(3))
    e1 = p1 - p0
    e1 /= np.linalg.norm(e1, axis=1)[:, None]
    e3 = np.cross(p1 - p0, p2 - p0)
    norm = np.linalg.norm(e3, axis=1)
    if np.any(norm <= 0.0):
        raise ConfigError(f'{int(np.sum(norm <= 0.0))} degenerate shell triangles (zero area)')
    e3 /= norm[:, None]
    return np.stack([e1, np.cross(e3, e1), e3], axis=1)


@skfem.BilinearForm
def _dxx(u, v, w):  # type: ignore[no-untyped-def]
    return w.c * u.grad[0] * v.grad[0]


@skfem.BilinearForm
def _dyy(u, v, w):  # type: ignore[no-untyped-def]
    return w.c * u.grad[1] * v.grad[1]


@skfem.BilinearForm
def _dxy(u, v, w):  # type: ignore[no-untyped-def]
    # [i, j] = c dphi_i/dx dphi_j/dy (test function v = phi_i, trial u = phi_j)
    return w.c * u.grad[1] * v.grad[0]


@skfem.BilinearForm
def _nx(u, v, w):  # type: ignore[no-untyped-def]
    # [i, j] = c dphi_i/dx phi_j
    return w.c * u * v.grad[0]


@skfem.BilinearForm
def _ny(u, v, w):  # type: ignore[no-untyped-def]
    return w.c * u * v.grad[1]


@skfem.BilinearForm
def _n0(u, v, w):  # type: ignore[no-untyped-def]
    return w.c * u * v


def _local(form: skfem.BilinearForm, basis: skfem.Basis, weight: Array) -> Array:
    """(E, 6, 6) element matrices of a scalar form with an element-wise weight."""
    c = np.repeat(weight[:, None], basis.X.shape[-1], axis=1)
    # tolocal() gives [element, trial, test]; rows here are test functions
    return np.swapaxes(np.asarray(form.elemental(basis, c=c).tolocal()), 1, 2)


def tr(a: Array) -> Array:
    """Element-wise transpose of (E, n, n) matrices."""
    return np.swapaxes(a, 1, 2)


def _bases(xyz: Array, corners: IntArray, frames: Array
           ) -> tuple[skfem.Basis, skfem.Basis, IntArray]:
    """
    Bases on a mesh whose triangles share no node, in each triangle's own plane.

    Returns the full-order basis (order 4: mass and shear exact), the order-2 basis (gradient
    products exact) and, per element, the gmsh node position (0..5) of each of skfem's six
    local DOFs.
    """
    n_el = corners.shape[0]
    rel = xyz[corners] - xyz[corners[:, :1]]                       # (E, 3, 3)
    local = np.einsum('ekc,ejc->ekj', rel, frames[:, :2])           # (E, 3 corners, 2)
    mesh = skfem.MeshTri(local.reshape(-1, 2).T, np.arange(3 * n_el).reshape(n_el, 3).T)
    element = skfem.ElementTriP2()
    full = skfem.Basis(mesh, element, intorder=4)
    low = skfem.Basis(mesh, element, intorder=2)
    dofs = full.element_dofs                                       # (6, E)
    position = np.empty((6, n_el), dtype=np.int64)
    corner_of_vertex = np.arange(3 * n_el) % 3
    position[:3] = corner_of_vertex[mesh.t]                          # skfem keeps t's order
    for k in range(3):
        a, b = np.sort(corner_of_vertex[mesh.facets[:, mesh.t2f[k]]], axis=0)
        mid = np.full(n_el, -1)
        for (ca, cb), node in _MID.items():
            mid[(a == ca) & (b == cb)] = node
        position[3 + k] = mid
    vertex_dofs = dofs[:3] - np.arange(3 * n_el).reshape(n_el, 3).T
    if np.any(vertex_dofs != 0) or np.any(position < 0):
        raise RuntimeError('unexpected scikit-fem DOF numbering of ElementTriP2')
    return full, low, position


def shell_element_matrices(mesh: ShellMesh, youngs_modulus: float, poisson: float,
                           density: float, elements: npt.ArrayLike | None = None,
                           drill: float = DRILL) -> tuple[Array, Array, IntArray]:
    """
    Element stiffness and mass matrices in the global frame.

    Parameters
    ----------
    mesh : ShellMesh
        The shell mesh.
    youngs_modulus, poisson, density : float
        Isotropic material: E [Pa], Poisson's ratio [-], density [kg/m^3].
    elements : array_like of int, optional
        Triangles to compute (default all).
    drill : float
        Drilling penalty relative to G t [-].

    Returns
    -------
    k, m : (E, 36, 36) ndarray
        Element matrices for the DOFs (6 per node, nodes in ``dofs`` order) [N/m, kg, ...].
    dofs : (E, 36) ndarray of int
        Global DOF index (6 * node + component) of each element matrix row.
    """
    sel = np.arange(mesh.triangles.shape[0]) if elements is None else np.asarray(elements)
    tri = mesh.triangles[sel]
    t = mesh.thickness[sel]
    frames = _element_frames(mesh.xyz, tri[:, :3])
    full, low, position = _bases(mesh.xyz, tri[:, :3], frames)
    shear_mod = youngs_modulus / (2.0 * (1.0 + poisson))
    c_plane = youngs_modulus / (1.0 - poisson ** 2)
    g = (1.0 - poisson) / 2.0
    mem, bend = c_plane * t, c_plane * t ** 3 / 12.0
    shear, drl = SHEAR_FACTOR * shear_mod * t, drill * shear_mod * t
    dxx_m, dyy_m, dxy_m = (_local(f, low, mem) for f in (_dxx, _dyy, _dxy))
    dxx_b, dyy_b, dxy_b = (_local(f, low, bend) for f in (_dxx, _dyy, _dxy))
    dxx_s, dyy_s = _local(_dxx, low, shear), _local(_dyy, low, shear)
    nx_s, ny_s, n0_s = (_local(f, low, shear) for f in (_nx, _ny, _n0))
    dxx_d, dyy_d, dxy_d = (_local(f, low, drl) for f in (_dxx, _dyy, _dxy))
    nx_d, ny_d, n0_d = (_local(f, full, drl) for f in (_nx, _ny, _n0))
    n_el = tri.shape[0]
    # local fields 0..5 = u, v, w, theta_x, theta_y, theta_z, each 6 DOFs
    kl = np.zeros((n_el, 6, 6, 6, 6))
    kl[:, 0, 0] = dxx_m + g * dyy_m + dyy_d / 4.0
    kl[:, 1, 1] = dyy_m + g * dxx_m + dxx_d / 4.0
    kl[:, 0, 1] = poisson * dxy_m + g * tr(dxy_m) - tr(dxy_d) / 4.0
    kl[:, 1, 0] = tr(kl[:, 0, 1])
    # bending in beta_x = theta_y, beta_y = -theta_x
    kl[:, 4, 4] = dxx_b + g * dyy_b + n0_s
    kl[:, 3, 3] = dyy_b + g * dxx_b + n0_s
    kl[:, 4, 3] = -(poisson * dxy_b + g * tr(dxy_b))
    kl[:, 3, 4] = tr(kl[:, 4, 3])
    kl[:, 2, 2] = dxx_s + dyy_s
    kl[:, 2, 4] = nx_s
    kl[:, 4, 2] = tr(nx_s)
    kl[:, 2, 3] = -ny_s
    kl[:, 3, 2] = -tr(ny_s)
    kl[:, 5, 5] = n0_d
    kl[:, 5, 1] = -tr(nx_d) / 2.0
    kl[:, 1, 5] = tr(kl[:, 5, 1])
    kl[:, 5, 0] = tr(ny_d) / 2.0
    kl[:, 0, 5] = tr(kl[:, 5, 0])
    n0_t = _local(_n0, full, density * t)
    n0_r = _local(_n0, full, density * t ** 3 / 12.0)
    ml = np.zeros_like(kl)
    for f in range(3):
        ml[:, f, f] = n0_t
        ml[:, f + 3, f + 3] = n0_r
    # rotation to global DOFs: local field f at skfem DOF a = frame row (f % 3) . global
    # component block (f // 3) of the node at gmsh position position[a]
    rot5 = np.zeros((n_el, 6, 6, 6, 6))             # (E, field, dof a, node pos, component)
    ar = np.arange(6)
    for f in range(6):
        blk = 3 * (f // 3)
        for c in range(3):
            rot5[np.arange(n_el)[:, None], f, ar[None, :], position.T, blk + c] = \
                frames[:, f % 3, c][:, None]
    rot = rot5.reshape(n_el, 36, 36)
    k = np.einsum('eai,eab,ebj->eij', rot, kl.transpose(0, 1, 3, 2, 4).reshape(n_el, 36, 36),
                  rot, optimize=True)
    m = np.einsum('eai,eab,ebj->eij', rot, ml.transpose(0, 1, 3, 2, 4).reshape(n_el, 36, 36),
                  rot, optimize=True)
    dofs = (6 * tri[:, :, None] + np.arange(6)).reshape(n_el, 36)
    return k, m, dofs


def assemble(blocks: Array, dofs: IntArray, n_dof: int) -> sp.csr_matrix:
    """Sum element matrices (E, d, d) at DOF indices (E, d) into a CSR matrix."""
    d = dofs.shape[1]
    rows = np.repeat(dofs, d, axis=1).ravel()
    cols = np.tile(dofs, (1, d)).ravel()
    return sp.coo_matrix((blocks.ravel(), (rows, cols)), shape=(n_dof, n_dof)).tocsr()
