"""
Eigensolvers for one spectrum window: the k eigenpairs nearest a shift.

The problem is ``K phi = lambda M phi``; the factorisation of ``K - sigma M``
(:class:`pentapod_sim.modes.sturm.ShiftedFactor`) is given.

* ``'arpack'``: shift-invert Lanczos, ``scipy.sparse.linalg.eigsh`` with the factorisation as
  ``OPinv`` (``which='LM'`` on ``1 / (lambda - sigma)``); ``tol`` is relative on those values.
* ``'primme'``: Davidson (PRIMME's GD+k, ``PRIMME_DEFAULT_MIN_MATVECS``) on the same
  shift-inverted pencil ``M (K - sigma M)^-1 M v = nu M v``, ``nu = 1 / (lambda - sigma)``,
  largest ``|nu|``; converged when ``||r|| <= 0.001 tol |nu| ||M v||`` (with ``tol`` itself
  the residuals of ``K v = lambda M v`` came out 100x worse than ARPACK's). Tried and
  slower: PRIMME on ``K v = lambda M v`` with the factorisation as preconditioner
  (``sigma``, ``OPinv``, ``which='SM'``: 3x the solves), its default JDQMR, blocks of 4-8
  (docs/modes.md). PRIMME is an optional package, not in requirements.txt (``pip install
  primme`` builds it against a system BLAS and LAPACK, e.g. Debian's libopenblas-dev).

Both return the eigenvalues [rad^2/s^2] sorted ascending and their vectors (columns);
:func:`mass_normalise` scales those to unit modal mass and gives each one's residual.
"""
from __future__ import annotations

from typing import Callable

import numpy as np
import numpy.typing as npt
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from pentapod_sim.errors import ModalError
from pentapod_sim.modes.sturm import ShiftedFactor

#: Window eigensolvers and what they are.
METHODS = {'arpack': 'shift-invert Lanczos (ARPACK)',
           'primme': 'block Davidson preconditioned by the shift factorisation (PRIMME)'}

#: The solver used unless another is asked for (measured faster at 148k and 788k DOF,
#: docs/modes.md 'Eigensolver per window').
DEFAULT_METHOD = 'arpack'


#: Called before every solve with the shift factorisation; it may raise to abandon the window.
Checkpoint = Callable[[], None]
Array = npt.NDArray[np.float64]
#: Eigenvalues [rad^2/s^2] and eigenvectors (columns)
Eigenpairs = tuple[Array, Array]


def _solver(factor: ShiftedFactor, checkpoint: Checkpoint | None) -> Callable[[Array], Array]:
    """``x -> (K - sigma M)^-1 x``, calling ``checkpoint`` first when one is given."""
    if checkpoint is None:
        return factor.lu.solve
    solve = factor.lu.solve

    def checked(x: Array) -> Array:
        checkpoint()
        return solve(x)
    return checked


def _arpack(K: sp.spmatrix, M: sp.spmatrix, factor: ShiftedFactor, k: int, tol: float,
            checkpoint: Checkpoint | None) -> Eigenpairs:
    n = K.shape[0]
    v0 = np.random.default_rng(n).standard_normal(n)   # same start whatever ran before
    solve = _solver(factor, checkpoint)   # blocks of vectors go to SuperLU in one call
    op = spla.LinearOperator((n, n), matvec=solve, matmat=solve, dtype=float)
    return spla.eigsh(K, k=k, M=M, sigma=factor.sigma, OPinv=op, which='LM',
                      v0=v0, ncv=min(n - 1, max(2 * k + 1, 20)), tol=tol)


def _primme(K: sp.spmatrix, M: sp.spmatrix, factor: ShiftedFactor, k: int, tol: float,
            checkpoint: Checkpoint | None) -> Eigenpairs:
    try:
        import primme
    except ImportError:
        raise ModalError("method 'primme' needs the optional package primme "
                         '(pip install primme); method arpack needs nothing else') from None
    n, solve = K.shape[0], _solver(factor, checkpoint)

    def inverted(x: Array) -> Array:
        return M @ solve(M @ x)

    m_norm = [1.0]

    def converged(value: float, vector: npt.ArrayLike | None, res_norm: float) -> bool:
        """ARPACK's criterion on the inverted pencil, 1000 x tighter."""
        if vector is not None:   # PRIMME may ask without the vector: keep the last ||M v||
            m_norm[0] = float(np.linalg.norm(M @ np.asarray(vector).ravel()))
        return bool(res_norm <= 1e-3 * tol * abs(value) * m_norm[0])

    op = spla.LinearOperator((n, n), matvec=inverted, matmat=inverted, dtype=float)
    v0 = np.random.default_rng(n).standard_normal((n, 1))
    try:
        nu, phi = primme.eigsh(op, k=k, M=M, which='LM', v0=v0, convtest=converged,
                               ncv=min(n - 1, max(2 * k + 1, 20)), maxiter=1000 * k,
                               method='PRIMME_DEFAULT_MIN_MATVECS')
    except primme.PrimmeError as err:
        raise ModalError(f'PRIMME failed on the window around {factor.sigma:.6g} rad^2/s^2: '
                         f'{err}') from None
    return factor.sigma + 1.0 / nu, phi


def window_eigs(K: sp.spmatrix, M: sp.spmatrix, factor: ShiftedFactor, k: int, method: str,
                tol: float, checkpoint: Checkpoint | None = None) -> Eigenpairs:
    """
    Return the ``k`` eigenpairs nearest ``factor.sigma``, eigenvalues ascending.

    Parameters
    ----------
    K, M : (n, n) sparse matrices
        Stiffness [N/m] and mass [kg] matrices.
    factor : ShiftedFactor
        Factorisation of ``K - sigma M`` (also the window's Sturm count).
    k : int
        Eigenpairs wanted (at most n - 2).
    method : {'arpack', 'primme'}
        Eigensolver (:data:`METHODS`).
    tol : float
        Convergence tolerance (relative, see the module notes).
    checkpoint : callable, optional
        Called before every solve with the factorisation; whatever it raises ends the window.
    """
    k = min(k, K.shape[0] - 2)
    if method == 'arpack':
        lam, phi = _arpack(K, M, factor, k, tol, checkpoint)
    elif method == 'primme':
        lam, phi = _primme(K, M, factor, k, tol, checkpoint)
    else:
        raise ValueError(f'method={method!r} is not one of {", ".join(METHODS)}')
    order = np.argsort(lam)
    return lam[order], phi[:, order]


def mass_normalise(K: sp.spmatrix, M: sp.spmatrix, lam: Array, phi: Array,
                   chunk: int = 16) -> Array:
    """
    Scale the columns of ``phi`` in place to ``phi_j^T M phi_j = 1``; return their residuals.

    The residual of mode j is ``||K phi_j - lam_j M phi_j|| / ||K phi_j||``. Column chunks keep
    the products ``M phi`` and ``K phi`` small.
    """
    resid = np.empty(lam.size)
    for lo in range(0, lam.size, chunk):
        cols = slice(lo, lo + chunk)
        Mphi = M @ phi[:, cols]
        scale = 1.0 / np.sqrt(np.einsum('ij,ij->j', phi[:, cols], Mphi))
        phi[:, cols] *= scale
        Mphi *= scale
        Kphi = K @ phi[:, cols]
        resid[cols] = np.linalg.norm(Kphi - Mphi * lam[cols], axis=0) / np.maximum(
            np.linalg.norm(Kphi, axis=0), 1e-300)
    return resid
