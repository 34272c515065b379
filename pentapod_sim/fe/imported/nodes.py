"""
Node coordinates of an imported FE model: CSV, Abaqus ``*NODE`` blocks or a MAPDL archive.

CSV: header ``node,x,y,z``, one line per node, coordinates in the model's length unit.
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import numpy.typing as npt

from pentapod_sim.errors import ModelFileError
from pentapod_sim.fe.imported import abaqus, mapdl_full

NODE_COLUMNS = ('node', 'x', 'y', 'z')


def read_csv(path: str | os.PathLike[str]) -> tuple[npt.NDArray[np.int64],
                                                    npt.NDArray[np.float64]]:
    """Labels (N,) and coordinates (N, 3) of a node CSV."""
    try:
        with open(path, encoding='utf-8') as stream:
            header = stream.readline().strip().replace(' ', '').split(',')
        if tuple(header) != NODE_COLUMNS:
            raise ModelFileError(f'{path}: expected the header {",".join(NODE_COLUMNS)}, got '
                                 f'{",".join(header)!r}')
        data = np.loadtxt(path, delimiter=',', skiprows=1, ndmin=2, dtype=float)
    except OSError as err:
        raise ModelFileError(f'{path}: cannot read: {err}') from None
    except ValueError as err:
        raise ModelFileError(f'{path}: bad node line: {err}') from None
    if data.shape[1] != 4:
        raise ModelFileError(f'{path}: expected 4 columns node,x,y,z, got {data.shape[1]}')
    return data[:, 0].astype(np.int64), data[:, 1:4]


def write_csv(path: str | os.PathLike[str], labels: npt.ArrayLike, xyz: npt.ArrayLike) -> Path:
    """Write a node CSV (exact doubles)."""
    with open(path, 'w', encoding='ascii') as stream:
        stream.write(','.join(NODE_COLUMNS) + '\n')
        np.savetxt(stream, np.column_stack([labels, xyz]), fmt=['%d'] + ['%.17g'] * 3,
                   delimiter=',')
    return Path(path)


def read_nodes(path: str | os.PathLike[str]) -> tuple[npt.NDArray[np.int64],
                                                      npt.NDArray[np.float64]]:
    """Node labels and coordinates by the file's suffix: .csv, .inp (Abaqus) or .cdb (MAPDL)."""
    suffix = Path(path).suffix.lower()
    if suffix == '.csv':
        labels, xyz = read_csv(path)
    elif suffix == '.inp':
        labels, xyz = abaqus.read_nodes(path)
    elif suffix in ('.cdb', '.dat'):
        labels, xyz = mapdl_full.read_nodes(path)
    else:
        raise ModelFileError(f'{path}: unknown node file type {suffix!r} (use .csv, .inp or '
                             '.cdb)')
    if len(np.unique(labels)) != len(labels):
        raise ModelFileError(f'{path}: node labels repeat')
    if not np.all(np.isfinite(xyz)):
        raise ModelFileError(f'{path}: node coordinates must be finite')
    return labels, xyz
