"""
Mode selection by dc gain, static error and static correction of a modal plant.

The dc gain of mode i from input k to output j is ``c_ji b_ik / omega_i^2`` (unit of the
compliance, e.g. m/N). A mode is kept if, for any input/output pair considered, its absolute
dc gain reaches an absolute limit, its share of the pair's summed absolute dc gains reaches a
relative limit, or it is among the ``count`` most relevant modes. The static error compares
the reduced static gain with the exact compliance ``C K^-1 B`` of the full FE model (a sparse
solve, not a modal sum); the static correction adds the dropped modes' residual flexibility as
feed-through.
"""
from __future__ import annotations

from dataclasses import dataclass
import logging
import warnings

import numpy as np
import numpy.typing as npt
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from pentapod_sim.errors import ConfigError

LOG = logging.getLogger(__name__)


def modal_dc_gains(omega: npt.ArrayLike, b: npt.ArrayLike,
                   c: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """
    Dc gain of every mode for every output/input pair.

    Parameters
    ----------
    omega : (m,) array_like
        Natural angular frequencies [rad/s], all > 0.
    b : (m, n_in) array_like
        Modal input matrix ``Phi^T B``.
    c : (n_out, m) array_like
        Modal displacement output matrix ``C Phi``.

    Returns
    -------
    (m, n_out, n_in) ndarray
        ``g[i, j, k] = c[j, i] b[i, k] / omega_i^2`` (e.g. m/N for TCP force -> displacement).
    """
    omega = np.asarray(omega, dtype=float)
    if np.any(omega <= 0):
        raise ConfigError(f'dc gains need omega > 0; mode(s) {np.flatnonzero(omega <= 0) + 1} '
                          'are rigid-body modes')
    return np.einsum('ji,ik->ijk', np.asarray(c, float), np.asarray(b, float)) \
        / (omega ** 2)[:, None, None]


def modal_resonance_gains(omega: npt.ArrayLike, zeta: npt.ArrayLike, b: npt.ArrayLike,
                          c: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """
    Peak gain of every mode at its resonance, ``c_ji b_ik / (2 zeta_i omega_i^2)``.

    The dc gain ranks modes correctly only when all share one damping ratio; with individual
    ratios the single-mode resonance gain is the measure to compare. Same shapes as
    :func:`modal_dc_gains`; zeta (m,) > 0.
    """
    zeta = np.broadcast_to(np.asarray(zeta, float), np.shape(omega))
    if np.any(zeta <= 0):
        raise ConfigError(f'resonance gains need zeta > 0; got min zeta {zeta.min()}')
    return modal_dc_gains(omega, b, c) / (2 * zeta)[:, None, None]


def _check_limit(name: str, value: object, upper: float = np.inf) -> None:
    """ConfigError unless 0 < value < upper (finite number)."""
    if not isinstance(value, (int, float, np.floating, np.integer)) or isinstance(value, bool) \
            or not np.isfinite(value) or value <= 0 or value >= upper:
        raise ConfigError(f'{name} must be a number in (0, {upper}), got {value!r}')


def select_modes(gains: npt.ArrayLike, abs_limit: float | None = None,
                 rel_limit: float | None = None, count: int | None = None
                 ) -> npt.NDArray[np.intp]:
    """
    Indices of the relevant modes (ascending), by exactly one criterion.

    Parameters
    ----------
    gains : (m, n_out, n_in) or (m,) array_like
        Modal dc gains of the pairs that decide relevance (see :func:`modal_dc_gains`).
    abs_limit : float, optional
        Keep mode i if ``|g_i| >= abs_limit`` for any pair (unit of the gains; the paper
        uses 5e-8 for TCP yy).
    rel_limit : float, optional
        Keep mode i if ``|g_i| / sum_k |g_k| >= rel_limit`` for any pair, 0 < rel_limit < 1.
    count : int, optional
        Keep the ``count`` modes with the largest relative dc gain (max over pairs).

    Raises
    ------
    ConfigError
        If not exactly one criterion is given or its value is out of range.
    """
    given = {k: v for k, v in (('abs_limit', abs_limit), ('rel_limit', rel_limit),
                               ('count', count)) if v is not None}
    if len(given) != 1:
        raise ConfigError(f'give exactly one of abs_limit, rel_limit, count; got {given}')
    g = np.abs(np.asarray(gains, dtype=float))
    g = g.reshape(g.shape[0], -1)
    m = g.shape[0]
    if abs_limit is not None:
        _check_limit('abs_limit', abs_limit)
        keep = np.flatnonzero(np.any(g >= abs_limit, axis=1))
    else:
        total = g.sum(axis=0)
        share = np.max(g / np.where(total > 0, total, 1.0), axis=1)
        if rel_limit is not None:
            _check_limit('rel_limit', rel_limit, 1.0)
            keep = np.flatnonzero(share >= rel_limit)
        else:
            if isinstance(count, bool) or not isinstance(count, (int, np.integer)) \
                    or not 1 <= count <= m:
                raise ConfigError(f'count must be an integer in [1, {m}], got {count!r}')
            keep = np.sort(np.argsort(-share, kind='stable')[:count])
    if keep.size == 0:
        warnings.warn(f'no mode passes the relevance criterion {given}', stacklevel=2)
    return keep


def static_compliance(K: sp.spmatrix, B: npt.ArrayLike,
                      C: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """
    Exact static gain ``C K^-1 B`` of the full FE model by one sparse LU factorisation.

    Parameters
    ----------
    K : (n, n) sparse matrix
        Stiffness matrix (positive definite after supports).
    B : (n, n_in) array_like
        Load vectors of the inputs.
    C : (n_out, n) array_like
        Displacement observation rows of the outputs.

    Returns
    -------
    (n_out, n_in) ndarray
    """
    lu = spla.splu(sp.csc_matrix(K))
    return np.asarray(C, float) @ lu.solve(np.asarray(B, float))


def static_error_percent(g_reduced: npt.ArrayLike, g_full: npt.ArrayLike
                         ) -> npt.NDArray[np.float64]:
    """Signed static error ``(G_red - G) / G * 100`` [%] per pair; NaN where G == 0."""
    g_reduced, g_full = np.asarray(g_reduced, float), np.asarray(g_full, float)
    with np.errstate(divide='ignore', invalid='ignore'):
        return np.where(g_full != 0, (g_reduced - g_full) / g_full * 100.0, np.nan)


@dataclass(frozen=True)
class ReductionResult:
    """
    Outcome of a mode selection.

    Attributes
    ----------
    keep : (r,) ndarray of int
        Indices of the kept modes into the computed modes.
    gains : (m, n_out, n_in) ndarray
        Modal dc gains of all computed modes.
    g_full : (n_out, n_in) ndarray
        Exact static compliance of the full FE model (or of all modes if no K was given).
    g_reduced : (n_out, n_in) ndarray
        Static gain of the kept modes alone.
    residual : (n_out, n_in) ndarray
        Static correction ``g_full - g_reduced`` (the feed-through D).
    error_percent, error_corrected_percent : (n_out, n_in) ndarray
        Static error without and with the static correction [%]. The corrected error is
        round-off only when ``g_full`` is exact.
    """

    keep: npt.NDArray[np.intp]
    gains: npt.NDArray[np.float64]
    g_full: npt.NDArray[np.float64]
    g_reduced: npt.NDArray[np.float64]
    residual: npt.NDArray[np.float64]
    error_percent: npt.NDArray[np.float64]
    error_corrected_percent: npt.NDArray[np.float64]


def reduce_modes(omega: npt.ArrayLike, b: npt.ArrayLike, c: npt.ArrayLike,
                 g_full: npt.ArrayLike | None = None, *, abs_limit: float | None = None,
                 rel_limit: float | None = None, count: int | None = None) -> ReductionResult:
    """
    Select modes by dc gain and evaluate the static error.

    Parameters
    ----------
    omega, b, c
        As in :func:`modal_dc_gains` (c: displacement outputs).
    g_full : (n_out, n_in) array_like, optional
        Exact static compliance (:func:`static_compliance`); default the sum over all
        given modes, which ignores modes that were never computed.
    abs_limit, rel_limit, count
        Exactly one of them (:func:`select_modes`).
    """
    gains = modal_dc_gains(omega, b, c)
    keep = select_modes(gains, abs_limit, rel_limit, count)
    criterion = {k: v for k, v in (('abs_limit', abs_limit), ('rel_limit', rel_limit),
                                   ('count', count)) if v is not None}
    g_red = gains[keep].sum(axis=0)
    if g_full is None:
        g_full = gains.sum(axis=0)
    g_exact = np.asarray(g_full, float)
    residual = g_exact - g_red
    g_corr = g_red + residual
    LOG.info('kept %d of %d modes (%s)', keep.size, gains.shape[0], criterion)
    return ReductionResult(keep, gains, g_exact, g_red, residual,
                           static_error_percent(g_red, g_exact),
                           static_error_percent(g_corr, g_exact))


def harmonic_response(K: sp.spmatrix, M: sp.spmatrix, B: npt.ArrayLike, C: npt.ArrayLike,
                      freq_hz: npt.ArrayLike, damping: sp.spmatrix | npt.ArrayLike | None = None,
                      ) -> npt.NDArray[np.complex128]:
    """
    Direct harmonic solve of the full FE model, ``C (K - w^2 M + i w C_d)^-1 B``.

    Parameters
    ----------
    K, M : (n, n) sparse matrix
        Stiffness [N/m] and mass [kg] matrices.
    B : (n, n_in) array_like
        Load vectors.
    C : (n_out, n) array_like
        Displacement observation rows.
    freq_hz : (n_f,) array_like
        Frequencies [Hz]; with ``damping=None`` they must avoid the resonances.
    damping : (n, n) matrix, optional
        Viscous damping matrix [N s/m]; default undamped.

    Returns
    -------
    (n_out, n_in, n_f) complex ndarray
        Dynamic compliance (e.g. m/N).
    """
    B, C = np.asarray(B, float), np.asarray(C, float)
    freq_hz = np.atleast_1d(np.asarray(freq_hz, float))
    out = np.empty((C.shape[0], B.shape[1], freq_hz.size), dtype=complex)
    for n, f in enumerate(freq_hz):
        w = 2 * np.pi * f
        dyn = sp.csc_matrix(K - w ** 2 * M, dtype=complex)
        if damping is not None:
            dyn = dyn + 1j * w * (sp.csc_matrix(damping) if sp.issparse(damping)
                                  else sp.csc_matrix(np.asarray(damping)))
        out[:, :, n] = C @ spla.splu(sp.csc_matrix(dyn)).solve(B.astype(complex))
    return out


def frf_error_percent(h_reduced: npt.ArrayLike, h_reference: npt.ArrayLike
                      ) -> npt.NDArray[np.float64]:
    """
    Frequency-domain error per pair: ``max_f |H_red - H_ref| / max_f |H_ref| * 100`` [%].

    Parameters
    ----------
    h_reduced, h_reference : (n_out, n_in, n_f) array_like
        FRFs on the same frequency grid.
    """
    h_reduced, h_reference = np.asarray(h_reduced), np.asarray(h_reference)
    peak = np.max(np.abs(h_reference), axis=-1)
    with np.errstate(divide='ignore', invalid='ignore'):
        return np.where(peak > 0, np.max(np.abs(h_reduced - h_reference), axis=-1) / peak * 100,
                        np.nan)


def frf_relative_error_percent(h_reduced: npt.ArrayLike,
                               h_reference: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """
    Pointwise relative FRF error ``|H_red - H_ref| / |H_ref| * 100`` [%], shape of the inputs.

    Large near anti-resonances of the reference; summarise it with a median or percentile.
    """
    h_reduced, h_reference = np.asarray(h_reduced), np.asarray(h_reference)
    with np.errstate(divide='ignore', invalid='ignore'):
        return np.abs(h_reduced - h_reference) / np.abs(h_reference) * 100


def between_resonances(freq_hz: npt.ArrayLike, f_max: float) -> npt.NDArray[np.float64]:
    """Midpoints [Hz] between consecutive natural frequencies below ``f_max`` [Hz]."""
    freq = np.sort(np.asarray(freq_hz, float))
    freq = freq[freq < f_max]
    return 0.5 * (freq[:-1] + freq[1:])
