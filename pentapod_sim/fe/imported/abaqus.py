"""
Abaqus matrix text: ``*MATRIX OUTPUT, FORMAT=MATRIX INPUT`` (``.mtx``) and ``*NODE`` blocks.

Each data line of a ``.mtx`` file is ``row node, row DOF, column node, column DOF, value``;
``**`` starts a comment. Abaqus writes one triangle of a symmetric matrix; the reader accepts
either triangle or both (then it takes the entries as they are). DOF 1..6 are ux, uy, uz, rx,
ry, rz; other DOF numbers and Abaqus's internal nodes (negative labels, e.g. Lagrange
multipliers of constraints) stay in the matrices but are never observed. Node coordinates come
from the ``*NODE`` blocks of an input file (``label, x, y, z``).

The text is parsed with ``numpy.loadtxt`` (its C reader); the format is too simple to need a
library, and none reads it.
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import numpy.typing as npt
import scipy.sparse as sp

from pentapod_sim.errors import ModelFileError
from pentapod_sim.fe.model import OTHER_COMPONENT


def _table(path: str | os.PathLike[str], columns: int, what: str) -> npt.NDArray[np.float64]:
    try:
        data = np.loadtxt(path, delimiter=',', comments='*', ndmin=2, dtype=float)
    except (OSError, ValueError) as err:
        raise ModelFileError(f'{path}: not a readable {what}: {err}') from None
    if data.shape[1] != columns or data.shape[0] == 0:
        raise ModelFileError(f'{path}: expected lines of {columns} comma-separated numbers '
                             f'({what}), got {data.shape[1] if data.size else 0} per line')
    return data


def read(path: str | os.PathLike[str]) -> tuple[npt.NDArray[np.int64], sp.csr_matrix]:
    """
    DOF labels and matrix of a ``.mtx`` file in the MATRIX INPUT format.

    Returns
    -------
    labels : (n, 2) ndarray of int
        Node label and component (0..5, or ``OTHER_COMPONENT``) of each row, sorted by node
        label and DOF number.
    matrix : (n, n) csr_matrix
        Symmetric matrix in the file's units.
    """
    data = _table(path, 5, 'Abaqus matrix (node, DOF, node, DOF, value)')
    keys = data[:, :4].astype(np.int64)
    if not np.array_equal(keys, data[:, :4]):
        raise ModelFileError(f'{path}: node and DOF columns must hold integers')
    dof_number = np.concatenate([keys[:, 1], keys[:, 3]])
    if np.any(dof_number < 1):
        raise ModelFileError(f'{path}: DOF numbers start at 1, found {dof_number.min()}')
    if np.any(dof_number >= 64):
        raise ModelFileError(f'{path}: DOF number {dof_number.max()} (Abaqus has fewer than 64)')
    flat = np.concatenate([keys[:, 0] * 64 + keys[:, 1], keys[:, 2] * 64 + keys[:, 3]])
    codes, index = np.unique(flat, return_inverse=True)   # sorted by node, then DOF
    unique = np.column_stack([codes // 64, codes % 64])
    rows, cols = index[:len(data)], index[len(data):]
    n = len(unique)
    both = sp.coo_matrix((np.ones(len(data)), (np.minimum(rows, cols), np.maximum(rows, cols))),
                         shape=(n, n)).tocsr()
    one_triangle = both.max() <= 1 if both.nnz else True
    matrix = sp.coo_matrix((data[:, 4], (rows, cols)), shape=(n, n)).tocsr()
    if one_triangle:
        off = sp.triu(matrix, 1) + sp.tril(matrix, -1)
        matrix = (matrix + off.T).tocsr()
    components = np.where(unique[:, 1] <= 6, unique[:, 1] - 1, OTHER_COMPONENT)
    return np.column_stack([unique[:, 0], components]), matrix


def write(path: str | os.PathLike[str], matrix: sp.spmatrix, labels: npt.ArrayLike,
          title: str = '') -> Path:
    """
    Write a symmetric matrix as Abaqus MATRIX INPUT text (lower triangle, exact doubles).

    ``labels`` (n, 2): node label and component 0..5 of each row.
    """
    labels = np.asarray(labels, dtype=np.int64)
    if np.any(labels[:, 1] < 0):
        raise ModelFileError('Abaqus matrix export: every DOF needs a component 0..5')
    lower = sp.tril(sp.coo_matrix(matrix)).tocoo()
    order = np.lexsort((lower.col, lower.row))
    r, c = lower.row[order], lower.col[order]
    table = np.column_stack([labels[r, 0], labels[r, 1] + 1, labels[c, 0], labels[c, 1] + 1])
    with open(path, 'w', encoding='ascii') as stream:
        stream.write(f'** {title}\n' if title else '')
        np.savetxt(stream, np.column_stack([table, lower.data[order]]),
                   fmt=['%d', '%d', '%d', '%d', '%.17g'], delimiter=',')
    return Path(path)


def read_nodes(path: str | os.PathLike[str]) -> tuple[npt.NDArray[np.int64],
                                                      npt.NDArray[np.float64]]:
    """Labels (N,) and coordinates (N, 3) of the ``*NODE`` blocks of an Abaqus input file."""
    labels, xyz = [], []
    try:
        lines = Path(path).read_text(encoding='utf-8', errors='replace').splitlines()
    except OSError as err:
        raise ModelFileError(f'{path}: cannot read: {err}') from None
    inside = False
    for number, line in enumerate(lines, start=1):
        text = line.strip()
        if text.startswith('**') or not text:
            continue
        if text.startswith('*'):
            keyword = text[1:].split(',')[0].strip().lower()
            inside = keyword == 'node'
            continue
        if inside:
            fields = [f for f in text.split(',') if f.strip()]
            try:
                values = [float(f) for f in fields]
            except ValueError:
                raise ModelFileError(f'{path}:{number}: bad *NODE line {text!r}') from None
            if not 2 <= len(values) <= 4:
                raise ModelFileError(f'{path}:{number}: a *NODE line is label, x[, y[, z]]')
            labels.append(int(values[0]))
            xyz.append((values[1:] + [0.0, 0.0])[:3])
    if not labels:
        raise ModelFileError(f'{path}: no *NODE block')
    return np.array(labels, dtype=np.int64), np.array(xyz, dtype=float)


def write_nodes(path: str | os.PathLike[str], labels: npt.ArrayLike, xyz: npt.ArrayLike) -> Path:
    """Write node coordinates as one Abaqus ``*NODE`` block (exact doubles)."""
    with open(path, 'w', encoding='ascii') as stream:
        stream.write('*NODE\n')
        np.savetxt(stream, np.column_stack([labels, xyz]), fmt=['%d'] + ['%.17g'] * 3,
                   delimiter=', ')
    return Path(path)
