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

On several cores the windows above the last checked one are solved ahead, side by side
(:class:`pentapod_sim.modes.window_pool.WindowPool`): their shifts are extrapolated from the
last checked window as if the windows in between had delivered their targets. The checks are
the same, one window after the other in shift order; a window solved ahead that ends up below
the cut it should continue from is dropped and solved again, and one that misses modes is
solved again for more, as above.

Units: eigenvalues omega^2 [rad^2/s^2].
"""
from __future__ import annotations

from collections import deque
from concurrent.futures import Future
from dataclasses import dataclass, field
import logging
import math
from typing import Callable

import numpy as np
import numpy.typing as npt

from pentapod_sim.errors import ModalError
from pentapod_sim.modes.window_pool import Window, WindowPool

_LOG = logging.getLogger(__name__)
Array = npt.NDArray[np.float64]

#: Eigensolver convergence tolerance (relative; ARPACK: on the shift-inverted Ritz values);
#: results are checked afterwards by their residual ||K phi - omega^2 M phi|| / ||K phi||.
LANCZOS_TOL = 1e-8

#: Modes asked for per window, relative to the modes it should deliver (overlap margin).
WINDOW_PAD = 1.3

#: Windows solved ahead are centred this many targets apart, so neighbours overlap by about
#: ``WINDOW_PAD - AHEAD_SPACING`` targets (a checked window's successor: by half that, but
#: placed from the window's actual top). At 148k DOF, 500 modes, 2 processes: 1.0 took 20
#: windows, no retries, 42 s; 1.15 and 1.3 took 18 and 16 windows but 2 and 3 retries (a
#: window solved again for more modes), 52 and 54 s (docs/modes.md).
AHEAD_SPACING = 1.0

#: The windows below the highest frequency wanted (``lam_max``) share the modes predicted
#: there (density extrapolated, this margin on top, plus four) equally instead of the last
#: one being a full window: at 104k DOF the last of three full windows had delivered 175 of
#: its 299 modes (the others above the edge). The modes left are one window while they are
#: at most :data:`LAST_WINDOW_STRETCH` windows: a window's Gram-Schmidt cost grows with the
#: square of its basis (at 763k DOF one of 403 modes took 330 s with a restart, one of 300
#: modes 218 s).
LAST_WINDOW_MARGIN = 1.15
LAST_WINDOW_STRETCH = 1.25

#: Progress callback: (modes found so far, modes wanted or None, message).
Progress = Callable[[int, 'int | None', str], None]


def _edge_between(lam: Array, hi_index: int) -> float:
    """A window edge between ``lam[hi_index - 1]`` and ``lam[hi_index]``, moved off clusters."""
    i = hi_index
    while i > 1 and lam[i] - lam[i - 1] < 1e-6 * abs(lam[i]):
        i -= 1   # never cut a (nearly) repeated eigenvalue
    return 0.5 * (lam[i - 1] + lam[i])


def _density(lam: Array) -> float:
    """
    Modes per rad/s in the upper half of a window, where the next window continues.

    The mode count of the beam models grows about linearly with frequency; the plate frame's
    density grows with it: at 763k DOF the density over the whole first window (0-520 Hz)
    put the next window's shift so high that it left 57 modes below it uncovered.
    """
    w = np.sqrt(np.clip(lam, 0.0, None))
    if w.size >= 8:
        w = w[w.size // 2:]
    return (w.size - 1) / max(w[-1] - w[0], 1e-300)


def _next_shift(lam: Array, a: float, target: int) -> float:
    """
    Shift [rad^2/s^2] of the next window above edge ``a`` that should hold ``target`` modes.

    The density per unit omega of the last window ``lam`` is extrapolated; the shift sits in
    the middle (in omega^2) of the predicted window, and asking for ``WINDOW_PAD * target``
    modes makes the returned set reach a little below ``a``.
    """
    density = _density(lam)
    w_a = math.sqrt(max(a, 0.0))
    w_b = w_a + target / density
    return 0.5 * (w_a ** 2 + w_b ** 2)


def _edge_above(lam: Array, sigma: float, target: int) -> float:
    """
    Edge [rad^2/s^2] above which the window after one solved ahead at ``sigma`` is placed.

    It lies half of ``AHEAD_SPACING * target`` modes above ``sigma`` (density extrapolated
    from the window ``lam``), as a checked window's successor is placed above its cut.
    """
    return (math.sqrt(max(sigma, 0.0)) + 0.5 * AHEAD_SPACING * target / _density(lam)) ** 2


def _modes_left(lam: Array, edge: float, lam_max: float) -> int:
    """Modes predicted in [``edge``, ``lam_max``) by the density of ``lam``, with margin."""
    span = math.sqrt(max(lam_max, 0.0)) - math.sqrt(max(edge, 0.0))
    return int(math.ceil(LAST_WINDOW_MARGIN * _density(lam) * max(span, 0.0))) + 4


def _between(lam: Array, lo: float, hi: float) -> npt.NDArray[np.bool_]:
    return (lam >= lo) & (lam < hi)


def _n_in(window: Window, lo: float, hi: float) -> int:
    return int(np.count_nonzero(_between(window.lam, lo, hi)))


@dataclass
class Slicer:
    """
    State of one spectrum-slicing run.

    Every window is solved around its shift with the factorisation of ``K - shift M``, whose
    inertia is also the Sturm count at that shift: one factorisation per window, plus one
    count-only factorisation at the upper end. ``ahead`` holds the windows being solved above
    the last checked one (as many as the pool has processes), lowest first.
    """

    pool: WindowPool
    per_window: int
    progress: Progress | None
    limit: float = math.inf           # no mode at or above this eigenvalue is kept
    share_last: bool = False          # the windows below lam_max share its modes
    lam: list[Array] = field(default_factory=list)
    phi: list[Array] = field(default_factory=list)
    residual: list[Array] = field(default_factory=list)
    factors: list[float] = field(default_factory=list)          # factorisation times [s]
    solve_times: list[float] = field(default_factory=list)      # eigensolver times [s]
    #: (future window, modes it should deliver, its shift) of the windows solved ahead
    ahead: deque[tuple[Future[Window | None], int, float]] = field(default_factory=deque)
    windows: int = 0
    retries: int = 0
    gaps: int = 0                     # windows solved between a window and the one below it
    unused: int = 0                   # windows solved ahead and then not used
    final: Window | None = None

    def report(self, found: int, wanted: int | None, msg: str) -> None:
        _LOG.info(msg)
        if self.progress is not None:
            self.progress(found, wanted, msg)

    def take(self, future: Future[Window | None]) -> Window:
        window = self.pool.result(future)
        if window.factor_seconds:
            self.factors.append(window.factor_seconds)
        if window.k:
            self.solve_times.append(window.solve_seconds)
        return window

    def solve(self, sigma: float, k: int) -> Window:
        """Solve one window now (``k = 0``: only factorise and count)."""
        return self.take(self.pool.submit(sigma, k))

    def accept(self, window: Window, lo: float, hi: float) -> None:
        inside = _between(window.lam, lo, min(hi, self.limit))
        if np.any(inside):
            self.lam.append(window.lam[inside])
            self.phi.append(window.phi[:, inside])
            self.residual.append(window.residual[inside])

    def retry(self, window: Window, a: float, b: float, counted: int) -> Window:
        """Solve ``window`` again with more modes (at the same shift, unless it sits on one)."""
        self.retries += 1
        if self.retries > 20:
            raise ModalError(f'spectrum slicing could not fill window [{a:.6g}, {b:.6g}) '
                             f'rad^2/s^2: Sturm count {counted}')
        k = int(window.k * 1.5) + 5
        sigma = window.sigma
        near = np.abs(window.lam - sigma) < 1e-7 * abs(sigma)
        if np.any(near):   # the shift sits on an eigenvalue: its count is unreliable, move it
            j = int(np.flatnonzero(near)[-1])
            above = window.lam[j + 1] if j + 1 < window.lam.size else window.lam[j] * 1.01
            sigma = 0.5 * (window.lam[j] + above)
        return self.solve(sigma, k)


def _launch(sl: Slicer, prev: Window, below: int, cut: float, wanted: int | None,
            lam_max: float | None) -> None:
    """
    Keep as many windows above ``prev`` in the pool as it has processes.

    ``below`` modes lie below ``cut`` (Sturm count plus the modes of ``prev``). The next
    window is placed above ``cut`` and always started; each later one above the predicted
    edge of the window before it, and only while the modes predicted below it are fewer than
    ``wanted`` and that edge is below ``lam_max``.
    """
    while len(sl.ahead) < sl.pool.workers:
        edge, skip = cut, 0
        if sl.ahead:
            _, last_target, last_sigma = sl.ahead[-1]
            edge = _edge_above(prev.lam, last_sigma, last_target)
            skip = sum(target for _, target, _ in sl.ahead)
            if wanted is not None and below + skip >= wanted:
                return
            if lam_max is not None and edge >= lam_max:
                return
        target = sl.per_window
        if lam_max is not None and sl.share_last:   # sized to the modes left below lam_max
            left = _modes_left(prev.lam, edge, lam_max)
            target = left if left <= LAST_WINDOW_STRETCH * target else \
                math.ceil(left / math.ceil(left / target))     # the rest in equal windows
        if wanted is not None:   # the last window asks only for what is still missing
            target = max(4, min(target, wanted - below - skip + 2))
        sigma = _next_shift(prev.lam, edge, target)
        sl.ahead.append((sl.pool.submit(sigma, int(WINDOW_PAD * target)), target, sigma))


def _next_window(sl: Slicer, prev: Window, below: int, cut: float, wanted: int | None,
                 lam_max: float | None) -> Window:
    """The lowest window above ``cut``: solved ahead, or now if those ahead lie below it."""
    while True:
        _launch(sl, prev, below, cut, wanted, lam_max)
        future, _, _ = sl.ahead.popleft()
        window = sl.take(future)
        if window.sigma > cut:
            return window
        sl.unused += 1   # extrapolated too low: below where it should continue


def _edge_below(window: Window, top: float) -> float:
    """An edge just below ``top`` and above every mode of ``window`` that lies below it."""
    below = window.lam[window.lam < top * (1.0 - 1e-6)]   # the same mode found twice: above
    return 0.5 * (max(float(below[-1]) if below.size else window.sigma, window.sigma) + top)


def _interval(sl: Slicer, prev: Window, lo: float, c_lo: int, cut: float,
              run: Window) -> Window:
    """
    Accept every mode in [lo, the shift of ``run``) from ``prev`` and ``run``.

    Modes in [lo, cut) come from ``prev`` and those in [cut, shift) from ``run``; their
    number must equal the Sturm count at the shift minus ``c_lo`` (both from the windows'
    own factorisations). On a mismatch where ``run`` does not reach down to ``cut`` (its
    shift was extrapolated too high), a window is solved in the gap for the modes missing
    there, and both intervals are checked in turn; on any other mismatch ``run`` is solved
    for more modes. Once ``run`` reaches below ``lo`` it supplies the whole interval.
    Returns the window that ends the interval (``run``, or ``run`` solved again).
    """
    while True:
        sigma, counted = run.sigma, run.count - c_lo
        if run.lam.size and run.lam[0] < lo:
            cut = lo
        found = _n_in(prev, lo, cut) + _n_in(run, cut, sigma)
        if found == counted and cut < sigma:
            sl.accept(prev, lo, cut)
            sl.accept(run, cut, sigma)
            return run
        _LOG.debug('window at %.6g rad^2/s^2 holds %d of the %d modes in [%.6g, %.6g) with '
                   'its neighbour below (lowest %.6g, cut %.6g)', sigma, found, counted, lo,
                   sigma, run.lam[0] if run.lam.size else math.nan, cut)
        if run.lam.size and cut < run.lam[0] < sigma and found < counted:
            # the gap [cut, lowest mode of run) holds the missing modes: a window there costs
            # them, solving run again 1.5 times its modes (609 at 763k DOF, 5 minutes)
            sl.gaps += 1
            if sl.gaps > 20:
                raise ModalError(f'spectrum slicing could not fill window [{lo:.6g}, '
                                 f'{sigma:.6g}) rad^2/s^2: Sturm count {counted}')
            gap = sl.solve(0.5 * (cut + float(run.lam[0])),
                           int(WINDOW_PAD * (counted - found)) + 8)
            sl.windows += 1
            gap = _interval(sl, prev, lo, c_lo, cut, gap)
            return _interval(sl, gap, gap.sigma, gap.count, _edge_below(gap, float(run.lam[0])),
                             run)
        run = sl.retry(run, lo, sigma, counted)


def slice_spectrum(sl: Slicer, wanted: int | None, lam_max: float | None) -> None:
    """Collect all eigenpairs below lam_max (if given) and at least ``wanted`` of them."""
    K, M = sl.pool.K, sl.pool.M
    scale = abs(K.diagonal()).max() / abs(M.diagonal()).max()
    prev = sl.solve(-1e-9 * scale, sl.per_window + 1)   # K may be only semi-definite
    sl.windows = 1
    lo, c_lo = prev.sigma, prev.count
    limit = math.inf if lam_max is None else lam_max
    while True:
        done_by_limit = prev.lam[-1] >= limit
        cut = limit if done_by_limit else _edge_between(prev.lam, prev.lam.size - 1)
        below = c_lo + _n_in(prev, lo, cut)
        if done_by_limit or (wanted is not None and below >= wanted):
            end = sl.solve(cut, 0)               # the last edge: a count-only factorisation
            if end.count - c_lo == _n_in(prev, lo, cut):
                sl.accept(prev, lo, cut)
                sl.final = end
                sl.unused += len(sl.ahead)
                sl.report(end.count, wanted, f'last window: {end.count - c_lo} modes up to '
                          f'{math.sqrt(cut) / 2 / math.pi:.4g} Hz, {end.count} below (Sturm)')
                return
            prev = sl.retry(prev, lo, cut, end.count - c_lo)
            continue
        sl.windows += 1
        run = _interval(sl, prev, lo, c_lo, cut,
                        _next_window(sl, prev, below, cut, wanted, lam_max))
        lo, c_lo = run.sigma, run.count
        sl.report(c_lo, wanted, f'window {sl.windows}: modes up to '
                  f'{math.sqrt(max(lo, 0)) / 2 / math.pi:.4g} Hz, {c_lo} below (Sturm)')
        prev = run
        if (wanted is not None and c_lo >= wanted) or lo >= limit:
            sl.unused += len(sl.ahead)
            return
