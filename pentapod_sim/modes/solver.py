"""
Undamped modal analysis of large sparse structures: K phi = omega^2 M phi.

The spectrum is cut into slices (windows in omega^2), each solved around a shift with a
SuperLU factorisation of ``K - sigma M`` (shift-invert Lanczos, ARPACK through
``scipy.sparse.linalg.eigsh``, or block Davidson, PRIMME: :mod:`pentapod_sim.modes.windows`).
The inertia of that same factorisation is the Sturm count at the shift, so one factorisation
per window gives both the solves and the count: the modes between two consecutive shifts come
from the two windows (split at a cut between two eigenvalues) and must number the difference
of the two counts, so no mode is missed or found twice. The Lanczos re-orthogonalisation costs
O(n ncv^2) per restart, so a few windows of tens of modes are much cheaper than one run with
``ncv ~ 2 * n_modes``.

Units: K [N/m, N/rad, N m/rad], M [kg, kg m, kg m^2], frequencies [Hz], omega [rad/s].
"""
from __future__ import annotations

from dataclasses import dataclass, field
import logging
import math
import time
from typing import Any
import warnings

import numpy as np
import numpy.typing as npt
import scipy.linalg as sla
import scipy.sparse as sp

from pentapod_sim.modes.slicing import LANCZOS_TOL, Progress, slice_spectrum, Slicer
from pentapod_sim.modes.sturm import choose_backend
from pentapod_sim.modes.window_pool import default_workers, WindowPool
from pentapod_sim.modes.windows import DEFAULT_METHOD, mass_normalise, METHODS

_LOG = logging.getLogger(__name__)

#: Problems up to this size are solved densely with ``scipy.linalg.eigh`` (exact, all modes).
DENSE_LIMIT = 400
#: Up to this size, a problem whose matrices are this dense (nnz / n^2) is solved densely too:
#: a pose's model with the plate frame's superelement (dense blocks of 66 + ~500 DOF in about
#: 1,300) factorises like a dense matrix in every window, while one LAPACK call costs
#: O(n^3) once.
DENSE_FILL_LIMIT = (3000, 0.05)
Array = npt.NDArray[np.float64]


@dataclass(frozen=True)
class ModalResult:
    """
    Mass-normalised undamped modes, sorted by frequency.

    Attributes
    ----------
    frequencies : (m,) ndarray
        Natural frequencies [Hz], ascending.
    shapes : (n, m) ndarray
        Mode shapes, mass-normalised (``shapes.T @ M @ shapes = I``); column j belongs to
        ``frequencies[j]``. Units of the DOFs they act on per unit modal coordinate
        [m/sqrt(kg), rad/sqrt(kg m^2)].
    sturm_count : int or None
        Number of eigenvalues below ``f_max`` from the inertia of ``K - (2 pi f_max)^2 M``,
        or None when no frequency limit was asked for.
    f_max : float or None
        Frequency limit [Hz] the count refers to.
    stats : dict
        Solver bookkeeping: windows, factorisations, wall times [s], max residual and
        orthogonality error.
    """

    frequencies: npt.NDArray[np.float64]
    shapes: npt.NDArray[np.float64]
    sturm_count: int | None = None
    f_max: float | None = None
    stats: dict[str, Any] = field(default_factory=dict)

    @property
    def omega(self) -> npt.NDArray[np.float64]:
        """Angular natural frequencies [rad/s]."""
        return 2.0 * np.pi * self.frequencies

    @property
    def n_modes(self) -> int:
        """Number of modes held."""
        return self.frequencies.size

    def shapes_at(self, T: sp.spmatrix | npt.ArrayLike) -> npt.NDArray[np.float64]:
        """
        Return the mode shapes seen through an observation matrix.

        Parameters
        ----------
        T : (r, n) sparse matrix or array
            Observation matrix, e.g. a named point's (6, n) matrix from ``FEModel.points``.

        Returns
        -------
        (r, m) ndarray
            ``T @ shapes``: row i is output i of every mode.
        """
        obs: Any = T if sp.issparse(T) else np.asarray(T, dtype=float)
        if obs.shape[1] != self.shapes.shape[0]:
            raise ValueError(f'observation matrix has {obs.shape[1]} columns, '
                             f'the modes have {self.shapes.shape[0]} DOFs')
        return np.asarray(obs @ self.shapes)

    def count_below(self, f: float) -> int:
        """Return how many of the held modes lie below frequency ``f`` [Hz]."""
        return int(np.searchsorted(self.frequencies, f, side='left'))


