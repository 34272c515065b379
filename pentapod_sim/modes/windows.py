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
* ``'block'``: block shift-invert Lanczos (:func:`block_lanczos`): the Krylov space of
  ``S = (K - sigma M)^-1 M`` grown :data:`BLOCK_SIZE` vectors at a time, so the factorisation
  is applied to a block of right-hand sides in one call (at 104k DOF with PARDISO 6-8 x cheaper
  per vector than one at a time, docs/modes.md); full M-orthogonalisation against the whole
  basis (twice), Rayleigh-Ritz in the M inner product, converged when every one of the ``k``
  Ritz pairs nearest ``sigma`` meets ARPACK's criterion ``||S x - nu x||_M <= tol |nu|``
  tightened by :data:`BLOCK_TOL_FACTOR`;
  thick restarts keep the basis at most :data:`BLOCK_MAX_DIM` ``k`` vectors.

All return the eigenvalues [rad^2/s^2] sorted ascending and their vectors (columns);
:func:`mass_normalise` scales those to unit modal mass and gives each one's residual.
"""
from __future__ import annotations

import logging
import time
from typing import Callable

import numpy as np
import numpy.typing as npt
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from pentapod_sim.errors import ModalError
from pentapod_sim.modes import row_split
from pentapod_sim.modes.row_split import RowSplit
from pentapod_sim.modes.sturm import ShiftedFactor

_LOG = logging.getLogger(__name__)

#: Window eigensolvers and what they are.
METHODS = {'arpack': 'shift-invert Lanczos (ARPACK)',
           'primme': 'block Davidson preconditioned by the shift factorisation (PRIMME)',
           'block': 'block shift-invert Lanczos, full M-orthogonalisation'}

#: Vectors per block of :func:`block_lanczos` (docs/modes.md, 'Block Lanczos per window').
BLOCK_SIZE = 16
#: Largest basis of :func:`block_lanczos`, in multiples of the modes asked for (at least
#: ``k + 12 BLOCK_SIZE`` vectors: with ``k + 6`` blocks, 96 vectors for 15 modes, a window of a
#: 900-DOF random structure whose 15th and 16th ``|nu|`` differ by 0.3 % did not converge in
#: 50 restarts; with 200 it did); then it restarts from its best Ritz vectors.
BLOCK_MAX_DIM = 5.0
#: ... and at most this many bytes of basis vectors (6 GB: 1,050 vectors at 763k DOF; the
#: paper-scale frame's windows of 300 modes need about 800 without a restart, and a restart
#: costs solves: 576 of them for 104 modes with 2 GB against 528 without, docs/modes.md).
#: A window process also holds its factorisation (1.7 GB at 763k DOF).
BLOCK_MAX_BYTES = 6 * 1024 ** 3
#: Restarts of :func:`block_lanczos` after which a window that has not converged is a
#: ModalError (the slicing's Sturm counts catch modes missed otherwise).
BLOCK_RESTARTS = 50
#: :func:`block_lanczos` converges at this fraction of ``tol``. ARPACK's criterion itself left
#: residuals ``||K x - lambda M x|| / ||K x||`` of 1.4e-7 on the closed-form chain of 2,500
#: DOF, where ARPACK's were 1.2e-9. On a window of the plate frame (48,522 DOF, 104 modes)
#: 1e-2 / 1e-3 / 1e-4 gave residuals of 2.7e-8 / 1.8e-9 / 1.1e-10 (ARPACK's 3e-12) in
#: 4.2 / 4.1 / 4.3 s (bench/bench_frame.py, window row).
BLOCK_TOL_FACTOR = 1e-4
#: A window of :func:`block_lanczos` running longer than this [s] logs its progress this often
#: (a paper-scale window of 300 modes takes about 3 minutes).
BLOCK_PROGRESS_SECONDS = 30.0

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


def _m_orthonormal(W: Array, MW: Array, rng: np.random.Generator,
                   basis: Array | None, M: sp.spmatrix | RowSplit
                   ) -> tuple[Array, Array, Array]:
    """
    An M-orthonormal block ``V`` (and ``M V``) spanning ``W``, and ``R`` with ``W = V R``.

    ``W`` must already be M-orthogonal to ``basis``. Directions of ``W`` below 1e-10 of its
    largest (the Krylov space has become invariant there) are replaced by random vectors
    M-orthogonalised against ``basis`` and the rest; their rows of ``R`` are zero.
    """
    b = W.shape[1]
    G = W.T @ MW
    w, U = np.linalg.eigh(0.5 * (G + G.T))
    keep = w > 1e-20 * max(float(w.max(initial=0.0)), 1e-300)
    scale = 1.0 / np.sqrt(w[keep])
    V = (W @ U[:, keep]) * scale
    MV = (MW @ U[:, keep]) * scale
    R = np.zeros((b, b))
    R[:int(keep.sum())] = np.sqrt(w[keep])[:, None] * U[:, keep].T
    missing = b - V.shape[1]
    if missing:
        fresh = rng.standard_normal((W.shape[0], missing))
        for _ in range(2):
            for Q in (basis, V):
                if Q is not None and Q.shape[1]:
                    fresh -= Q @ (Q.T @ (M @ fresh))
        Mf = M @ fresh
        Gf = fresh.T @ Mf
        wf, Uf = np.linalg.eigh(0.5 * (Gf + Gf.T))
        if wf.min() <= 1e-20 * wf.max():
            raise ModalError('block Lanczos: no new directions left (the basis spans the '
                             'whole space?)')
        sf = 1.0 / np.sqrt(wf)
        V = np.hstack([V, (fresh @ Uf) * sf])
        MV = np.hstack([MV, (Mf @ Uf) * sf])
    return V, MV, R


def block_lanczos(K: sp.spmatrix, M: sp.spmatrix, factor: ShiftedFactor, k: int, tol: float,
                  checkpoint: Checkpoint | None, block: int = BLOCK_SIZE,
                  max_dim: int | None = None, restarts: int = BLOCK_RESTARTS) -> Eigenpairs:
    """
    The ``k`` eigenpairs nearest ``factor.sigma`` by thick-restarted block shift-invert Lanczos.

    ``S = (K - sigma M)^-1 M`` is self-adjoint in the M inner product; its eigenvalues are
    ``nu = 1 / (lambda - sigma)``. The basis ``Q`` (M-orthonormal, blocks of ``block``
    vectors, started from ``S`` applied to a seeded random block) grows by ``S V`` of its
    newest block, M-orthogonalised twice by classical Gram-Schmidt in blocks (against the
    blocks the recurrence couples it to, then against all of ``Q``); the coefficients give
    ``T = Q^T M S Q`` and ``S Q = Q T + V_next B E^T``, so the residual of a Ritz pair
    ``(nu, Q y)`` is ``||B y_last||`` without touching the long vectors. Converged when the
    ``k`` Ritz values largest in ``|nu|`` all have residuals
    ``<= BLOCK_TOL_FACTOR tol |nu|`` (no rounding floor: a floor of ``1000 eps max |nu|``
    bound in the frame's windows: their residuals rose from 6e-10 to 9e-8). When the basis
    is full (``max_dim`` vectors, default :data:`BLOCK_MAX_DIM` ``k``, at least
    ``k + 12 block``, but not above :data:`BLOCK_MAX_BYTES` unless that leaves less than
    ``k + 3 block``; at most n) it restarts from the Ritz vectors nearest ``sigma`` (about
    half the free room kept) and ``V_next``: ``T`` is then their Ritz values with the
    coupling ``B Y_last`` (thick restart). ``checkpoint`` is called before every block solve.
    Raises ModalError naming the window after ``restarts`` restarts without convergence.
    """
    n, sigma = K.shape[0], factor.sigma
    M = row_split.split(M)                  # the M products on the caller's threads
    if max_dim is None:
        bound = max(int(BLOCK_MAX_DIM * k), k + 12 * block)
        bound = max(min(bound, BLOCK_MAX_BYTES // (8 * n)), k + 3 * block)
    else:
        bound = max_dim
    b = max(1, min(block, min(bound, n) // 3))
    bound = min(bound, n) // b * b         # whole blocks
    keep_n = min(max(k, (bound + k) // 2 - b), bound - 2 * b)   # Ritz vectors kept
    rng = np.random.default_rng(n)          # same start whatever ran before
    start = rng.standard_normal((n, b))
    if checkpoint is not None:
        checkpoint()
    # S applied to the random block, as ARPACK does in shift-invert mode: a start outside S's
    # range carries the pencil's highest modes into the Ritz vectors, where K amplifies them
    # (with ARPACK's test, a closed-form chain's residuals were 1.1e-6 with a random start and
    # 1.4e-7 with this one)
    start = np.asarray(factor.lu.solve(np.asfortranarray(M @ start)), dtype=np.float64)
    V, MV, _ = _m_orthonormal(start, M @ start, rng, None, M)
    Q = np.empty((n, bound), order='F')     # pages are touched only as the basis grows
    T = np.zeros((bound + b, bound))
    m, cycle, solves, t_solve, t0 = 0, 0, b, 0.0, time.perf_counter()
    t_said = t0                             # last progress message
    local = 0                               # where the recurrence's coupling starts
    MV_prev: Array | None = None            # M times the block before V
    while True:
        Q[:, m:m + b] = V
        if checkpoint is not None:
            checkpoint()
        t1 = time.perf_counter()
        W = np.asarray(factor.lu.solve(np.asfortranarray(MV)), dtype=np.float64)
        t_solve += time.perf_counter() - t1
        solves += b
        basis = Q[:, :m + b]
        MW = M @ W
        # classical Gram-Schmidt in M, twice: first against the blocks the Lanczos recurrence
        # couples to the new one (the previous block, or everything since a restart; M times
        # the last two blocks is at hand, so their update needs no M product), then against
        # the whole basis (skipping that pass where its coefficients were below 1e-11 of the
        # block's M-norm saved 10 % and raised the residuals from 3e-11 to 2e-9, docs/modes.md)
        lo = min(local, max(m - b, 0))
        C = basis[:, lo:].T @ MW
        W -= basis[:, lo:] @ C
        T[lo:m + b, m:m + b] += C
        if lo == m:
            MW -= MV @ C
        elif lo == m - b and MV_prev is not None:
            MW -= np.hstack([MV_prev, MV]) @ C
        else:
            MW = M @ W
        C = basis.T @ MW
        W -= basis @ C
        T[:m + b, m:m + b] += C
        MW = M @ W
        MV_prev = MV
        local = m + b
        m += b
        if m < n:
            V, MV, R = _m_orthonormal(W, MW, rng, basis, M)
            T[m:m + b, m - b:m] = R
            if m < k and m + b <= bound:
                continue                    # fewer Ritz pairs than wanted: grow first
        nu, Y = np.linalg.eigh(0.5 * (T[:m, :m] + T[:m, :m].T))
        order = np.argsort(-np.abs(nu))
        nu, Y = nu[order], Y[:, order]
        if m >= n:
            break                           # the basis spans everything: Ritz pairs exact
        coupling = R @ Y[m - b:m]
        resid = np.linalg.norm(coupling, axis=0)
        late = resid[:k] > BLOCK_TOL_FACTOR * tol * np.abs(nu[:k])
        if nu.size >= k and not np.any(late):
            break
        if time.perf_counter() - t_said > BLOCK_PROGRESS_SECONDS:
            t_said = time.perf_counter()
            _LOG.info('window at %.4g Hz: %d of %d modes converged, basis %d vectors, %d '
                      'solves, %.0f s', np.sqrt(max(sigma, 0.0)) / 2 / np.pi,
                      int(np.count_nonzero(~late)), k, m, solves, t_said - t0)
        if m + b <= bound:
            continue
        if cycle == restarts:
            raise ModalError(f'block Lanczos did not converge in the window around '
                             f'{sigma:.6g} rad^2/s^2 ({np.sqrt(max(sigma, 0)) / 2 / np.pi:.4g} '
                             f'Hz): {int(np.count_nonzero(late))} of {k} modes above tolerance '
                             f'{tol:g} after {cycle} restarts of a basis of {bound} vectors')
        cycle += 1
        p = min(keep_n, m)
        for lo in range(0, n, 65536):       # in row chunks: no second basis in memory
            Q[lo:lo + 65536, :p] = Q[lo:lo + 65536, :m] @ Y[:, :p]
        T[:] = 0.0
        T[:p, :p] = np.diag(nu[:p])
        T[p:p + b, :p] = coupling[:, :p]
        m, local = p, 0                     # V is coupled to every kept Ritz vector
        MV_prev = None
    _LOG.debug('block Lanczos at %.6g rad^2/s^2: %d modes, %d solves in blocks of %d, %d '
               'restarts, basis %d of %d; %.2f s, of which solves %.2f s', sigma, k, solves, b,
               cycle, m, bound, time.perf_counter() - t0, t_solve)
    return sigma + 1.0 / nu[:k], Q[:, :m] @ Y[:, :k]


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
    method : {'arpack', 'primme', 'block'}
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
    elif method == 'block':
        lam, phi = block_lanczos(K, M, factor, k, tol, checkpoint)
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
    K, M = row_split.split(K), row_split.split(M)      # on the caller's threads
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
