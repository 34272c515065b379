"""
Undamped modal analysis of large sparse structures: K phi = omega^2 M phi.

The solver is shift-invert Lanczos (ARPACK through ``scipy.sparse.linalg.eigsh``) with a
SuperLU factorisation of ``K - sigma M`` passed as ``OPinv``. For hundreds of modes the
spectrum is cut into slices (windows in omega^2), each solved around a shift in its middle;
Sturm counts (the inertia of ``K - s M``) at the window edges tell how many eigenvalues each
window holds, so no mode is missed or found twice. The Lanczos re-orthogonalisation costs
O(n ncv^2) per restart, so a few windows of tens of modes are much cheaper than one run with
``ncv ~ 2 * n_modes``.

Units: K [N/m, N/rad, N m/rad], M [kg, kg m, kg m^2], frequencies [Hz], omega [rad/s].
"""
from __future__ import annotations

from dataclasses import dataclass, field
import logging
import math
import time
from typing import Any, Callable
import warnings

import numpy as np
import numpy.typing as npt
import scipy.linalg as sla
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from pentapod_sim.errors import ModalError
from pentapod_sim.modal.sturm import factorize_shifted, sturm_count

_LOG = logging.getLogger(__name__)

#: Problems up to this size are solved densely with ``scipy.linalg.eigh`` (exact, all modes).
DENSE_LIMIT = 400

#: ARPACK convergence tolerance (relative, on the shift-inverted Ritz values); results are
#: checked afterwards by their residual ||K phi - omega^2 M phi|| / ||K phi||.
LANCZOS_TOL = 1e-8

#: Modes asked for per window, relative to the modes it should deliver (overlap margin).
WINDOW_PAD = 1.3

#: Progress callback: (modes found so far, modes wanted or None, message).
Progress = Callable[[int, 'int | None', str], None]


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
    stats: dict = field(default_factory=dict)

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


def _check_inputs(K, M, n_modes, f_max) -> int:
    if K.shape != M.shape or K.shape[0] != K.shape[1]:
        raise ValueError(f'K {K.shape} and M {M.shape} must be square and of equal size')
    if n_modes is None and f_max is None:
        raise ValueError('give n_modes, f_max or both')
    if n_modes is not None and not 0 < n_modes <= K.shape[0]:
        raise ValueError(f'n_modes={n_modes} must be in 1..{K.shape[0]}')
    if f_max is not None and not f_max > 0.0:
        raise ValueError(f'f_max={f_max} Hz must be positive')
    return K.shape[0]


def _solve_dense(K, M, n_modes, f_max) -> tuple[np.ndarray, np.ndarray, int | None]:
    """All modes of a small problem with LAPACK (exact reference, no Lanczos)."""
    lam, phi = sla.eigh(K.toarray(), M.toarray())
    below = None
    if f_max is not None:
        below = int(np.count_nonzero(lam < (2 * np.pi * f_max) ** 2))
        lam, phi = lam[:below], phi[:, :below]
    if n_modes is not None:
        lam, phi = lam[:n_modes], phi[:, :n_modes]
    return lam, phi, below


def _window_solve(K, M, sigma, k, lu_timer) -> tuple[np.ndarray, np.ndarray]:
    """The k eigenpairs nearest to ``sigma`` (shift-invert Lanczos, our own factorisation)."""
    t0 = time.perf_counter()
    lu = factorize_shifted(K, M, sigma)
    lu_timer.append(time.perf_counter() - t0)
    n = K.shape[0]
    opinv = spla.LinearOperator((n, n), matvec=lu.solve, dtype=float)
    k = min(k, n - 2)
    v0 = np.random.default_rng(n).standard_normal(n)   # same start whatever ran before
    lam, phi = spla.eigsh(K, k=k, M=M, sigma=sigma, OPinv=opinv, which='LM', v0=v0,
                          ncv=min(n - 1, max(2 * k + 1, 20)), tol=LANCZOS_TOL)
    order = np.argsort(lam)
    return lam[order], phi[:, order]


