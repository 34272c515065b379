"""
Write an FE model as matrix files of another FE code, with the description that reads it back.

Every stiffness group goes to its own file (so the cause analysis of the read-back model sees
the same groups), the DOF map and node coordinates beside them, and each named point becomes a
node, or a node and an offset where the point is rigidly attached to one (the platform points
of the project's model). Numbers are written with 17 significant digits, so a round trip
reproduces the doubles exactly. Units are SI (``length_unit: 1``, ``mass_unit: 1``).
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import Mapping

import numpy as np
import numpy.typing as npt
import scipy.sparse as sp
import yaml

from pentapod_sim.errors import ModelFileError
from pentapod_sim.fe.imported import abaqus, matrix_market, nodes
from pentapod_sim.fe.model import FEModel

#: Formats the exporter writes (the MAPDL .full format is binary and read only).
WRITTEN_FORMATS = ('matrix-market', 'abaqus')


class _NodeDofs:
    """DOF indices of each node of a DOF map, found by bisection (sorted once)."""

    def __init__(self, nodes: npt.NDArray[np.int64]) -> None:
        self.order = np.argsort(nodes, kind='stable')
        self.sorted = nodes[self.order]

    def __call__(self, node: int) -> npt.NDArray[np.int64]:
        lo, hi = np.searchsorted(self.sorted, [node, node + 1])
        return self.order[lo:hi]


def point_node(fe: FEModel, name: str, lookup: _NodeDofs | None = None
               ) -> tuple[int, npt.NDArray[np.float64]]:
    """
    Node and offset [m] of a named point that is a node or rigidly attached to one.

    Raises
    ------
    ModelFileError
        If the point's observation matrix is not ``[I, -[r]x; 0, I]`` on one node's DOFs.
    """
    if fe.dofs is None:
        raise ModelFileError('the FE model has no DOF map (FEModel.dofs); cannot export it')
    lookup = lookup or _NodeDofs(fe.dofs.nodes)
    T = sp.csr_matrix(fe.points[name])
    first = T.getrow(0)
    candidates = [int(fe.dofs.nodes[j]) for j, v in zip(first.indices, first.data)
                  if v == 1.0 and fe.dofs.components[j] == 0]
    for node in candidates:
        cols = {int(fe.dofs.components[j]): int(j) for j in lookup(node)}
        if not {0, 1, 2} <= set(cols):
            continue
        rotations = {3, 4, 5} <= set(cols)
        r = (np.array([T[1, cols[5]], T[2, cols[3]], T[0, cols[4]]]) if rotations
             else np.zeros(3))
        lever = -np.array([[0, -r[2], r[1]], [r[2], 0, -r[0]], [-r[1], r[0], 0]])
        entries = [(c, cols[c], 1.0) for c in range(6) if c in cols]
        entries += [(c, cols[3 + k], lever[c, k]) for c in range(3)
                    for k in range(3 if rotations else 0) if lever[c, k] != 0.0]
        rows, columns, values = zip(*entries)
        rebuilt = sp.csr_matrix((values, (rows, columns)), shape=T.shape)
        if (rebuilt != T).nnz == 0:
            return node, r
    raise ModelFileError(f'point {name!r} is not a node, nor a rigid offset of one')


def _description(fe: FEModel, fmt: str, files: Mapping[str, str | dict[str, str]]
                 ) -> dict[str, object]:
    points: dict[str, dict[str, int | list[float]]] = {}
    assert fe.dofs is not None
    lookup = _NodeDofs(fe.dofs.nodes)
    for name in fe.points:
        node, offset = point_node(fe, name, lookup)
        points[name] = {'node': node}
        if np.any(offset != 0.0):
            points[name]['offset'] = [float(v) for v in offset]
    text: dict[str, object] = {'format': fmt, 'length_unit': 1.0, 'mass_unit': 1.0, **files,
                               'points': points}
    if np.all(np.isfinite(fe.strut_frames)):
        text['strut_frames'] = np.asarray(fe.strut_frames, dtype=float).tolist()
    text['pose'] = [float(v) for v in fe.pose]
    return text


def export_fe_model(fe: FEModel, folder: str | os.PathLike[str], fmt: str = 'matrix-market',
                    stem: str = 'machine') -> Path:
    """
    Write the model's M, K per stiffness group, DOF map, nodes and description.

    Parameters
    ----------
    fe : FEModel
        A model with a DOF map (``fe.dofs``), e.g. :func:`pentapod_sim.fe.assembly.build_model`.
    folder : path
        Output folder (created).
    fmt : {'matrix-market', 'abaqus'}
        Matrix file format.
    stem : str
        File name stem.

    Returns
    -------
    Path
        The description ``<stem>.yaml``, for :func:`pentapod_sim.fe.imported.load_fe_model`.
    """
    if fmt not in WRITTEN_FORMATS:
        raise ModelFileError(f'cannot write format {fmt!r}; written: {", ".join(WRITTEN_FORMATS)}')
    if fe.dofs is None:
        raise ModelFileError('the FE model has no DOF map (FEModel.dofs); cannot export it')
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    labels = np.column_stack([fe.dofs.nodes, fe.dofs.components])

    def write(name: str, matrix: sp.spmatrix, title: str) -> str:
        path = folder / f'{stem}_{name}.mtx'    # both formats' usual suffix
        if fmt == 'matrix-market':
            matrix_market.write_matrix(path, matrix, title)
        else:
            abaqus.write(path, matrix, labels, title)
        return path.name
    files: dict[str, str | dict[str, str]] = {
        'mass': write('mass', fe.M, 'mass [kg, kg m, kg m^2]')}
    files['stiffness'] = {g: write(f'stiffness_{g}', k, f'stiffness of {g} [N/m, N, N m/rad]')
                          for g, k in fe.stiffness_groups.items()}
    if fmt == 'matrix-market':
        files['dofs'] = matrix_market.write_dof_map(folder / f'{stem}_dofs.csv', labels).name
        files['nodes'] = nodes.write_csv(folder / f'{stem}_nodes.csv', fe.dofs.labels,
                                         fe.dofs.xyz).name
    else:
        files['nodes'] = abaqus.write_nodes(folder / f'{stem}_nodes.inp', fe.dofs.labels,
                                            fe.dofs.xyz).name
    path = folder / f'{stem}.yaml'
    header = (f'# FE model description written by pentapod_sim.fe.imported.export ({fmt}); '
              f'{fe.n_dof} DOF, SI units\n')
    path.write_text(header + yaml.safe_dump(_description(fe, fmt, files), sort_keys=False),
                    encoding='utf-8')
    return path