def _check_inputs(K: sp.spmatrix, M: sp.spmatrix, n_modes: int | None,
                  f_max: float | None) -> int:
    if K.shape != M.shape or K.shape[0] != K.shape[1]:
        raise ValueError(f'K {K.shape} and M {M.shape} must be square and of equal size')
    if n_modes is None and f_max is None:
        raise ValueError('give n_modes, f_max or both')
    if n_modes is not None and not 0 < n_modes <= K.shape[0]:
        raise ValueError(f'n_modes={n_modes} must be in 1..{K.shape[0]}')
    if f_max is not None and not f_max > 0.0:
        raise ValueError(f'f_max={f_max} Hz must be positive')
    return K.shape[0]


def _solve_dense(K: sp.spmatrix, M: sp.spmatrix, n_modes: int | None, f_max: float | None
                 ) -> tuple[Array, Array, int | None]:
    """All modes of a small problem with LAPACK (exact reference, no Lanczos)."""
    lam, phi = sla.eigh(K.toarray(), M.toarray(), driver='gvd')
    below = None
    if f_max is not None:
        below = int(np.count_nonzero(lam < (2 * np.pi * f_max) ** 2))
        lam, phi = lam[:below], phi[:, :below]
    if n_modes is not None:
        lam, phi = lam[:n_modes], phi[:, :n_modes]
    return lam, phi, below


def _assemble_blocks(lam_blocks: list[Array], phi_blocks: list[Array], n_keep: int | None
                     ) -> tuple[Array, Array, list[tuple[int, int]]]:
    """Stack the windows' modes into one array, freeing each window as it is copied."""
    total = sum(x.size for x in lam_blocks)
    n_keep = total if n_keep is None else min(n_keep, total)
    lam = np.concatenate(lam_blocks)[:n_keep]
    phi = np.empty((phi_blocks[0].shape[0], n_keep))
    blocks, lo = [], 0
    while phi_blocks and lo < n_keep:
        block = phi_blocks.pop(0)
        hi = min(lo + block.shape[1], n_keep)
        phi[:, lo:hi] = block[:, :hi - lo]
        blocks.append((lo, hi))
        lo = hi
    phi_blocks.clear()
    return lam, phi, blocks


def _edge_orthogonality(M: sp.spmatrix, phi: Array, blocks: list[tuple[int, int]],
                        edge_modes: int = 12) -> float:
    """
    Largest M-orthogonality error across the window edges, where a mode found twice would show.

    The highest modes of one window against the lowest of the next (a full ``Phi^T M Phi``
    would cost O(n m^2), 2e11 flops for 500 modes of 800k DOF).
    """
    ortho = 0.0
    for j, (lo, hi) in enumerate(blocks):
        nxt = blocks[j + 1][1] if j + 1 < len(blocks) else hi
        cols = np.r_[max(lo, hi - edge_modes):min(nxt, hi + edge_modes)]
        G = phi[:, cols].T @ (M @ phi[:, cols])
        ortho = max(ortho, float(np.abs(G - np.eye(cols.size)).max()))
    return ortho