def _edge_between(lam: np.ndarray, hi_index: int) -> float:
    """A window edge between ``lam[hi_index - 1]`` and ``lam[hi_index]``, moved off clusters."""
    i = hi_index
    while i > 1 and lam[i] - lam[i - 1] < 1e-6 * abs(lam[i]):
        i -= 1   # never cut a (nearly) repeated eigenvalue
    return 0.5 * (lam[i - 1] + lam[i])


def _next_shift(lam: np.ndarray, a: float, target: int) -> float:
    """
    Shift of the next window above edge ``a`` [rad^2/s^2] that should hold ``target`` modes.

    The mode count of these structures grows about linearly in frequency, so the density per
    unit omega of the last window is extrapolated; the shift sits in the middle (in omega^2)
    of the predicted window, and asking for ``WINDOW_PAD * target`` modes makes the returned
    set reach a little below ``a``.
    """
    w = np.sqrt(np.clip(lam, 0.0, None))
    density = (w.size - 1) / max(w[-1] - w[0], 1e-300)   # modes per rad/s
    w_a = math.sqrt(max(a, 0.0))
    w_b = w_a + target / density
    return 0.5 * (w_a ** 2 + w_b ** 2)


@dataclass
class _Slicer:
    """State of one spectrum-slicing run (kept small so each step stays readable)."""

    K: sp.spmatrix
    M: sp.spmatrix
    per_window: int
    progress: Progress | None
    lam: list = field(default_factory=list)
    phi: list = field(default_factory=list)
    lu_times: list = field(default_factory=list)
    windows: int = 0
    retries: int = 0

    def report(self, found: int, wanted: int | None, msg: str) -> None:
        _LOG.info(msg)
        if self.progress is not None:
            self.progress(found, wanted, msg)

    def count(self, omega2: float) -> int:
        t0 = time.perf_counter()
        c = sturm_count(self.K, self.M, omega2)
        self.lu_times.append(time.perf_counter() - t0)
        return c

    def first_window(self, k: int) -> tuple[float, int, np.ndarray, np.ndarray]:
        """Lowest modes by a shift below the spectrum; returns edge, its count and modes."""
        scale = abs(self.K.diagonal()).max() / abs(self.M.diagonal()).max()
        sigma = -1e-9 * scale   # K may be only semi-definite: stay just below zero
        lam, phi = _window_solve(self.K, self.M, sigma, k + 1, self.lu_times)
        return sigma, 0, lam, phi


def _slice(sl: _Slicer, wanted: int | None, lam_max: float | None) -> None:
    """Collect all eigenpairs below lam_max (if given) and at least ``wanted`` of them."""
    a, c_a, lam, phi = sl.first_window(sl.per_window)
    target = sl.per_window
    while True:
        sl.windows += 1
        done_by_limit = lam_max is not None and lam[-1] >= lam_max
        b = lam_max if lam_max is not None and done_by_limit else _edge_between(lam,
                                                                                lam.size - 1)
        c_b = sl.count(b)
        inside = (lam >= a) & (lam < b)
        if b <= a or c_b - c_a != np.count_nonzero(inside):
            sl.retries += 1
            if sl.retries > 20:
                raise ModalError(f'spectrum slicing could not fill window [{a:.6g}, {b:.6g}) '
                                 f'rad^2/s^2: Sturm count {c_b - c_a}, found '
                                 f'{np.count_nonzero(inside)}')
            # shift lower and ask for more: the returned set did not reach the lower edge
            target = int(target * 1.5) + 5
            sigma = a + 0.3 * (lam[-1] - a)
            lam, phi = _window_solve(sl.K, sl.M, sigma, target, sl.lu_times)
            continue
        sl.lam.append(lam[inside])
        sl.phi.append(phi[:, inside])
        sl.report(c_b, wanted, f'window {sl.windows}: {c_b - c_a} modes '
                  f'{math.sqrt(max(a, 0)) / 2 / math.pi:.4g}-{math.sqrt(b) / 2 / math.pi:.4g} Hz, '
                  f'{c_b} below upper edge (Sturm)')
        a, c_a = b, c_b
        if done_by_limit or (wanted is not None and c_b >= wanted):
            return
        target = sl.per_window
        if wanted is not None:   # the last window asks only for what is still missing
            target = max(4, min(target, wanted - c_a + 2))
        sigma = _next_shift(lam, a, target)
        lam, phi = _window_solve(sl.K, sl.M, sigma, int(WINDOW_PAD * target), sl.lu_times)


