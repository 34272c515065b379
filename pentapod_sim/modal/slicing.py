"""
Spectrum slicing: windows in omega^2 with one factorisation each, checked by Sturm counts.

Window j is solved around its shift sigma_j with the factorisation of ``K - sigma_j M``; the
inertia of that factorisation is the Sturm count N(sigma_j) (eigenvalues below sigma_j). The
modes in [sigma_j, sigma_{j+1}) are those of window j below a cut placed between two of its
eigenvalues (never in a cluster) and those of window j+1 from the cut up; their number must
be N(sigma_{j+1}) - N(sigma_j), else window j+1 is solved again for more modes with the same
factorisation (and supplies the whole interval once it reaches below sigma_j). The last
window's modes are checked by one count-only factorisation at the final edge (f_max, or a cut
above the last mode wanted). So every mode below the last edge is there exactly once, with
one factorisation per window plus one, where counting at separate window edges took two.

Units: eigenvalues omega^2 [rad^2/s^2].
"""
from __future__ import annotations

from dataclasses import dataclass, field
import logging
import math
import time
from typing import Callable

import numpy as np
import scipy.sparse as sp

from pentapod_sim.errors import ModalError
from pentapod_sim.modal.sturm import factor_at, ShiftedFactor
from pentapod_sim.modal.windows import window_eigs

_LOG = logging.getLogger(__name__)

#: Eigensolver convergence tolerance (relative; ARPACK: on the shift-inverted Ritz values);
#: results are checked afterwards by their residual ||K phi - omega^2 M phi|| / ||K phi||.
LANCZOS_TOL = 1e-8

#: Modes asked for per window, relative to the modes it should deliver (overlap margin).
WINDOW_PAD = 1.3

#: Progress callback: (modes found so far, modes wanted or None, message).
Progress = Callable[[int, 'int | None', str], None]


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


def _between(lam: np.ndarray, lo: float, hi: float) -> np.ndarray:
    return (lam >= lo) & (lam < hi)


@dataclass
class _Run:
    """One window: its factorisation (shift and Sturm count there) and the modes found."""

    factor: ShiftedFactor
    lam: np.ndarray
    phi: np.ndarray

    def n_in(self, lo: float, hi: float) -> int:
        return int(np.count_nonzero(_between(self.lam, lo, hi)))


@dataclass
class Slicer:
    """
    State of one spectrum-slicing run.

    Every window is solved around its shift with the factorisation of ``K - shift M``, whose
    inertia is also the Sturm count at that shift: one factorisation per window, plus one
    count-only factorisation at the upper end.
    """

    K: sp.spmatrix
    M: sp.spmatrix
    per_window: int
    method: str
    progress: Progress | None
    limit: float = math.inf           # no mode at or above this eigenvalue is kept
    lam: list = field(default_factory=list)
    phi: list = field(default_factory=list)
    factors: list = field(default_factory=list)
    solve_times: list = field(default_factory=list)
    windows: int = 0
    retries: int = 0
    final: ShiftedFactor | None = None

    def report(self, found: int, wanted: int | None, msg: str) -> None:
        _LOG.info(msg)
        if self.progress is not None:
            self.progress(found, wanted, msg)

    def factor(self, sigma: float) -> ShiftedFactor:
        factor = factor_at(self.K, self.M, sigma)
        self.factors.append(factor.seconds)
        return factor

    def solve(self, factor: ShiftedFactor, k: int) -> _Run:
        t0 = time.perf_counter()
        lam, phi = window_eigs(self.K, self.M, factor, k, self.method, LANCZOS_TOL)
        self.solve_times.append(time.perf_counter() - t0)
        return _Run(factor, lam, phi)

    def accept(self, run: _Run, lo: float, hi: float) -> None:
        inside = _between(run.lam, lo, min(hi, self.limit))
        if np.any(inside):
            self.lam.append(run.lam[inside])
            self.phi.append(run.phi[:, inside])

    def retry(self, run: _Run, k: int, a: float, b: float, counted: int) -> tuple[_Run, int]:
        """Solve the window of ``run`` again with more modes (same factorisation)."""
        self.retries += 1
        if self.retries > 20:
            raise ModalError(f'spectrum slicing could not fill window [{a:.6g}, {b:.6g}) '
                             f'rad^2/s^2: Sturm count {counted}')
        k = int(k * 1.5) + 5
        sigma = run.factor.sigma
        near = np.abs(run.lam - sigma) < 1e-7 * abs(sigma)
        if np.any(near):   # the shift sits on an eigenvalue: its count is unreliable, move it
            j = int(np.flatnonzero(near)[-1])
            above = run.lam[j + 1] if j + 1 < run.lam.size else run.lam[j] * 1.01
            return self.solve(self.factor(0.5 * (run.lam[j] + above)), k), k
        return self.solve(run.factor, k), k


