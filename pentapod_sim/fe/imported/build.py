"""
An :class:`~pentapod_sim.fe.model.FEModel` from an FE model description and its matrix files.

Steps: read each matrix with its DOF labels (one stiffness file per element group, summed to
K), bring them onto one DOF set, convert to SI, drop the DOFs that carry nothing (constrained
DOFs of a ``.full`` file, unused DOFs) or a penalty diagonal (boundary conditions written as
stiff springs), check symmetry, and build the named points' observation matrices from their
nodes (a point rigidly attached to a node at an offset: ``u_p = u_n + theta_n x r``).

Units: with ``L`` metres per model length unit and ``m`` kilograms per model mass unit, a
translation DOF is ``L`` metres and a rotation one radian, so ``K_SI = m L^2 S^-1 K S^-1`` with
``S = diag(L`` for translations, ``1`` otherwise) (the same for M): e.g. mm-t-s models give
N/m = 1e3 N/mm and kg = 1e-3 t.
"""
from __future__ import annotations

import hashlib
import logging
import os
from pathlib import Path
import time

import numpy as np
import numpy.typing as npt
import scipy.sparse as sp

from pentapod_sim.errors import ModelFileError
from pentapod_sim.fe.geometry import strut_frames
from pentapod_sim.fe.imported import abaqus, mapdl_full, matrix_market
from pentapod_sim.fe.imported.description import FEDescription, load_description
from pentapod_sim.fe.imported.nodes import read_nodes
from pentapod_sim.fe.model import DofMap, FEModel, POINT_COMPONENTS

LOG = logging.getLogger(__name__)
Labels = npt.NDArray[np.int64]
#: Largest relative asymmetry ``max|A - A^T| / max|A|`` accepted (text files round).
SYMMETRY_TOLERANCE = 1e-9


def _read_matrices(desc: FEDescription) -> tuple[dict[str, tuple[Labels, sp.csr_matrix]],
                                                 tuple[Labels, sp.csr_matrix]]:
    """Stiffness per group and mass, each with its own DOF labels, in model units."""
    if desc.format == 'mapdl-full':
        labels, k, m = mapdl_full.read(desc.path(str(desc.matrices)))
        return {'structure': (labels, k)}, (labels, m)
    if desc.format == 'abaqus':
        def reader(name: str) -> tuple[Labels, sp.csr_matrix]:
            return abaqus.read(desc.path(name))
    else:
        dof_map = matrix_market.read_dof_map(desc.path(str(desc.dofs)))

        def reader(name: str) -> tuple[Labels, sp.csr_matrix]:
            return matrix_market.read(desc.path(name), dof_map)
    groups = {}
    for group, name in desc.stiffness_files.items():
        LOG.info('reading stiffness %s (%s)', name, group)
        groups[group] = reader(name)
    LOG.info('reading mass %s', desc.mass)
    return groups, reader(str(desc.mass))


def _on_dofs(labels: Labels, matrix: sp.csr_matrix, dofs: Labels) -> sp.csr_matrix:
    """Scatter a matrix over its own DOF labels onto the sorted DOF set ``dofs``."""
    if len(labels) == len(dofs) and np.array_equal(labels, dofs):
        return matrix
    where = _positions(dofs, labels)
    coo = matrix.tocoo()
    return sp.csr_matrix((coo.data, (where[coo.row], where[coo.col])), shape=(len(dofs),) * 2)


def _keys(labels: Labels) -> npt.NDArray[np.int64]:
    """One sortable integer per (node, component); component -1..5 fits in 3 bits."""
    return labels[:, 0] * 8 + (labels[:, 1] + 1)


def _positions(dofs: Labels, wanted: Labels) -> npt.NDArray[np.int64]:
    """Index into the (node, component)-sorted ``dofs`` of every row of ``wanted``."""
    return np.searchsorted(_keys(dofs), _keys(wanted)).astype(np.int64)


