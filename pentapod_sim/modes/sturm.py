"""
Sturm counts: how many eigenvalues of ``K phi = omega^2 M phi`` lie below a shift.

The inertia of ``K - s M`` (its number of negative pivots, Sylvester's law) is that count; the
modal solver uses it to cut the spectrum into windows without missing or repeating a mode.
:func:`factor_at` gives both from one factorisation: the solves of a shift-invert window and
the count at its shift.

Two factorisations give the inertia: SuperLU in symmetric mode (scipy; every size, the only
one for the beam models of a few thousand DOF) and MKL PARDISO's LDL^T
(:mod:`pentapod_sim.modes.ldlt`; nested dissection, 4-5 times less fill and 5 times faster
on the plate frame's shell meshes), chosen by :func:`choose_backend`.
"""
from __future__ import annotations

from dataclasses import dataclass
import functools
import time
from typing import Union

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from pentapod_sim.errors import ModalError
from pentapod_sim.modes import ldlt

#: Factorisation backends of :func:`factorize_shifted`.
BACKENDS = ('auto', 'superlu', 'pardiso')
#: From this many DOF 'auto' uses PARDISO where it is installed. Below it SuperLU factorises
#: in a fraction of a second and PARDISO's set-up (ordering, threads) is not worth it.
PARDISO_MIN_DOF = 20_000


Factorisation = Union[spla.SuperLU, ldlt.PardisoLDLT]


@functools.lru_cache(maxsize=1)
def _pardiso_available() -> bool:
    return ldlt.available()


def choose_backend(n_dof: int, backend: str = 'auto') -> str:
    """
    The factorisation used for a problem of ``n_dof`` DOF: 'superlu' or 'pardiso'.

    'auto' takes PARDISO from :data:`PARDISO_MIN_DOF` DOF on if it is installed; asking for
    'pardiso' where it is not is a :class:`ModalError`.
    """
    if backend not in BACKENDS:
        raise ValueError(f'factorisation backend {backend!r} is not one of {", ".join(BACKENDS)}')
    if backend == 'superlu':
        return backend
    if backend == 'pardiso':
        if not _pardiso_available():
            raise ModalError("factorisation 'pardiso' needs MKL PARDISO (pip install "
                             "pypardiso, x86-64); 'superlu' needs nothing else")
        return backend
    return 'pardiso' if n_dof >= PARDISO_MIN_DOF and _pardiso_available() else 'superlu'


def factorize_shifted(K: sp.spmatrix, M: sp.spmatrix, sigma: float,
                      backend: str = 'auto') -> Factorisation:
    """
    Factorise ``K - sigma M`` so that its inertia can be read.

    SuperLU with ``SymmetricMode`` and ``diag_pivot_thresh=0`` pivots on the diagonal only, so
    ``P A P^T = L U`` with ``U = D L^T`` and ``diag(U)`` carries the inertia (Sylvester).
    PARDISO's LDL^T (:class:`pentapod_sim.modes.ldlt.PardisoLDLT`) reports it directly.

    Parameters
    ----------
    K, M : (n, n) sparse matrices
        Stiffness [N/m] and mass [kg] matrices (symmetric).
    sigma : float
        Shift [rad^2/s^2].
    backend : {'auto', 'superlu', 'pardiso'}
        Factorisation (:func:`choose_backend`).

    Returns
    -------
    scipy.sparse.linalg.SuperLU or PardisoLDLT
    """
    if choose_backend(K.shape[0], backend) == 'pardiso':
        return ldlt.PardisoLDLT(sp.csr_matrix(K - sigma * M))
    A = (K - sigma * M).tocsc()
    # MMD on A^T A gave 9 % more fill than MMD on A^T + A at 790k DOF but an 18 % faster
    # solve (0.045 s vs 0.054 s); COLAMD doubles the fill and reverse Cuthill-McKee with the
    # natural order quadruples it (docs/modes.md, 'Solver tuning').
    return spla.splu(A, permc_spec='MMD_ATA', diag_pivot_thresh=0.0,
                     options={'SymmetricMode': True})


def inertia_count(lu: Factorisation) -> int:
    """
    Return the number of negative pivots of a factorisation of :func:`factorize_shifted`.

    For ``lu = factorize_shifted(K, M, s)`` this is the number of eigenvalues of
    ``K phi = lambda M phi`` below ``s`` (Sturm count).

    Raises
    ------
    ModalError
        If SuperLU had to pivot off the diagonal (then the count is not an inertia).
    """
    if isinstance(lu, ldlt.PardisoLDLT):
        return lu.negative_pivots()
    if not np.array_equal(lu.perm_r, lu.perm_c):
        raise ModalError('SuperLU pivoted off the diagonal; the Sturm count is unreliable '
                         '(shift too close to an eigenvalue?)')
    return int(np.count_nonzero(lu.U.diagonal() < 0.0))


def sturm_count(K: sp.spmatrix, M: sp.spmatrix, omega2: float, backend: str = 'auto') -> int:
    """
    Return the number of eigenvalues ``omega^2`` of ``(K, M)`` below ``omega2`` [rad^2/s^2].

    Parameters
    ----------
    K, M : (n, n) sparse matrices
        Stiffness and mass matrices, symmetric, M positive definite.
    omega2 : float
        Shift [rad^2/s^2].
    backend : {'auto', 'superlu', 'pardiso'}
        Factorisation (:func:`choose_backend`).
    """
    return inertia_count(factorize_shifted(K, M, omega2, backend))


@dataclass(frozen=True)
class ShiftedFactor:
    """
    One factorisation of ``K - sigma M``, used for shift-invert solves and as a Sturm count.

    Attributes
    ----------
    sigma : float
        Shift [rad^2/s^2].
    lu : scipy.sparse.linalg.SuperLU or PardisoLDLT
        Factorisation (:func:`factorize_shifted`); ``lu.solve(b)`` applies
        ``(K - sigma M)^-1``.
    count : int
        Number of eigenvalues below ``sigma`` (:func:`inertia_count`).
    seconds : float
        Wall time of the factorisation [s].
    """

    sigma: float
    lu: Factorisation
    count: int
    seconds: float


def factor_at(K: sp.spmatrix, M: sp.spmatrix, sigma: float,
              backend: str = 'auto') -> ShiftedFactor:
    """Factorise ``K - sigma M`` once and read its Sturm count from the same factors."""
    t0 = time.perf_counter()
    lu = factorize_shifted(K, M, sigma, backend)
    return ShiftedFactor(float(sigma), lu, inertia_count(lu), time.perf_counter() - t0)
