"""
Measured DOFs on the model: the observation row of each label over the FE DOFs.

``POINT:COMP`` takes row COMP of the point's (6, n) observation matrix, ``NODE:COMP`` the DOF
of that FE node (through the model's DOF map), a port name the port's vector
(:mod:`pentapod_sim.plant.ports`). The sign of the label multiplies the row. A response row
applied to displacements gives the measured displacement; the same row transposed is the load
vector of a unit force at a reference DOF, so ``rows_out Phi`` and ``rows_in Phi`` are the model's
mode shapes at the measured responses and references.
"""
from __future__ import annotations

from typing import Sequence

import numpy as np
import scipy.sparse as sp

from pentapod_sim.analysis.measured.labels import DofLabel
from pentapod_sim.errors import ConfigError
from pentapod_sim.fe.model import FEModel
from pentapod_sim.plant.ports import INPUT_NAMES, OUTPUT_NAMES, port


def label_row(fe: FEModel, label: DofLabel) -> sp.csr_matrix:
    """(1, n) observation row of a measured DOF on an FE model."""
    if label.is_port:
        if label.target not in INPUT_NAMES + OUTPUT_NAMES:
            raise ConfigError(f'measured DOF {label}: not a port, and no :COMP to read it as '
                              'a point or node')
        return sp.csr_matrix(port(fe.points, fe.strut_frames, label.target).vector)
    assert label.component is not None
    if label.target in fe.points:
        return label.sign * sp.csr_matrix(fe.point(label.target)[label.component])
    try:
        node = int(label.target)
    except ValueError:
        known = ', '.join(sorted(fe.points))
        raise ConfigError(f'measured DOF {label}: no point {label.target!r} (known points: '
                          f'{known}) and not a node number') from None
    if fe.dofs is None:
        raise ConfigError(f'measured DOF {label}: the model has no DOF map to find node {node}')
    hit = np.flatnonzero((fe.dofs.nodes == node) & (fe.dofs.components == label.component))
    if hit.size != 1:
        raise ConfigError(f'measured DOF {label}: the model has no such node DOF')
    return sp.csr_matrix(([label.sign], ([0], [hit[0]])), shape=(1, fe.n_dof))


def label_rows(fe: FEModel, labels: Sequence[DofLabel]) -> sp.csr_matrix:
    """(len(labels), n) observation rows of measured DOFs."""
    return sp.vstack([label_row(fe, label) for label in labels]).tocsr()
