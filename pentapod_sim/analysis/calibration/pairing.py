"""
Pairs of measured and model modes: MAC at the measured DOFs, gated by frequency, Hungarian.

The MAC of a measured shape ``psi`` (complex, at the response DOFs) and a model shape ``phi``
(real, the same DOFs) is ``|psi^H phi|^2 / ((psi^H psi) (phi^T phi))``. A pair is admissible if
its MAC reaches ``mac_min`` and the frequencies differ by at most ``frequency_tolerance``
(relative); among admissible pairs the assignment maximising the summed MAC is chosen
(``scipy.optimize.linear_sum_assignment``), so two measured modes never take the same model mode.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
import scipy.optimize

#: Default least MAC of a pair (the usual threshold of EMA correlation).
MAC_MIN = 0.8
#: Default largest relative frequency difference of a pair.
FREQUENCY_TOLERANCE = 0.1


def mac_matrix(measured: npt.ArrayLike, model: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """
    MAC of every measured shape with every model shape.

    Parameters
    ----------
    measured : (n_dof, p) array_like
        Measured shapes (complex allowed), one per column.
    model : (n_dof, m) array_like
        Model shapes at the same DOFs.

    Returns
    -------
    (p, m) ndarray
    """
    a = np.asarray(measured, dtype=complex)
    b = np.asarray(model, dtype=complex)
    cross = np.abs(a.conj().T @ b) ** 2
    norms = np.real(np.sum(a.conj() * a, axis=0))[:, None] * np.real(np.sum(b.conj() * b,
                                                                             axis=0))[None, :]
    with np.errstate(divide='ignore', invalid='ignore'):
        return np.where(norms > 0, cross / norms, 0.0)


@dataclass(frozen=True)
class Pairing:
    """Pairs (measured index, model index) with their MAC, and the full MAC matrix."""

    measured: npt.NDArray[np.int64]
    model: npt.NDArray[np.int64]
    mac: npt.NDArray[np.float64]
    mac_matrix: npt.NDArray[np.float64]


def pair_modes(measured_hz: npt.ArrayLike, measured_shapes: npt.ArrayLike,
               model_hz: npt.ArrayLike, model_shapes: npt.ArrayLike, mac_min: float = MAC_MIN,
               frequency_tolerance: float = FREQUENCY_TOLERANCE) -> Pairing:
    """
    Pair measured with model modes (module docstring).

    Parameters
    ----------
    measured_hz : (p,) array_like
        Measured natural frequencies [Hz].
    measured_shapes : (n_dof, p) array_like
        Measured shapes at the response DOFs.
    model_hz : (m,) array_like
        Model natural frequencies [Hz].
    model_shapes : (n_dof, m) array_like
        Model shapes at the same DOFs.
    mac_min : float
        Least MAC of a pair (0..1).
    frequency_tolerance : float
        Largest ``|f_measured / f_model - 1|`` of a pair.
    """
    if not 0.0 <= mac_min <= 1.0:
        raise ValueError(f'mac_min must lie in [0, 1], got {mac_min!r}')
    f_meas = np.asarray(measured_hz, dtype=float)
    f_model = np.asarray(model_hz, dtype=float)
    mac = mac_matrix(measured_shapes, model_shapes)
    gap = np.abs(f_meas[:, None] / f_model[None, :] - 1.0)
    admissible = (mac >= mac_min) & (gap <= frequency_tolerance)
    empty = np.zeros(0, dtype=np.int64)
    if not admissible.any():
        return Pairing(empty, empty, np.zeros(0), mac)
    cost = np.where(admissible, 1.0 - mac, 1e3)        # an inadmissible pair is never chosen
    rows, cols = scipy.optimize.linear_sum_assignment(cost)
    ok = admissible[rows, cols]
    rows, cols = rows[ok], cols[ok]
    order = np.argsort(cols)
    return Pairing(rows[order].astype(np.int64), cols[order].astype(np.int64),
                   mac[rows, cols][order], mac)
