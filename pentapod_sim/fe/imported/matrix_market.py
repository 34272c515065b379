"""
Matrix Market files (``scipy.io.mmread`` / ``mmwrite``) and the DOF map CSV that goes with them.

A Matrix Market file holds a matrix without DOF labels, so the description names a CSV with
one line per matrix row (header ``node,component``): the node label and the component, 1..6
for ux, uy, uz, rx, ry, rz (the Abaqus and Nastran numbering) or the names themselves; any
other number marks a DOF that is none of the six (kept in the matrices, never observed).
"""
from __future__ import annotations

import csv
import os
from pathlib import Path

import numpy as np
import numpy.typing as npt
import scipy.io
import scipy.sparse as sp

from pentapod_sim.errors import ModelFileError
from pentapod_sim.fe.model import OTHER_COMPONENT, POINT_COMPONENTS

DOF_COLUMNS = ('node', 'component')


def component_number(text: str, where: str) -> int:
    """0..5 for a component 1..6 or ux..rz, ``OTHER_COMPONENT`` for other numbers."""
    text = text.strip().lower()
    if text in POINT_COMPONENTS:
        return POINT_COMPONENTS.index(text)
    try:
        number = int(text)
    except ValueError:
        raise ModelFileError(f'{where}: component {text!r} is neither 1..6 nor one of '
                             f'{", ".join(POINT_COMPONENTS)}') from None
    return number - 1 if 1 <= number <= 6 else OTHER_COMPONENT


def read_matrix(path: str | os.PathLike[str]) -> sp.csr_matrix:
    """A square sparse matrix from a Matrix Market file (symmetric storage expanded)."""
    try:
        matrix = scipy.io.mmread(path)
    except (OSError, ValueError, TypeError) as err:
        raise ModelFileError(f'{path}: not a readable Matrix Market file: {err}') from None
    matrix = sp.csr_matrix(matrix, dtype=float)
    if matrix.shape[0] != matrix.shape[1]:
        raise ModelFileError(f'{path}: matrix is {matrix.shape[0]} x {matrix.shape[1]}, '
                             'expected a square one')
    return matrix


def write_matrix(path: str | os.PathLike[str], matrix: sp.spmatrix, comment: str = '') -> Path:
    """Write a symmetric matrix (lower triangle, 17 significant digits: exact doubles)."""
    scipy.io.mmwrite(path, sp.coo_matrix(matrix), comment=comment, symmetry='symmetric',
                     precision=17)
    return Path(path)


def read_dof_map(path: str | os.PathLike[str]) -> npt.NDArray[np.int64]:
    """(n, 2) node label and component (0..5 or OTHER_COMPONENT) of each matrix row."""
    try:
        with open(path, newline='', encoding='utf-8') as stream:
            reader = csv.DictReader(stream)
            if tuple(reader.fieldnames or ()) [:2] != DOF_COLUMNS:
                raise ModelFileError(f'{path}: expected the header {",".join(DOF_COLUMNS)}, '
                                     f'got {",".join(reader.fieldnames or ())!r}')
            rows = [(int(r['node']), component_number(r['component'], f'{path}:{k + 2}'))
                    for k, r in enumerate(reader)]
    except (OSError, UnicodeDecodeError) as err:
        raise ModelFileError(f'{path}: cannot read the DOF map: {err}') from None
    except (TypeError, ValueError) as err:
        raise ModelFileError(f'{path}: bad DOF map line: {err}') from None
    return np.array(rows, dtype=np.int64).reshape(-1, 2)


def write_dof_map(path: str | os.PathLike[str], labels: npt.ArrayLike) -> Path:
    """Write the DOF map CSV of (n, 2) node labels and components 0..5."""
    labels = np.asarray(labels, dtype=np.int64)
    with open(path, 'w', newline='', encoding='utf-8') as stream:
        writer = csv.writer(stream)
        writer.writerow(DOF_COLUMNS)
        writer.writerows([int(n), int(c) + 1 if c >= 0 else 0] for n, c in labels)
    return Path(path)


def read(path: str | os.PathLike[str], dof_map: npt.NDArray[np.int64]
         ) -> tuple[npt.NDArray[np.int64], sp.csr_matrix]:
    """DOF labels (n, 2) and matrix of one Matrix Market file, checked against the DOF map."""
    matrix = read_matrix(path)
    if matrix.shape[0] != len(dof_map):
        raise ModelFileError(f'{path}: {matrix.shape[0]} rows, but the DOF map has '
                             f'{len(dof_map)}')
    return dof_map, matrix