def solve_modes(K: sp.spmatrix, M: sp.spmatrix, *, n_modes: int | None = None,
                f_max: float | None = None, modes_per_window: int = 30,
                progress: Progress | None = None, tol_check: float = 1e-6,
                method: str = DEFAULT_METHOD, workers: int | None = None,
                factorisation: str = 'auto', share_last_windows: bool = False) -> ModalResult:
    """
    Compute the lowest undamped modes of ``K phi = omega^2 M phi``.

    Parameters
    ----------
    K : (n, n) sparse matrix
        Stiffness matrix [N/m, ...], symmetric positive (semi-)definite.
    M : (n, n) sparse matrix
        Mass matrix [kg, ...], symmetric positive definite.
    n_modes : int, optional
        Number of lowest modes wanted. With ``f_max`` too: at most this many below ``f_max``.
    f_max : float, optional
        Return every mode below this frequency [Hz]; the count is verified by a Sturm count.
    modes_per_window : int
        Modes per spectrum slice; each slice costs one factorisation (shared by its solves and
        the Sturm count at its shift) plus an eigensolver run for ``1.3 * modes_per_window``
        modes.
    progress : callable, optional
        Called after each slice as ``progress(found, wanted, message)``.
    tol_check : float
        Relative residual / M-orthogonality error above which a warning is issued.
    method : {'arpack', 'primme', 'block'}
        Eigensolver per window (:data:`pentapod_sim.modes.windows.METHODS`): shift-invert
        Lanczos (ARPACK through scipy), block Davidson (PRIMME, an optional package) or
        block shift-invert Lanczos (blocks of solves in one call; the plate frame's
        reduction uses it).
    workers : int, optional
        Processes solving windows side by side (1: all in this process). Default: one per
        core for problems of at least 100,000 DOF, else 1
        (:func:`pentapod_sim.modes.window_pool.default_workers`). Each window process uses
        the BLAS threads its environment allows (``OPENBLAS_NUM_THREADS``).
    factorisation : {'auto', 'superlu', 'pardiso'}
        Factorisation of the shifted pencils (:func:`pentapod_sim.modes.sturm.choose_backend`:
        'auto' takes MKL PARDISO's LDL^T from 20,000 DOF where it is installed).
    share_last_windows : bool
        With ``f_max``: the windows below it share the modes predicted there instead of the
        last one being a whole window (:data:`pentapod_sim.modes.slicing.LAST_WINDOW_MARGIN`;
        the plate frame's reduction). Off by default: the beam models' windows are cheap, and
        with it their shapes changed by 4e-11 relative at P1 (signs aside), enough for the
        damping calibration's mode identification to drop two modes
        (test/test_damping_calibration.py).

    Returns
    -------
    ModalResult
        Sorted, mass-normalised modes.

    Raises
    ------
    ValueError
        For inconsistent sizes or requests, or an unknown method.
    ModalError
        If the slices cannot be made consistent with the Sturm counts.
    """
    n = _check_inputs(K, M, n_modes, f_max)
    if method not in METHODS:
        raise ValueError(f'method={method!r} is not one of {", ".join(METHODS)}')
    K, M = sp.csr_matrix(K), sp.csr_matrix(M)
    lam_max = None if f_max is None else (2.0 * np.pi * f_max) ** 2
    t0 = time.perf_counter()
    sturm = None
    stats: dict[str, Any]
    dense_n, dense_fill = DENSE_FILL_LIMIT
    if n <= DENSE_LIMIT or (n <= dense_n and max(K.nnz, M.nnz) >= dense_fill * n * n):
        lam, phi, sturm = _solve_dense(K, M, n_modes, f_max)
        blocks, stats = [(0, lam.size)], {'method': 'dense eigh', 'windows': 1}
        residual = mass_normalise(K, M, lam, phi)
    else:
        per_window = modes_per_window if n_modes is None else min(modes_per_window, n_modes)
        workers = default_workers(n) if workers is None else workers
        backend = choose_backend(n, factorisation)
        with WindowPool(K, M, method, LANCZOS_TOL, workers, backend) as pool:
            sl = Slicer(pool, max(per_window, 4), progress,
                        math.inf if lam_max is None else lam_max, share_last_windows)
            slice_spectrum(sl, n_modes, lam_max)
            if lam_max is not None:
                final = sl.final if sl.final is not None and sl.final.sigma == lam_max \
                    else sl.solve(lam_max, 0)
                sturm = final.count
        residual = np.concatenate(sl.residual)[:n_modes]
        lam, phi, blocks = _assemble_blocks(sl.lam, sl.phi, n_modes)
        stats = {'method': f'{METHODS[method]}, spectrum slicing', 'windows': sl.windows,
                 'retries': sl.retries, 'gap_windows': sl.gaps, 'windows_unused': sl.unused,
                 'window_processes': workers, 'factorisations': len(sl.factors),
                 'factorisation': backend,
                 'factorisation_time_s': float(sum(sl.factors)),
                 'eigensolver_time_s': float(sum(sl.solve_times))}
    if lam.size and lam[0] < -tol_check * abs(lam).max():
        warnings.warn(f'negative eigenvalue {lam[0]:.3g} rad^2/s^2: K is not positive '
                      'semi-definite', RuntimeWarning, stacklevel=2)
    stats['max_residual'] = float(residual.max(initial=0.0))
    stats['max_orthogonality_error'] = _edge_orthogonality(M, phi, blocks)
    stats['solve_time_s'] = time.perf_counter() - t0
    stats['n_dof'] = n
    if stats['max_residual'] > tol_check or stats['max_orthogonality_error'] > tol_check:
        warnings.warn(f'modes are inaccurate: residual {stats["max_residual"]:.2g}, '
                      f'M-orthogonality error {stats["max_orthogonality_error"]:.2g}',
                      RuntimeWarning, stacklevel=2)
    freqs = np.sqrt(np.clip(lam, 0.0, None)) / (2.0 * np.pi)
    _LOG.info('%d modes of %d DOF in %.2f s (%s)', lam.size, n, stats['solve_time_s'],
              stats['method'])
    return ModalResult(freqs, phi, sturm, f_max, stats)