def _check_symmetric(matrix: sp.csr_matrix, what: str) -> None:
    scale = abs(matrix).max() if matrix.nnz else 0.0
    if scale == 0:
        raise ModelFileError(f'{what}: the matrix is all zero')
    asym = abs(matrix - matrix.T).max() / scale
    if asym > SYMMETRY_TOLERANCE:
        raise ModelFileError(f'{what}: not symmetric (max |A - A^T| / max |A| = {asym:.2e} > '
                             f'{SYMMETRY_TOLERANCE:g})')


def _unit_scale(components: npt.NDArray[np.int64], desc: FEDescription) -> sp.dia_matrix:
    """``m L^2 S^-1`` split as one diagonal applied on both sides: ``sqrt(m) L / S``."""
    length = np.where((components >= 0) & (components < 3), desc.length_unit, 1.0)
    return sp.diags(np.sqrt(desc.mass_unit) * desc.length_unit / length)


def _kept_dofs(k: sp.csr_matrix, m: sp.csr_matrix, desc: FEDescription
               ) -> npt.NDArray[np.bool_]:
    """DOFs that carry stiffness or mass and no penalty diagonal."""
    empty = (np.diff(k.indptr) == 0) & (np.diff(m.indptr) == 0)
    empty |= (abs(k).sum(axis=1).A1 == 0) & (abs(m).sum(axis=1).A1 == 0)
    penalty = k.diagonal() >= desc.penalty_diagonal
    if penalty.any():
        LOG.info('%d DOFs with a stiffness diagonal >= %g (constrained) dropped',
                 penalty.sum(), desc.penalty_diagonal)
    return ~(empty | penalty)


def _point_matrix(name: str, node: int, offset: npt.NDArray[np.float64],
                  keys: npt.NDArray[np.int64]) -> sp.csr_matrix:
    """(6, n) observation matrix of a point at ``offset`` [m] from a node's DOFs.

    ``keys``: :func:`_keys` of the model's sorted DOF labels.
    """
    n = len(keys)
    wanted = node * 8 + np.arange(6) + 1
    where = np.searchsorted(keys, wanted)
    index = {c: int(i) for c, (i, k) in enumerate(zip(where, wanted)) if i < n and keys[i] == k}
    missing = [POINT_COMPONENTS[c] for c in range(3) if c not in index]
    if missing:
        raise ModelFileError(f'point {name!r}: node {node} has no DOF {", ".join(missing)} in '
                             'the matrices (constrained, or not a node of the model)')
    lever = np.array([[0.0, offset[2], -offset[1]], [-offset[2], 0.0, offset[0]],
                      [offset[1], -offset[0], 0.0]])             # u_p = u_n - [r]x theta
    entries: list[tuple[int, int, float]] = []          # (row, DOF, value)
    for c in range(3):
        entries.append((c, index[c], 1.0))
        for k in range(3):
            if lever[c, k] != 0.0:
                if 3 + k not in index:
                    raise ModelFileError(f'point {name!r}: an offset from node {node} needs its '
                                         f'rotation DOF {POINT_COMPONENTS[3 + k]}, which the '
                                         'matrices lack')
                entries.append((c, index[3 + k], float(lever[c, k])))
    entries += [(c, index[c], 1.0) for c in range(3, 6) if c in index]
    rows, cols, vals = zip(*entries)
    return sp.csr_matrix((vals, (rows, cols)), shape=(6, n))


def _frames(desc: FEDescription, positions: dict[str, npt.NDArray[np.float64]]
            ) -> npt.NDArray[np.float64]:
    """Strut frames: given, from the joint points (the project's convention), or NaN."""
    if desc.strut_frames is not None:
        return np.asarray(desc.strut_frames, dtype=float)
    ends = [(f'strut{i}_at_bp', f'strut{i}_wp_end') for i in range(1, 6)]
    if not all(a in positions and b in positions for a, b in ends):
        return np.full((5, 3, 3), np.nan)
    axis = np.array([positions[b] - positions[a] for a, b in ends])
    return strut_frames(axis / np.linalg.norm(axis, axis=1)[:, None])


