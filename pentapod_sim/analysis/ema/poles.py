"""
Experimental modal analysis: poles by poly-reference LSCF, stability diagram, pole selection.

Chain: FRFs ``H[o, i, k]`` (output o, input i, frequency k) in a band ->
:func:`plscf` poles for every model order -> :func:`stability_diagram` classes ->
:func:`select_poles` (automatic, for the non-interactive CLI) -> residues by LSFD
(:mod:`pentapod_sim.analysis.ema.lsfd`). :func:`identify_modes` runs the chain.

pLSCF (Peeters, Van der Auweraer, Guillaume, Leuridan, Shock Vib. 11 (2004) 395-409): a right
matrix-fraction model ``H_o(w) = B_o(z) A(z)^-1`` with ``z = exp(j w dt_m)``,
``dt_m = 1 / (2 f_max)`` of the band, matrix polynomial ``A(z) = sum_p z^p alpha_p`` of order n
(``alpha_n = I``, so the poles are the eigenvalues of its block companion matrix and the
eigenvectors' first block holds the participation factors). The numerator coefficients are
eliminated from the (real-valued) normal equations, so every order costs only a small solve;
orders 1..n_max reuse one set of matrices. Each output row is weighted by ``1 / sigma_o`` (noise
standard deviation per line if known, floored at 1e-3 of its median and 1e-8 of the row's RMS
so that a noise-free record gets even weights; else ``1 / RMS`` of the row over the band).

Stability (order n against order n-1; nearest pole in frequency): ``f`` if the frequency moves
less than ``tol_freq`` (relative), ``d`` if the damping ratio also moves less than
``tol_damping`` (relative), ``s`` if in addition ``1 - MAC`` of the participation factors is
below ``tol_mac`` (with one input the factors are scalars and this test always passes), ``o``
otherwise. Only poles in the band with 0 < zeta < ``max_damping`` are kept.

Automatic selection (:func:`select_poles`): the ``s`` poles are followed from the highest
order down. Each order's poles are matched one to one with the modes found so far (a mode's
last pole within ``tol_freq`` in frequency; nearest first by the frequency and damping
distance normalised by ``tol_freq`` and ``tol_damping``), and a pole left unmatched starts a
mode. A mode whose ``s`` poles come from at least ``min_stable`` different orders, and from at
least ``min_stable_fraction`` times as many orders as the best-supported mode, is physical
(spurious poles of an over-fitted noise model stay stable over a few orders only). Its pole
is the member closest to the median frequency and damping (distance normalised by the
tolerances) of its members; with ``upper_orders``, of its members from the upper half of its
orders: on a noise-free record a pole that the lower orders fit next to other modes' drifts
there and converges at the higher orders (the study's recorded runs), while with noise the
higher orders fit the noise too and the median over all orders is steadier (2 % noise on
the calibration test's FRFs: 6 % damping error on one mode from the upper half, within 5 %
from all orders). Two poles of one
order are never one mode: two modes closer than ``tol_freq`` whose half-power bands overlap
are resolved at the higher orders as two poles, while the lower orders fit one pole between
them, and chaining all poles by frequency (``one_per_order`` False, the selection before
2026-12; median over all its members) merged both into one cluster whose median lay between
them (P2's feed drives: 26.67 Hz at 2.3 % and 26.83 Hz at 0.9 % identified as one pole,
26.73 Hz at 0.96 %).
"""
from __future__ import annotations

import dataclasses
from typing import Optional, Sequence

import numpy as np
import numpy.typing as npt

CLASSES = ('o', 'f', 'd', 's')


@dataclasses.dataclass
class Tolerances:
    """Stability tolerances and selection settings (see the module docstring)."""

    tol_freq: float = 0.005
    tol_damping: float = 0.05
    tol_mac: float = 0.02
    max_damping: float = 0.2
    min_stable: int = 8
    min_stable_fraction: float = 0.3
    one_per_order: bool = True
    upper_orders: bool = False


