"""
Stability lobes from a TCP FRF: turning (Tlusty) and the zero-order milling solution.

Both reduce to an eigenvalue ``Lambda(w_c)`` per chatter frequency w_c and a process gain c:
the limiting depth is ``b_lim = -|Lambda|^2 / (2 c Re Lambda)`` where ``Re Lambda < 0`` (no
chatter at w_c elsewhere), and the phase between the present and the previous tooth's
vibration is ``eps = (pi - 2 arg Lambda) mod 2 pi``; lobe k has the tooth period
``T = (eps + 2 pi k) / w_c`` and the spindle speed ``n = 60 / (N T)`` [rpm].

* Turning, or one direction (Tlusty): ``Lambda = 1 / G`` of the oriented FRF, ``c = K_f``;
  then ``b_lim = -1 / (2 K_f Re G)`` and ``eps = 3 pi + 2 arg G`` (mod 2 pi).
* Milling, zero-order solution (Altintas & Budak 1995): the roots of
  ``a0 Lambda^2 + a1 Lambda + 1 = 0`` with ``a0 = det([alpha] G)``, ``a1 = tr([alpha] G)``
  (the FRF matrix in the cutting frame, cross terms included), ``c = N K_t / (4 pi)``, so
  ``a_lim = -2 pi Lambda_R (1 + kappa^2) / (N K_t)``.

The zero-order solution keeps only the mean of the time-varying directional matrix; it fails
where that matrix is far from its mean: low radial immersion and few teeth (period-doubling
lobes it does not predict) and low speeds (process damping, not modelled anyway).
:mod:`pentapod_sim.machining.semi_discretisation` solves the time-periodic problem instead.

:meth:`StabilityLimit.envelope` is the lobe diagram: the lowest limiting depth over all lobes
and branches at each spindle speed, computed for all speeds at once (every grid interval and
lobe whose crossing falls in the speed range, rasterised onto the speed grid).
"""
from __future__ import annotations

from dataclasses import dataclass
import math

import numpy as np
import numpy.typing as npt

from pentapod_sim.errors import ConfigError
from pentapod_sim.machining.milling_cut import directional_factors, MillingCut
from pentapod_sim.machining.tcp_frf import TcpFrf

#: Relative change of the depth between the grid neighbours of the minimum above which the
#: frequency grid is called too coarse to resolve the minimum.
RESOLVED_STEP = 0.02


@dataclass(frozen=True)
class Minimum:
    """Smallest limiting depth over all chatter frequencies: the absolute stability limit."""

    depth: float
    freq_hz: float
    resolved: bool


@dataclass(frozen=True)
class LobeEnvelope:
    """
    Lobe diagram: the limiting depth at each spindle speed.

    Attributes
    ----------
    speed : (n_s,) ndarray
        Spindle speeds [rpm].
    depth : (n_s,) ndarray
        Limiting depth [m]; ``inf`` where no lobe of the frequency band crosses.
    chatter_freq : (n_s,) ndarray
        Chatter frequency at the limit [Hz] (nan where none).
    lobe : (n_s,) ndarray of int
        Lobe number k at the limit (-1 where none).
    label : str
        Legend text.
    """

    speed: np.ndarray
    depth: np.ndarray
    chatter_freq: np.ndarray
    lobe: np.ndarray
    label: str = ''

    def best_pocket(self) -> tuple[float, float]:
        """
        (speed [rpm], depth [m]) of the deepest stable pocket between two lobes.

        The highest local maximum inside the speed range; if the envelope has none (it rises
        to one end of the range), the highest point.
        """
        d = np.where(np.isfinite(self.depth), self.depth, np.nan)
        inner = np.flatnonzero((d[1:-1] >= d[:-2]) & (d[1:-1] > d[2:])) + 1
        pick = inner[np.nanargmax(d[inner])] if inner.size else int(np.nanargmax(d))
        return float(self.speed[pick]), float(d[pick])

    def lowest(self) -> tuple[float, float]:
        """(speed [rpm], depth [m]) of the lowest limiting depth in the speed range."""
        pick = int(np.argmin(self.depth))
        return float(self.speed[pick]), float(self.depth[pick])


