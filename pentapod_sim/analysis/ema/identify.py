"""
Modal identification from FRFs in one call: pLSCF poles, automatic selection, LSFD residues.

:func:`identify_modes` is the entry point for the CLI (``analyze modes``) and the study; the
steps and the automatic pole selection are described in :mod:`pentapod_sim.analysis.ema.poles`
and :mod:`pentapod_sim.analysis.ema.lsfd`.
"""
from __future__ import annotations

import dataclasses
from typing import Optional, Sequence

import numpy as np
import numpy.typing as npt

from pentapod_sim.analysis.ema.lsfd import lsfd, refine_poles, ResidueFit
from pentapod_sim.analysis.ema.poles import (
    as_frf_array,
    OrderPoles,
    plscf,
    pole_frequency_damping,
    select_poles,
    stability_diagram,
    Tolerances,
)

#: Highest polynomial order (times the number of inputs) tried by default.
DEFAULT_MAX_ORDER = 60


@dataclasses.dataclass
class ModalModel:
    """
    Identified modes.

    Attributes
    ----------
    freq_hz : (R,) ndarray
        Natural frequencies [Hz] (undamped, ``|lambda| / 2 pi``).
    damping : (R,) ndarray
        Damping ratios [-] (``-Re lambda / |lambda|``).
    fit : ResidueFit
        Poles, residues, residuals; ``fit.modal_constants`` (No, Ni, R).
    diagram : list of OrderPoles
        Stability diagram (every order's poles with their class).
    band : (float, float)
        Analysed band [Hz].
    tol : Tolerances
        Tolerances used.
    """

    freq_hz: np.ndarray
    damping: np.ndarray
    fit: ResidueFit
    diagram: list[OrderPoles]
    band: tuple[float, float]
    tol: Tolerances

    @property
    def poles(self) -> np.ndarray:
        """Selected poles [rad/s]."""
        return self.fit.poles

    def synthesise(self, freq: npt.ArrayLike) -> np.ndarray:
        """FRFs (No, Ni, F) of the identified model at ``freq`` [Hz]."""
        return self.fit.synthesise(freq)


def identify_modes(freq: npt.ArrayLike, H: npt.ArrayLike,
                   band: Optional[Sequence[float]] = None,
                   orders: Optional[Sequence[int]] = None,
                   sigma: Optional[npt.ArrayLike] = None, frf_form: str = 'receptance',
                   tol: Tolerances = Tolerances(), refine: bool = False) -> ModalModel:
    """
    Identify natural frequencies, damping ratios and modal constants from FRFs.

    Parameters
    ----------
    freq : (F,) array_like
        Frequencies [Hz] of the FRF lines.
    H : (No, Ni, F) array_like
        FRFs, output o per input i ((F,) or (No, F): one input).
    band : (f_low, f_high), optional
        Band [Hz] to fit; default all lines above 0 Hz.
    orders : sequence of int, optional
        Model orders of the stability diagram; default ``1 .. DEFAULT_MAX_ORDER / Ni``.
        Orders above ``F No / (No + Ni) - 1`` (F lines in the band, No outputs, Ni inputs:
        half the real equations per unknown) are dropped.
    sigma : array_like, optional
        Noise standard deviation of H per line (weights), shaped like H.
    frf_form : {'receptance', 'mobility', 'accelerance'}
        Residual terms of LSFD.
    tol : Tolerances
        Stability tolerances and selection settings.
    refine : bool
        Refine the selected poles by nonlinear least squares on the lines around each
        (:func:`pentapod_sim.analysis.ema.lsfd.refine_poles`); else LSFD at the pLSCF poles.
        Use it for noisy FRFs whose lines are sparser than the half-power bands; on noise-free
        records of a sampled plant (continuous pole-residue model against a ZOH system) and
        next to modes that were not selected it can pull a pole away (docs/recording.md).

    Returns
    -------
    ModalModel

    Raises
    ------
    ValueError
        If the band holds too few lines for ``tol.min_stable + 1`` orders, or no pole is stable
        over ``tol.min_stable`` orders.
    """
    freq = np.asarray(freq, dtype=float)
    H = as_frf_array(H, len(freq))
    f_low, f_high = band if band is not None else (0.0, float(freq.max()))
    if not 0 <= f_low < f_high:
        raise ValueError(f'band {f_low:g} .. {f_high:g} Hz: need 0 <= f_low < f_high')
    inside = (freq >= f_low) & (freq <= f_high) & (freq > 0) & np.all(np.isfinite(H), axis=(0, 1))
    n_out, n_in = H.shape[:2]
    n_lines = int(np.count_nonzero(inside))
    # real equations 2 F No Ni >= unknowns (n + 1)(No Ni + Ni^2); keep a factor 2 in hand
    supported = n_lines * n_out // (n_out + n_in) - 1
    orders = sorted(int(n) for n in (orders if orders is not None
                                     else range(1, DEFAULT_MAX_ORDER // n_in + 1)))
    orders = [n for n in orders if 1 <= n <= supported]
    if len(orders) < tol.min_stable + 1:
        raise ValueError(f'band {f_low:g} .. {f_high:g} Hz holds {n_lines} FRF lines: too few '
                         f'for {tol.min_stable + 1} model orders (widen the band or record '
                         'with a finer line spacing)')
    f_in, h_in = freq[inside], H[..., inside]
    s_in = None if sigma is None else as_frf_array(sigma, len(freq))[..., inside]
    diagram = stability_diagram(plscf(f_in, h_in, orders, s_in, tol.max_damping), tol)
    poles = select_poles(diagram, tol)
    if len(poles) == 0:
        raise ValueError(f'no mode in {f_in.min():g} .. {f_in.max():g} Hz is stable over '
                         f'{tol.min_stable} model orders (orders {orders[0]}..{orders[-1]}); '
                         'check that the excitation covers the band, or widen it')
    fit = (refine_poles if refine else lsfd)(f_in, h_in, poles, frf_form, s_in)
    freq_hz, damping = pole_frequency_damping(fit.poles)
    return ModalModel(freq_hz, damping, fit, diagram, (float(f_in.min()), float(f_in.max())),
                      tol)