def _interval(sl: Slicer, prev: _Run, lo: float, c_lo: int, cut: float, k: int) -> _Run:
    """
    Solve the window above ``cut`` and accept every mode in [lo, its shift).

    Modes in [lo, cut) come from ``prev`` and those in [cut, shift) from the new window; their
    number must equal the Sturm count at the new shift minus ``c_lo`` (both from the windows'
    own factorisations). On a mismatch the new window is solved for more modes; once it
    reaches below ``lo`` it supplies the whole interval.
    """
    sl.windows += 1
    run = sl.solve(sl.factor(_next_shift(prev.lam, cut, k)), int(WINDOW_PAD * k))
    k = int(WINDOW_PAD * k)
    while True:
        sigma, counted = run.factor.sigma, run.factor.count - c_lo
        if run.lam.size and run.lam[0] < lo:
            cut = lo
        if prev.n_in(lo, cut) + run.n_in(cut, sigma) == counted and cut < sigma:
            sl.accept(prev, lo, cut)
            sl.accept(run, cut, sigma)
            return run
        run, k = sl.retry(run, k, lo, sigma, counted)


def slice_spectrum(sl: Slicer, wanted: int | None, lam_max: float | None) -> None:
    """Collect all eigenpairs below lam_max (if given) and at least ``wanted`` of them."""
    scale = abs(sl.K.diagonal()).max() / abs(sl.M.diagonal()).max()
    first = sl.factor(-1e-9 * scale)   # K may be only semi-definite: stay just below zero
    k = sl.per_window + 1
    sl.windows = 1
    prev = sl.solve(first, k)
    lo, c_lo = first.sigma, first.count
    while True:
        done_by_limit = lam_max is not None and prev.lam[-1] >= lam_max
        cut = lam_max if done_by_limit else _edge_between(prev.lam, prev.lam.size - 1)
        if done_by_limit or (wanted is not None and c_lo + prev.n_in(lo, cut) >= wanted):
            end = sl.factor(cut)               # the last edge: a count-only factorisation
            if end.count - c_lo == prev.n_in(lo, cut):
                sl.accept(prev, lo, cut)
                sl.final = end
                sl.report(end.count, wanted, f'last window: {end.count - c_lo} modes up to '
                          f'{math.sqrt(cut) / 2 / math.pi:.4g} Hz, {end.count} below (Sturm)')
                return
            prev, k = sl.retry(prev, k, lo, cut, end.count - c_lo)
            continue
        target = sl.per_window
        if wanted is not None:   # the last window asks only for what is still missing
            target = max(4, min(target, wanted - c_lo - prev.n_in(lo, cut) + 2))
        run = _interval(sl, prev, lo, c_lo, cut, target)
        lo, c_lo = run.factor.sigma, run.factor.count
        sl.report(c_lo, wanted, f'window {sl.windows}: modes up to '
                  f'{math.sqrt(max(lo, 0)) / 2 / math.pi:.4g} Hz, {c_lo} below (Sturm)')
        prev, k = run, int(WINDOW_PAD * target)
        if (wanted is not None and c_lo >= wanted) or (lam_max is not None and lo >= lam_max):
            return
