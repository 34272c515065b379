"""
The modal layout of a discrete state matrix: its 2x2 blocks per mode, if it has that layout.

A modal plant's A_d (states ``[q; dq]``,
:meth:`pentapod_sim.plant.model.PlantModel.discrete_matrices`) couples mode i only through
the four diagonals of its m x m blocks; the stepping cores
(:class:`pentapod_sim.sim.stepping.DiscretePlant`, :mod:`pentapod_sim.sim.multirate`) then
advance it blockwise instead of with a dense product.
"""
from __future__ import annotations

import numpy as np
import numpy.typing as npt


def modal_blocks(a: npt.NDArray[np.float64]) -> npt.NDArray[np.float64] | None:
    """
    The 2x2 blocks of a modal A_d, or None if A_d is not of that layout.

    Parameters
    ----------
    a : (2m, 2m) ndarray
        State matrix with states ``[q_1..q_m, dq_1..dq_m]``.

    Returns
    -------
    (2, 2, m) ndarray or None
        ``P[i, j]`` = diagonal of block (i, j) of A_d, if A_d has no other non-zero entry.
    """
    n = a.shape[0]
    if n == 0 or n % 2:
        return None
    m = n // 2
    idx = np.arange(m)
    rows, cols = np.array([[idx, idx], [idx + m, idx + m]]), np.array([[idx, idx + m]] * 2)
    blocks = a[rows, cols]
    rebuilt = np.zeros_like(a)
    rebuilt[rows, cols] = blocks
    return blocks if np.array_equal(rebuilt, a) else None