def _assemble_blocks(lam_blocks: list, phi_blocks: list, n_keep: int | None):
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


def _normalise_and_check(K, M, lam, phi, blocks, chunk: int = 16,
                         edge_modes: int = 12) -> dict:
    """Mass-normalise in place; return max residual and M-orthogonality errors."""
    resid = 0.0
    for lo in range(0, lam.size, chunk):   # column chunks keep M phi, K phi small
        cols = slice(lo, lo + chunk)
        Mphi = M @ phi[:, cols]
        scale = 1.0 / np.sqrt(np.einsum('ij,ij->j', phi[:, cols], Mphi))
        phi[:, cols] *= scale
        Mphi *= scale
        Kphi = K @ phi[:, cols]
        r = np.linalg.norm(Kphi - Mphi * lam[cols], axis=0) / np.maximum(
            np.linalg.norm(Kphi, axis=0), 1e-300)
        resid = max(resid, float(r.max(initial=0.0)))
    # M-orthogonality across each window edge, where a mode found twice would show: the
    # highest modes of one window against the lowest of the next (a full Phi^T M Phi would
    # cost O(n m^2), 2e11 flops for 500 modes of 800k DOF).
    ortho = 0.0
    for j, (lo, hi) in enumerate(blocks):
        nxt = blocks[j + 1][1] if j + 1 < len(blocks) else hi
        cols = np.r_[max(lo, hi - edge_modes):min(nxt, hi + edge_modes)]
        G = phi[:, cols].T @ (M @ phi[:, cols])
        ortho = max(ortho, float(np.abs(G - np.eye(cols.size)).max()))
    return {'max_residual': resid, 'max_orthogonality_error': ortho}


def solve_modes(K: sp.spmatrix, M: sp.spmatrix, *, n_modes: int | None = None,
                f_max: float | None = None, modes_per_window: int = 30,
                progress: Progress | None = None, tol_check: float = 1e-6) -> ModalResult:
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
        Modes per spectrum slice; each slice costs one factorisation plus a Lanczos run with
        ``ncv ~ 2.5 * modes_per_window``.
    progress : callable, optional
        Called after each slice as ``progress(found, wanted, message)``.
    tol_check : float
        Relative residual / M-orthogonality error above which a warning is issued.

    Returns
    -------
    ModalResult
        Sorted, mass-normalised modes.

    Raises
    ------
    ValueError
        For inconsistent sizes or requests.
    ModalError
        If the slices cannot be made consistent with the Sturm counts.
    """
    n = _check_inputs(K, M, n_modes, f_max)
    K, M = sp.csr_matrix(K), sp.csr_matrix(M)
    lam_max = None if f_max is None else (2.0 * np.pi * f_max) ** 2
    t0 = time.perf_counter()
    sturm = None
    stats: dict[str, Any]
    if n <= DENSE_LIMIT:
        lam, phi, sturm = _solve_dense(K, M, n_modes, f_max)
        blocks, stats = [(0, lam.size)], {'method': 'dense eigh', 'windows': 1}
    else:
        per_window = modes_per_window if n_modes is None else min(modes_per_window, n_modes)
        sl = _Slicer(K, M, max(per_window, 4), progress)
        _slice(sl, n_modes, lam_max)
        lam, phi, blocks = _assemble_blocks(sl.lam, sl.phi, n_modes)
        if lam_max is not None:
            sturm = sl.count(lam_max)
        stats = {'method': 'shift-invert Lanczos, spectrum slicing', 'windows': sl.windows,
                 'retries': sl.retries, 'factorisations': len(sl.lu_times),
                 'factorisation_time_s': float(sum(sl.lu_times))}
    if lam.size and lam[0] < -tol_check * abs(lam).max():
        warnings.warn(f'negative eigenvalue {lam[0]:.3g} rad^2/s^2: K is not positive '
                      'semi-definite', RuntimeWarning, stacklevel=2)
    stats.update(_normalise_and_check(K, M, lam, phi, blocks))
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
