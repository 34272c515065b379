"""
ANSYS MAPDL binary files through ansys-mapdl-reader: M and K from ``.full``, nodes from ``.cdb``.

The ``.full`` file is a Fortran binary record file; ansys-mapdl-reader (the PyAnsys reader of
MAPDL's binary files, an optional dependency: ``pip install ansys-mapdl-reader``) reads it.
``load_km`` gives the upper triangles of K and M over every DOF of the model with the
constrained DOFs' rows and columns zeroed; the DOF numbers are positions in the model's DOF
set, which for structural elements is UX, UY, UZ, ROTX, ROTY, ROTZ (0..5 here; others are
kept but never observed). Node coordinates come from an archive (``.cdb``, ``CDWRITE``) read by
the same library.
"""
from __future__ import annotations

import os
from typing import Any

import numpy as np
import numpy.typing as npt
import scipy.sparse as sp

from pentapod_sim.errors import ModelFileError
from pentapod_sim.fe.model import OTHER_COMPONENT

#: pip requirement of the optional reader (the version the tests ran with).
READER = 'ansys-mapdl-reader==0.56.0'


def _reader() -> Any:
    try:
        from ansys.mapdl import reader
    except ImportError as err:
        raise ModelFileError(f'reading MAPDL files needs the optional package {READER} '
                             f'(pip install {READER!r}): {err}') from None
    return reader


def read(path: str | os.PathLike[str]) -> tuple[npt.NDArray[np.int64], sp.csr_matrix,
                                                sp.csr_matrix]:
    """
    DOF labels, K and M of a ``.full`` file.

    Returns
    -------
    labels : (n, 2) ndarray of int
        Node number and component (0..5 or ``OTHER_COMPONENT``) of each row.
    K, M : (n, n) csr_matrix
        Symmetric stiffness and mass in the model's units; constrained DOFs have empty rows.
    """
    reader = _reader()
    try:
        full = reader.read_binary(os.fspath(path))
        dof_ref, k, m = full.load_km(as_sparse=True, sort=True)
    except (OSError, ValueError, RuntimeError, AttributeError, KeyError) as err:
        raise ModelFileError(f'{path}: not a readable MAPDL .full file: {err}') from None
    if not hasattr(full, 'load_km'):
        raise ModelFileError(f'{path}: a MAPDL {type(full).__name__}, not a .full file')
    labels = np.asarray(dof_ref, dtype=np.int64)
    labels[:, 1] = np.where(labels[:, 1] <= 5, labels[:, 1], OTHER_COMPONENT)

    def symmetric(upper: sp.spmatrix) -> sp.csr_matrix:
        upper = sp.triu(sp.csr_matrix(upper, dtype=float))
        return (upper + sp.triu(upper, 1).T).tocsr()
    return labels, symmetric(k), symmetric(m)


def read_nodes(path: str | os.PathLike[str]) -> tuple[npt.NDArray[np.int64],
                                                      npt.NDArray[np.float64]]:
    """Node numbers (N,) and coordinates (N, 3) of a MAPDL archive (``.cdb``)."""
    reader = _reader()
    try:
        archive = reader.Archive(os.fspath(path), parse_vtk=False)
    except (OSError, ValueError, RuntimeError) as err:
        raise ModelFileError(f'{path}: not a readable MAPDL archive: {err}') from None
    return np.asarray(archive.nnum, dtype=np.int64), np.asarray(archive.nodes, dtype=float)[:, :3]