@dataclasses.dataclass
class OrderPoles:
    """Poles of one model order in the band: pole [rad/s], f [Hz], zeta [-], class, factors."""

    order: int
    poles: np.ndarray
    freq: np.ndarray
    damping: np.ndarray
    factors: np.ndarray
    classes: Optional[np.ndarray] = None


def pole_frequency_damping(poles: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """Natural frequency [Hz] and damping ratio [-] of continuous poles ``s`` [rad/s]."""
    poles = np.asarray(poles, dtype=complex)
    wn = np.abs(poles)
    with np.errstate(divide='ignore', invalid='ignore'):
        return wn / (2 * np.pi), np.where(wn > 0, -poles.real / wn, np.nan)


def plscf(freq: npt.ArrayLike, H: npt.ArrayLike, orders: Sequence[int],
          sigma: Optional[npt.ArrayLike] = None, max_damping: float = 0.2
          ) -> list[OrderPoles]:
    """
    Poles of the (poly-reference) least-squares complex frequency-domain estimator.

    Parameters
    ----------
    freq : (F,) array_like
        Frequencies [Hz] of the FRF lines (any spacing), all inside the analysed band.
    H : (No, Ni, F) array_like
        FRFs (output o, input i). A (F,) or (No, F) array is one input.
    orders : sequence of int
        Model orders n >= 1 (poles per order: n * Ni).
    sigma : (No, Ni, F) or (No, F) array_like, optional
        Noise standard deviation per line (weights ``1 / sigma`` per output row).
    max_damping : float
        Poles with damping ratio outside (0, max_damping) are dropped.

    Returns
    -------
    list of OrderPoles
        One entry per order, poles with f in [freq.min(), freq.max()] sorted by frequency.
    """
    freq = np.asarray(freq, dtype=float)
    H = as_frf_array(H, len(freq))
    n_out, n_in, _ = H.shape
    n_max = int(max(orders))
    dt_m = 0.5 / freq.max()
    powers = np.exp(1j * 2 * np.pi * freq[:, None] * dt_m * np.arange(n_max + 1)[None, :])
    weights = _weights(H, sigma)
    size = (n_max + 1) * n_in
    big_r = np.zeros((n_out, n_max + 1, n_max + 1))
    big_s = np.zeros((n_out, n_max + 1, size))
    big_t = np.zeros((n_out, size, size))
    for o in range(n_out):
        gamma = weights[o][:, None] * powers  # (F, n+1); one weight per output row and line
        upsilon = -(gamma[:, :, None] * H[o].T[:, None, :]).reshape(len(freq), size)
        big_r[o] = np.real(gamma.conj().T @ gamma)
        big_s[o] = np.real(gamma.conj().T @ upsilon)
        big_t[o] = np.real(upsilon.conj().T @ upsilon)
    band = (freq.min(), freq.max())
    result = []
    for n in orders:
        k = (n + 1) * n_in
        m = np.zeros((k, k))
        for o in range(n_out):
            r, s = big_r[o, :n + 1, :n + 1], big_s[o, :n + 1, :k]
            m += big_t[o, :k, :k] - s.T @ np.linalg.solve(r, s)
        result.append(_order_poles(m, n, n_in, dt_m, band, max_damping))
    return result


def as_frf_array(H: npt.ArrayLike, n_freq: int) -> np.ndarray:
    """Return H as a complex (No, Ni, F) array; (F,) and (No, F) mean one input."""
    H = np.asarray(H, dtype=complex)
    if H.ndim == 1:
        H = H[None, None, :]
    elif H.ndim == 2:
        H = H[:, None, :]
    if H.ndim != 3 or H.shape[2] != n_freq:
        raise ValueError(f'FRF array of shape {H.shape} does not match {n_freq} frequencies')
    return H


def _weights(H: np.ndarray, sigma: Optional[npt.ArrayLike]) -> np.ndarray:
    """Weight per output and line (F,) from the noise std, or 1/RMS of the output's FRFs."""
    rms = np.maximum(np.sqrt(np.mean(np.abs(H) ** 2, axis=(1, 2))), 1e-300)[:, None]
    if sigma is None:
        return np.repeat(1.0 / rms, H.shape[2], axis=1)
    sig = np.sqrt(np.sum(as_frf_array(sigma, H.shape[2]).real ** 2, axis=1))
    # floor: 1e-3 of the median noise, and 1e-8 of the FRF level (noise-free records)
    floor = np.maximum(1e-3 * np.median(sig, axis=1, keepdims=True), 1e-8 * rms)
    return 1.0 / np.maximum(sig, floor)


def _order_poles(m: np.ndarray, n: int, n_in: int, dt_m: float, band: tuple[float, float],
                 max_damping: float) -> OrderPoles:
    k = n * n_in
    alpha = np.vstack([-np.linalg.lstsq(m[:k, :k], m[:k, k:], rcond=None)[0],
                       np.eye(n_in)])  # ((n+1) Ni, Ni), alpha_n = I
    companion = np.zeros((k, k))
    companion[:k - n_in, n_in:] = np.eye(k - n_in)
    for p in range(n):  # last block row: -alpha_p^T
        companion[k - n_in:, p * n_in:(p + 1) * n_in] = -alpha[p * n_in:(p + 1) * n_in].T
    z, vectors = np.linalg.eig(companion)
    with np.errstate(divide='ignore', invalid='ignore'):
        poles = np.log(z.astype(complex)) / dt_m
    f, zeta = pole_frequency_damping(poles)
    keep = (poles.imag > 0) & (zeta > 0) & (zeta < max_damping) & (f >= band[0]) \
        & (f <= band[1])
    order = np.argsort(f[keep])
    factors = vectors[:n_in][:, keep][:, order].T  # (poles, Ni)
    return OrderPoles(n, poles[keep][order], f[keep][order], zeta[keep][order], factors)


def _mac(a: np.ndarray, b: np.ndarray) -> float:
    return float(abs(np.vdot(a, b)) ** 2 / max(np.vdot(a, a).real * np.vdot(b, b).real, 1e-300))


def stability_diagram(orders: list[OrderPoles], tol: Tolerances = Tolerances()
                      ) -> list[OrderPoles]:
    """
    Label every pole of every order 'o', 'f', 'd' or 's' against the previous order.

    Parameters
    ----------
    orders : list of OrderPoles
        From :func:`plscf`, ascending order.
    tol : Tolerances
        Stability tolerances.

    Returns
    -------
    list of OrderPoles
        The same objects with ``classes`` set.
    """
    previous: Optional[OrderPoles] = None
    for entry in orders:
        classes = np.full(len(entry.poles), 'o')
        if previous is not None and len(previous.poles):
            for j, (f, zeta) in enumerate(zip(entry.freq, entry.damping)):
                i = int(np.argmin(np.abs(previous.freq - f)))
                if abs(previous.freq[i] - f) >= tol.tol_freq * f:
                    continue
                classes[j] = 'f'
                if abs(previous.damping[i] - zeta) >= tol.tol_damping * zeta:
                    continue
                classes[j] = 'd'
                if 1.0 - _mac(entry.factors[j], previous.factors[i]) < tol.tol_mac:
                    classes[j] = 's'
        entry.classes = classes
        previous = entry
    return orders


def select_poles(orders: Sequence[OrderPoles], tol: Tolerances = Tolerances()) -> np.ndarray:
    """
    Pick the physical poles from a labelled stability diagram (module docstring).

    Parameters
    ----------
    orders : list of OrderPoles
        With ``classes`` set by :func:`stability_diagram`.
    tol : Tolerances
        ``tol_freq`` (a mode's width), ``tol_damping``, ``min_stable``,
        ``min_stable_fraction``, ``one_per_order`` (follow the orders, at most one pole of
        an order per mode; False: chain all poles by frequency) and ``upper_orders`` (a
        followed mode's pole from the upper half of its orders) are used.

    Returns
    -------
    (R,) complex ndarray
        Selected poles [rad/s] (positive imaginary part), sorted by frequency; may be empty.

    Raises
    ------
    ValueError
        If an order has no classes (:func:`stability_diagram` was not run on it).
    """
    for e in orders:
        if e.classes is None:
            raise ValueError(f'order {e.order} has no pole classes; label the orders with '
                             'stability_diagram() first')
    clusters = _follow_orders(orders, tol) if tol.one_per_order else _chain(orders, tol)
    support = [len({row[2] for row in cluster}) for cluster in clusters]
    needed = max([tol.min_stable] + [tol.min_stable_fraction * max(support, default=0)])
    selected = []
    for cluster, count in zip(clusters, support):
        if count < needed:
            continue
        if tol.one_per_order and tol.upper_orders:  # the upper half of the mode's orders
            low = np.median([row[2] for row in cluster])
            cluster = [row for row in cluster if row[2] >= low]
        f_med = np.median([row[0] for row in cluster])
        z_med = np.median([row[1] for row in cluster])
        dist = [((row[0] - f_med) / (tol.tol_freq * f_med)) ** 2
                + ((row[1] - z_med) / (tol.tol_damping * z_med)) ** 2 for row in cluster]
        selected.append(cluster[int(np.argmin(dist))])
    selected.sort(key=lambda row: row[0])
    return np.array([row[3] for row in selected], dtype=complex)


#: A stable pole: (frequency [Hz], damping ratio [-], model order, pole [rad/s]).
_Row = tuple[float, float, int, complex]


def _stable_rows(entry: OrderPoles) -> list[_Row]:
    classes = entry.classes if entry.classes is not None else np.full(len(entry.poles), 'o')
    return [(f, z, entry.order, p) for f, z, p, c in
            zip(entry.freq, entry.damping, entry.poles, classes) if c == 's']


def _follow_orders(orders: Sequence[OrderPoles], tol: Tolerances) -> list[list[_Row]]:
    """Modes as chains of stable poles, highest order first, at most one pole per order."""
    clusters: list[list[_Row]] = []
    for entry in sorted(orders, key=lambda e: e.order, reverse=True):
        rows = _stable_rows(entry)
        if not rows:
            continue
        f = np.array([row[0] for row in rows])
        z = np.array([row[1] for row in rows])
        if clusters:
            f_last = np.array([c[-1][0] for c in clusters])
            z_last = np.array([c[-1][1] for c in clusters])
            df = (f[:, None] - f_last[None, :]) / (tol.tol_freq * f[:, None])
            dz = (z[:, None] - z_last[None, :]) / (tol.tol_damping * z[:, None])
            dist = np.where(np.abs(df) < 1.0, df ** 2 + dz ** 2, np.inf)
        else:
            dist = np.full((len(rows), 0), np.inf)
        free_rows, free_clusters = set(range(len(rows))), set(range(len(clusters)))
        for flat in np.argsort(dist, axis=None):
            j, c = np.unravel_index(flat, dist.shape)
            if not np.isfinite(dist[j, c]):
                break
            if j in free_rows and c in free_clusters:
                clusters[c].append(rows[j])
                free_rows.discard(j)
                free_clusters.discard(c)
        clusters += [[rows[j]] for j in sorted(free_rows)]
    return clusters


def _chain(orders: Sequence[OrderPoles], tol: Tolerances) -> list[list[_Row]]:
    """All stable poles sorted by frequency, chained where neighbours lie within tol_freq."""
    rows = [row for e in orders for row in _stable_rows(e)]
    rows.sort(key=lambda row: row[0])
    clusters: list[list[_Row]] = []
    current: list[_Row] = []
    for row in rows:
        if current and row[0] - current[-1][0] >= tol.tol_freq * row[0]:
            clusters.append(current)
            current = []
        current.append(row)
    if current:
        clusters.append(current)
    return clusters