@dataclass(frozen=True)
class StabilityLimit:
    """
    Limiting depth per chatter frequency, for each eigenvalue branch.

    Attributes
    ----------
    freq : (n_f,) ndarray
        Chatter frequencies [Hz].
    depth : (n_b, n_f) ndarray
        Limiting depth of cut [m]; nan where the branch cannot chatter (Re Lambda >= 0).
    phase : (n_b, n_f) ndarray
        ``eps`` in [0, 2 pi) [rad].
    teeth : int
        Tooth passes per revolution (1 in turning).
    label : str
        Legend text.
    """

    freq: np.ndarray
    depth: np.ndarray
    phase: np.ndarray
    teeth: int
    label: str = ''

    def minimum(self) -> Minimum:
        """
        The absolute stability limit: the smallest depth over every frequency and branch.

        ``resolved`` is False if the depth changes by more than :data:`RESOLVED_STEP` to a
        grid neighbour: the grid is too coarse there and the true minimum may be lower.
        """
        if not np.any(np.isfinite(self.depth)):
            return Minimum(math.inf, math.nan, True)
        b, i = np.unravel_index(np.nanargmin(self.depth), self.depth.shape)
        row = self.depth[b]
        near = [row[j] for j in (i - 1, i + 1) if 0 <= j < row.size]
        step = max((abs(v - row[i]) / row[i] if np.isfinite(v) else math.inf) for v in near)
        return Minimum(float(row[i]), float(self.freq[i]), bool(step <= RESOLVED_STEP))

    def lobe_speeds(self, lobe: int) -> npt.NDArray[np.float64]:
        """Spindle speed [rpm] of lobe ``k`` at every chatter frequency, shape (n_b, n_f)."""
        period = (self.phase + 2 * math.pi * lobe) / (2 * math.pi * self.freq)
        with np.errstate(divide='ignore'):
            return np.where(np.isfinite(self.depth), 60.0 / (self.teeth * period), np.nan)

    def envelope(self, speeds_rpm: npt.ArrayLike) -> LobeEnvelope:
        """
        Lowest limiting depth over all lobes and branches at each spindle speed.

        Parameters
        ----------
        speeds_rpm : array_like
            Increasing spindle speeds [rpm], > 0.
        """
        speed = np.asarray(speeds_rpm, dtype=float)
        if speed.ndim != 1 or speed.size < 1 or speed[0] <= 0 or np.any(np.diff(speed) <= 0):
            raise ConfigError('spindle speeds must be increasing and > 0 rpm')
        found = [_crossings(self.freq, a, eps, speed, self.teeth)
                 for a, eps in zip(self.depth, self.phase)]
        j = np.concatenate([c[0] for c in found])
        depth = np.concatenate([c[1] for c in found])
        freq = np.concatenate([c[2] for c in found])
        lobe = np.concatenate([c[3] for c in found])
        out_depth = np.full(speed.size, math.inf)
        out_freq = np.full(speed.size, math.nan)
        out_lobe = np.full(speed.size, -1)
        if j.size:
            order = np.lexsort((depth, j))
            first = np.unique(j[order], return_index=True)[1]
            pick = order[first]
            out_depth[j[pick]], out_freq[j[pick]], out_lobe[j[pick]] = (
                depth[pick], freq[pick], lobe[pick])
        return LobeEnvelope(speed, out_depth, out_freq, out_lobe, self.label)


