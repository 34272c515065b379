"""
Rigid couplings (RBE2-like): slave nodes that follow a master node as a rigid body.

A slave's DOFs are ``u_s = u_m + theta_m x (x_s - x_m)``, ``theta_s = theta_m``; the slaves are
eliminated exactly by ``u = T q`` (``K_r = T^T K T``), which keeps the matrices as well
conditioned as the elements themselves (no penalty stiffness). Used for the rigid platform
of every model and for the plate frame's interface points. DOF order per node: ux, uy, uz,
rx, ry, rz; SI units.
"""
from __future__ import annotations

from typing import Mapping

import numpy as np
import numpy.typing as npt
import scipy.sparse as sp


def node_dofs(nodes: npt.ArrayLike) -> npt.NDArray[np.int64]:
    """(n,) node ids -> (n, 6) global DOF indices (6 per node)."""
    return 6 * np.asarray(nodes, dtype=np.int64)[:, None] + np.arange(6)


def rigid_elimination(xyz: npt.NDArray[np.float64], slaves: Mapping[int, int],
                      extra_dofs: int = 0) -> sp.csr_matrix:
    """
    Return T (n_full, n_free) with ``u = T q`` for nodes at ``xyz`` (6 DOFs each).

    Parameters
    ----------
    xyz : (N, 3) ndarray
        Node coordinates [m].
    slaves : mapping of slave node to master node
        A master must not itself be a slave.
    extra_dofs : int
        DOFs after the 6 N node DOFs (e.g. a superelement's modal coordinates); they are kept
        as they are, after the free node DOFs.
    """
    n_nodes = xyz.shape[0]
    is_slave = np.zeros(n_nodes, bool)
    is_slave[list(slaves)] = True
    free_nodes = np.flatnonzero(~is_slave)
    col_of_node = -np.ones(n_nodes, np.int64)
    col_of_node[free_nodes] = np.arange(free_nodes.size)
    n_kept = 6 * free_nodes.size
    rows = [node_dofs(free_nodes).ravel(), 6 * n_nodes + np.arange(extra_dofs)]
    cols = [np.arange(n_kept), n_kept + np.arange(extra_dofs)]
    vals = [np.ones(n_kept), np.ones(extra_dofs)]
    if slaves:
        s = np.fromiter(slaves.keys(), np.int64, len(slaves))
        m = np.fromiter(slaves.values(), np.int64, len(slaves))
        r = xyz[s] - xyz[m]
        blk = np.broadcast_to(np.eye(6), (s.size, 6, 6)).copy()
        # translation of a slave from the master's rotation: -[r]x theta
        blk[:, 0, 4], blk[:, 0, 5] = r[:, 2], -r[:, 1]
        blk[:, 1, 3], blk[:, 1, 5] = -r[:, 2], r[:, 0]
        blk[:, 2, 3], blk[:, 2, 4] = r[:, 1], -r[:, 0]
        e, ii, jj = np.nonzero(blk)
        rows.append(6 * s[e] + ii)
        cols.append(6 * col_of_node[m[e]] + jj)
        vals.append(blk[e, ii, jj])
    return sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                         shape=(6 * n_nodes + extra_dofs, n_kept + extra_dofs))
