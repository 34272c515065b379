"""
The assembled finite-element model: the data every later stage works on.

This module fixes the contract between the model builder (``pentapod_sim.fe.assembly``) and its
users (modal analysis, cause analysis, ports and reduction). It holds data only.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt
import scipy.sparse as sp

#: Order of the six rows of a point's observation matrix.
POINT_COMPONENTS = ('ux', 'uy', 'uz', 'rx', 'ry', 'rz')
#: Component number of a DOF that is none of the six (an FE code's internal or extra DOF).
OTHER_COMPONENT = -1


@dataclass(frozen=True)
class DofMap:
    """
    Which node and component every DOF of the matrices belongs to, and where the nodes are.

    Attributes
    ----------
    nodes : (n,) ndarray of int
        Node label of each DOF (row/column of K and M).
    components : (n,) ndarray of int
        Component of each DOF: 0..5 for ``POINT_COMPONENTS`` (ux, uy, uz, rx, ry, rz in the
        global frame), ``OTHER_COMPONENT`` for any other DOF.
    labels : (N,) ndarray of int
        Labels of the nodes whose coordinates are known.
    xyz : (N, 3) ndarray
        Their global coordinates [m].
    """

    nodes: npt.NDArray[np.int64]
    components: npt.NDArray[np.int64]
    labels: npt.NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, np.int64))
    xyz: npt.NDArray[np.float64] = field(default_factory=lambda: np.zeros((0, 3)))


@dataclass(frozen=True)
class FEModel:
    """
    Sparse FE model of the machine at one pose, after constraint elimination.

    Attributes
    ----------
    K : (n, n) scipy.sparse.csr_matrix
        Stiffness matrix [N/m, N/rad, N m/rad]; symmetric positive semi-definite.
    M : (n, n) scipy.sparse.csr_matrix
        Mass matrix [kg, kg m, kg m^2]; symmetric positive definite.
    stiffness_groups : dict of str to (n, n) csr_matrix
        Contribution of each subassembly's elasticity; ``K == sum(stiffness_groups.values())``.
        Names: 'frame', 'installation', 'struts', 'feed_drives', 'bp_joints', 'wp_joints';
        the plate frame (``frame.model: shells``) adds 'frame_walls'.
    points : dict of str to (6, n) csr_matrix
        Observation matrix of each named physical point: ``T @ u`` gives its displacements
        ux, uy, uz [m] and rotations rx, ry, rz [rad] in the global frame; ``T.T @ f`` maps a
        force/moment vector [N, N m] at the point to generalised forces.
    point_positions : dict of str to (3,) ndarray
        Global position of each named point [m].
    strut_frames : (5, 3, 3) ndarray
        Per strut (index 0 = strut 1) the unit vectors e1 (strut axis, from the BP joint to
        the WP joint), e2 and e3 (the cardan axes), as rows.
    mass_parts : dict of str to float
        Mass of each part that went into M [kg], for bookkeeping and checks.
    pose : (5,) ndarray
        Platform pose x, y, z [m], a, b [rad] the model was built for.
    meta : dict
        Free-form provenance (parameter file, its hash, mesh size, ...).
    dofs : DofMap or None
        Node and component of every DOF, and the node coordinates (what a matrix file
        exchanged with another FE code needs); None where the builder does not know them.
    frame_dofs : (f,) ndarray of int or None
        DOFs of the machine frame (its nodes, or the plate frame's interface points and modal
        coordinates), to tell local frame modes (:mod:`pentapod_sim.modes.causes`); None
        where unknown.
    """

    K: sp.csr_matrix
    M: sp.csr_matrix
    stiffness_groups: dict[str, sp.csr_matrix]
    points: dict[str, sp.csr_matrix]
    point_positions: dict[str, npt.NDArray[np.float64]]
    strut_frames: npt.NDArray[np.float64]
    mass_parts: dict[str, float] = field(default_factory=dict)
    pose: npt.NDArray[np.float64] = field(default_factory=lambda: np.zeros(5))
    meta: dict[str, Any] = field(default_factory=dict)
    dofs: DofMap | None = None
    frame_dofs: npt.NDArray[np.int64] | None = None

    @property
    def n_dof(self) -> int:
        """Number of free degrees of freedom."""
        return self.K.shape[0]

    def point(self, name: str) -> sp.csr_matrix:
        """
        Return the (6, n) observation matrix of a named point.

        Raises
        ------
        KeyError
            If no point of that name exists; the message lists the known names.
        """
        try:
            return self.points[name]
        except KeyError:
            known = ', '.join(sorted(self.points))
            raise KeyError(f'unknown point {name!r}; known points: {known}') from None