def _repeat_ranges(starts: np.ndarray, counts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(owner index, start + offset) of every element of the ranges [start, start + count)."""
    owner = np.repeat(np.arange(counts.size), counts)
    offset = np.arange(owner.size) - np.repeat(np.cumsum(counts) - counts, counts)
    return owner, starts[owner] + offset


def _crossings(freq: np.ndarray, depth: np.ndarray, phase: np.ndarray, speed: np.ndarray,
               teeth: int) -> tuple[np.ndarray, ...]:
    """
    Every (speed index, depth, frequency, lobe) where a lobe of one branch crosses a speed.

    At a fixed tooth period T, ``g(w) = (w T - eps) / (2 pi)`` is interpolated linearly
    between grid neighbours with finite depth; each integer k >= 0 it passes is a crossing.
    Instead of scanning every speed, each (grid interval, lobe k) pair is mapped to the
    speeds it covers: the crossing periods at the interval's ends bound them.
    """
    w = 2 * math.pi * freq
    period = 60.0 / (teeth * speed)
    seg = np.flatnonzero(np.isfinite(depth[:-1]) & np.isfinite(depth[1:]))
    if seg.size == 0:
        return tuple(np.empty(0, dtype=t) for t in (int, float, float, int))
    w0, w1, e0, e1 = w[seg], w[seg + 1], phase[seg], phase[seg + 1]
    t_min, t_max = period.min(), period.max()
    k_lo = np.maximum(0, np.ceil(np.minimum(w0 * t_min - e0, w1 * t_min - e1) / (2 * math.pi)))
    k_hi = np.floor(np.maximum(w0 * t_max - e0, w1 * t_max - e1) / (2 * math.pi))
    counts = np.maximum(k_hi - k_lo + 1, 0).astype(int)
    owner, k = _repeat_ranges(k_lo.astype(int), counts)
    seg, w0, w1, e0, e1 = seg[owner], w0[owner], w1[owner], e0[owner], e1[owner]
    t_a = (e0 + 2 * math.pi * k) / w0                   # crossing period at each end
    t_b = (e1 + 2 * math.pi * k) / w1
    # speeds whose period lies between t_a and t_b (speed increases as the period falls)
    j_lo = np.searchsorted(speed, 60.0 / (teeth * np.maximum(t_a, t_b)))
    j_hi = np.searchsorted(speed, 60.0 / (teeth * np.minimum(t_a, t_b)), side='right')
    owner, j = _repeat_ranges(j_lo, np.maximum(j_hi - j_lo, 0))
    seg, k, w0, w1, t_a, t_b = seg[owner], k[owner], w0[owner], w1[owner], t_a[owner], t_b[owner]
    t = period[j]
    lead, lag = w0 * (t - t_a), w1 * (t - t_b)
    with np.errstate(invalid='ignore', divide='ignore'):
        frac = np.where(lead == lag, 0.0, lead / (lead - lag))
    frac = np.clip(frac, 0.0, 1.0)
    d = depth[seg] + frac * (depth[seg + 1] - depth[seg])
    f = freq[seg] + frac * (freq[seg + 1] - freq[seg])
    return j, d, f, k


def _limit(lam: np.ndarray, gain: float, freq: np.ndarray, teeth: int,
           label: str) -> StabilityLimit:
    """Depth and phase of eigenvalues ``lam`` (n_b, n_f) with process gain ``gain``."""
    with np.errstate(invalid='ignore', divide='ignore', over='ignore'):
        ok = np.isfinite(lam) & (lam.real < 0)
        safe = np.where(ok, lam, -1.0)
        depth = np.where(ok, -np.abs(safe) ** 2 / (2.0 * gain * safe.real), np.nan)
        phase = np.mod(math.pi - 2.0 * np.angle(safe), 2 * math.pi)
    return StabilityLimit(np.asarray(freq, float), depth, phase, teeth, label)


def turning_limit(frf: npt.ArrayLike, freq_hz: npt.ArrayLike, cutting_coefficient: float,
                  label: str = '') -> StabilityLimit:
    """
    Tlusty's limit of one direction: ``b_lim = -1 / (2 K_f Re G)`` where ``Re G < 0``.

    Parameters
    ----------
    frf : (n_f,) array_like
        Oriented FRF [m/N] (e.g. :meth:`TcpFrf.along`).
    freq_hz : (n_f,) array_like
        Frequencies [Hz].
    cutting_coefficient : float
        K_f [N/m^2]: cutting force per unit chip area.
    label : str
        Legend text.
    """
    g = np.asarray(frf, dtype=complex)
    if not (math.isfinite(cutting_coefficient) and cutting_coefficient > 0):
        raise ConfigError(f'cutting coefficient K_f = {cutting_coefficient!r} N/m^2 must be > 0')
    with np.errstate(divide='ignore', invalid='ignore'):
        lam = np.where(g != 0, 1.0 / np.where(g != 0, g, 1.0), np.nan)
    return _limit(lam[None, :], cutting_coefficient, np.asarray(freq_hz, float), 1, label)


def milling_eigenvalues(frf: TcpFrf, cut: MillingCut) -> npt.NDArray[np.complex128]:
    """
    Both roots of ``det(I + Lambda [alpha] G) = 0`` per frequency, shape (2, n_f).

    The square root of the discriminant is continued along the grid (its sign flipped where
    that keeps it continuous), so each branch is a continuous function of frequency.
    """
    g = frf.in_cutting_frame(cut.feed_angle)
    alpha = directional_factors(cut)
    a1 = np.einsum('ij,jif->f', alpha, g)
    a0 = np.linalg.det(alpha) * (g[0, 0] * g[1, 1] - g[0, 1] * g[1, 0])
    root = np.sqrt(a1 ** 2 - 4.0 * a0)
    flip = np.abs(root[1:] - root[:-1]) > np.abs(root[1:] + root[:-1])
    root *= np.concatenate([[1.0], np.cumprod(np.where(flip, -1.0, 1.0))])
    plus, minus = a1 + root, a1 - root
    tiny = 1e-9 * np.abs(a1)          # a0 ~ 0 (one flexible direction): that root is infinite
    with np.errstate(divide='ignore', invalid='ignore'):
        return np.stack([np.where(np.abs(plus) > tiny, -2.0 / plus, np.inf),
                         np.where(np.abs(minus) > tiny, -2.0 / minus, np.inf)])


def milling_limit(frf: TcpFrf, cut: MillingCut, label: str | None = None) -> StabilityLimit:
    """Zero-order (Altintas & Budak) limiting axial depth [m] per chatter frequency."""
    gain = cut.teeth * cut.tangential_coefficient / (4 * math.pi)
    return _limit(milling_eigenvalues(frf, cut), gain, frf.freq, cut.teeth,
                  frf.label if label is None else label)
