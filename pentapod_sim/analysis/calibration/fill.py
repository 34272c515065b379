"""
Damping of the modes no measurement pairs: a Rayleigh fit or per-band values.

Rayleigh: ``zeta(omega) = alpha / (2 omega) + beta omega / 2`` fitted to the paired modes by
non-negative least squares (``scipy.optimize.nnls``: negative coefficients would give negative
damping outside the fitted range). Bands: each band's median of the paired ratios; a band
without a paired mode gets the median of all.
"""
from __future__ import annotations

import numpy as np
import numpy.typing as npt
import scipy.optimize


def rayleigh_fit(omega: npt.ArrayLike, zeta: npt.ArrayLike) -> tuple[float, float]:
    """
    Non-negative ``(alpha [1/s], beta [s])`` of the Rayleigh law through ``(omega, zeta)``.

    Parameters
    ----------
    omega : (p,) array_like
        Angular natural frequencies [rad/s] of the paired modes, > 0.
    zeta : (p,) array_like
        Their damping ratios [-].
    """
    omega = np.asarray(omega, dtype=float)
    zeta = np.asarray(zeta, dtype=float)
    if omega.size == 0:
        raise ValueError('a Rayleigh fit needs at least one paired mode')
    design = np.column_stack([0.5 / omega, 0.5 * omega])
    scale = np.abs(design).max(axis=0)                  # columns of comparable size
    coef, _ = scipy.optimize.nnls(design / scale, zeta)
    alpha, beta = coef / scale
    return float(alpha), float(beta)


def band_values(freq_hz: npt.ArrayLike, zeta: npt.ArrayLike,
                edges_hz: npt.ArrayLike) -> list[tuple[float, float, float]]:
    """``(f_min, f_max, ratio)`` per band between consecutive ``edges_hz`` [Hz] (median fill)."""
    freq, zeta, edges = (np.asarray(v, dtype=float) for v in (freq_hz, zeta, edges_hz))
    if zeta.size == 0:
        raise ValueError('band values need at least one paired mode')
    if edges.size < 2 or np.any(np.diff(edges) <= 0):
        raise ValueError(f'band edges must be at least two ascending frequencies, got {edges}')
    out = []
    for lo, hi in zip(edges[:-1], edges[1:]):
        inside = (freq >= lo) & (freq < hi)
        out.append((float(lo), float(hi), float(np.median(zeta[inside] if inside.any()
                                                          else zeta))))
    return out