def _digest(paths: list[Path]) -> str:
    digest = hashlib.sha256()
    for path in paths:
        with open(path, 'rb') as stream:
            while block := stream.read(1 << 24):
                digest.update(block)
    return digest.hexdigest()


def model_from_description(desc: FEDescription) -> FEModel:
    """The FE model a validated description names (see the module docstring)."""
    t0 = time.perf_counter()
    groups, (m_labels, m_raw) = _read_matrices(desc)
    dofs = np.unique(np.concatenate([m_labels] + [lab for lab, _ in groups.values()]), axis=0)
    mass = _on_dofs(m_labels, m_raw, dofs)
    k_groups = {g: _on_dofs(lab, mat, dofs) for g, (lab, mat) in groups.items()}
    stiffness = sum(k_groups.values(), sp.csr_matrix(mass.shape)).tocsr()
    keep = _kept_dofs(stiffness, mass, desc)
    dofs = dofs[keep]
    scale = _unit_scale(dofs[:, 1], desc)

    def si(matrix: sp.csr_matrix) -> sp.csr_matrix:
        return (scale @ matrix[keep][:, keep] @ scale).tocsr()
    k_groups = {g: si(k) for g, k in k_groups.items()}
    stiffness, mass = si(stiffness), si(mass)
    _check_symmetric(stiffness, f'{desc.source}: stiffness')
    _check_symmetric(mass, f'{desc.source}: mass')
    labels, xyz = (read_nodes(desc.path(desc.nodes)) if desc.nodes is not None
                   else (np.zeros(0, np.int64), np.zeros((0, 3))))
    xyz = xyz * desc.length_unit
    where = {int(label): i for i, label in enumerate(labels)}
    points, positions = {}, {}
    keys = _keys(dofs)
    for name, point in desc.points.items():
        if point.node not in where:
            raise ModelFileError(f'{desc.source}: points.{name}.node = {point.node}: no such '
                                 f'node in {desc.nodes}')
        offset = np.asarray(point.offset, dtype=float) * desc.length_unit
        points[name] = _point_matrix(name, point.node, offset, keys)
        positions[name] = xyz[where[point.node]] + offset
    files = [Path(desc.source)] + [desc.path(f) for f in
                                   ([desc.matrices] if desc.matrices else
                                    [desc.mass, *desc.stiffness_files.values(), desc.dofs])
                                   if f is not None]
    meta = {'source': desc.source, 'format': desc.format, 'params_sha256': _digest(files),
            'units': {'length_m': desc.length_unit, 'mass_kg': desc.mass_unit},
            'dropped_dofs': int((~keep).sum()),
            'rigid_body_mass_kg': _rigid_mass(mass, dofs[:, 1]),
            'read_seconds': time.perf_counter() - t0}
    LOG.info('imported FE model %s: %d DOF (%d dropped), %d points in %.2f s', desc.source,
             len(dofs), meta['dropped_dofs'], len(points), meta['read_seconds'])
    return FEModel(K=stiffness, M=mass, stiffness_groups=k_groups, points=points,
                   point_positions=positions, strut_frames=_frames(desc, positions),
                   mass_parts={}, pose=np.asarray(desc.pose or np.zeros(5), dtype=float),
                   meta=meta, dofs=DofMap(dofs[:, 0], dofs[:, 1], labels, xyz))


def _rigid_mass(mass: sp.csr_matrix, components: npt.NDArray[np.int64]) -> list[float]:
    """Mass [kg] of a rigid translation along x, y, z (a check of the units)."""
    out = []
    for c in range(3):
        unit = (components == c).astype(float)
        out.append(float(unit @ (mass @ unit)))
    return out


def load_fe_model(path: str | os.PathLike[str]) -> FEModel:
    """
    Read an FE model description (YAML) and the files it names.

    Raises
    ------
    ConfigError
        For a bad description (file, key and value named).
    ModelFileError
        For unreadable, inconsistent or asymmetric matrix files, unknown nodes, missing DOFs.
    """
    return model_from_description(load_description(path))
