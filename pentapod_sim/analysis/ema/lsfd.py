"""
Residues by the least-squares frequency-domain method (LSFD) and FRF synthesis from modes.

Model of every FRF in the band, for selected poles ``lambda_r`` [rad/s] (with their
conjugates, so the impulse response is real)::

    H(w) = sum_r [ A_r / (jw - lambda_r) + conj(A_r) / (jw - conj(lambda_r)) ]
           + LR (jw)^p_low + UR (jw)^p_up

The residues ``A_r`` (complex) and the real lower/upper residuals ``LR``, ``UR`` (modes below /
above the band) are linear unknowns: one real least-squares problem whose design matrix is
shared by all FRFs. The residual exponents follow the FRF form: receptance (displacement per
force) ``(-2, 0)``: mass line below, static flexibility above; mobility (velocity) ``(-1, 1)``;
accelerance ``(0, 2)``.

The *modal constant* of mode r is ``rA = 2 j w_d A_r`` with ``w_d = Im lambda_r``: for a
lightly damped normal mode it is ``phi_o phi_i / m_r`` (real, the numerator of
``rA / (w_r^2 - w^2 + 2 j zeta w_r w)``), in the unit of H times (rad/s)^2 (1/kg for m/N).

:func:`refine_poles` then minimises the same (weighted) residual over each pole too, on the
lines around it, residues eliminated by LSFD at every step (variable projection,
``scipy.optimize.least_squares``). It removes the bias of the linearised pLSCF estimate for a
mode whose half-power band holds less than one FRF line.
"""
from __future__ import annotations

import dataclasses

import numpy as np
import numpy.typing as npt
import scipy.optimize

from pentapod_sim.analysis.ema.poles import as_frf_array

#: residual exponents (lower, upper) of (jw) per FRF form
RESIDUAL_POWERS = {'receptance': (-2, 0), 'mobility': (-1, 1), 'accelerance': (0, 2)}


@dataclasses.dataclass
class ResidueFit:
    """
    LSFD result.

    Attributes
    ----------
    poles : (R,) complex ndarray
        Poles [rad/s] (positive imaginary part).
    residues : (No, Ni, R) complex ndarray
        ``A_r`` [unit of H * rad/s].
    lower, upper : (No, Ni) ndarray
        Real lower / upper residuals.
    frf_form : str
        Key of :data:`RESIDUAL_POWERS`.
    """

    poles: np.ndarray
    residues: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    frf_form: str = 'receptance'

    @property
    def modal_constants(self) -> np.ndarray:
        """``2 j Im(lambda_r) A_r``, (No, Ni, R) [unit of H * (rad/s)^2]."""
        return 2j * self.poles.imag * self.residues

    def synthesise(self, freq: npt.ArrayLike) -> np.ndarray:
        """FRFs (No, Ni, F) of the modal model at ``freq`` [Hz]."""
        basis = _basis(np.asarray(freq, dtype=float), self.poles, self.frf_form)
        r = len(self.poles)
        coef = np.concatenate([self.residues.real, self.residues.imag,
                               self.lower[..., None], self.upper[..., None]], axis=2)
        order = np.concatenate([np.arange(0, 2 * r, 2), np.arange(1, 2 * r, 2),
                                [2 * r, 2 * r + 1]])
        return np.einsum('kc,oic->oik', basis[:, order], coef)


def _basis(freq: np.ndarray, poles: np.ndarray, frf_form: str) -> np.ndarray:
    """Complex design matrix (F, 2R + 2): per mode [re A, im A] columns, then LR, UR."""
    if frf_form not in RESIDUAL_POWERS:
        raise ValueError(f'frf_form {frf_form!r} is not one of {", ".join(RESIDUAL_POWERS)}')
    jw = 1j * 2 * np.pi * freq[:, None]
    if np.any(jw == 0) and RESIDUAL_POWERS[frf_form][0] < 0:
        raise ValueError('LSFD with a lower residual needs frequencies > 0 Hz')
    phi = 1.0 / (jw - poles[None, :])
    phi_c = 1.0 / (jw - np.conj(poles)[None, :])
    cols = np.empty((len(freq), 2 * len(poles)), dtype=complex)
    cols[:, 0::2] = phi + phi_c
    cols[:, 1::2] = 1j * (phi - phi_c)
    low, up = RESIDUAL_POWERS[frf_form]
    return np.column_stack([cols, jw[:, 0] ** low, jw[:, 0] ** up])


def lsfd(freq: npt.ArrayLike, H: npt.ArrayLike, poles: npt.ArrayLike,
         frf_form: str = 'receptance', sigma: npt.ArrayLike | None = None) -> ResidueFit:
    """
    Residues and lower/upper residuals of given poles by linear least squares.

    Parameters
    ----------
    freq : (F,) array_like
        Frequencies [Hz] (> 0).
    H : (No, Ni, F) array_like
        Measured FRFs ((F,) or (No, F): one input).
    poles : (R,) array_like
        Poles [rad/s] with positive imaginary part.
    frf_form : {'receptance', 'mobility', 'accelerance'}
        Selects the residual terms (module docstring).
    sigma : array_like, optional
        Noise standard deviation per line, shaped like H (weights ``1 / sigma``).

    Returns
    -------
    ResidueFit
    """
    freq = np.asarray(freq, dtype=float)
    H = as_frf_array(H, len(freq))
    poles = np.atleast_1d(np.asarray(poles, dtype=complex))
    coef, _, _ = _solve(freq, H, poles, frf_form, _line_weights(H, sigma))
    r = len(poles)
    residues = coef[..., 0:2 * r:2] + 1j * coef[..., 1:2 * r:2]
    return ResidueFit(poles, residues, coef[..., 2 * r], coef[..., 2 * r + 1], frf_form)


def _line_weights(H: np.ndarray, sigma: npt.ArrayLike | None) -> np.ndarray:
    """Weights (No * Ni, F): 1 / sigma per line (floored), or ones."""
    n_out, n_in, n_freq = H.shape
    if sigma is None:
        return np.ones((n_out * n_in, n_freq))
    sig = as_frf_array(sigma, n_freq).real.reshape(n_out * n_in, n_freq)
    rms = np.sqrt(np.mean(np.abs(H.reshape(n_out * n_in, n_freq)) ** 2, axis=1, keepdims=True))
    floor = np.maximum(1e-3 * np.median(sig, axis=1, keepdims=True),
                       1e-8 * np.maximum(rms, 1e-300))  # noise-free records: even weights
    return 1.0 / np.maximum(sig, floor)


def _solve(freq: np.ndarray, H: np.ndarray, poles: np.ndarray, frf_form: str,
           weights: np.ndarray, dpoles: np.ndarray | None = None
           ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """
    Weighted LSFD: coefficients (No, Ni, 2R + 2), residual vector, Jacobian or None.

    With ``dpoles`` (P, R), the derivatives of the poles by P parameters, the Jacobian of the
    residual by those parameters (Kaufman's variable-projection approximation) is returned.
    """
    n_out, n_in, n_freq = H.shape
    basis = _basis(freq, poles, frf_form)
    scale = np.linalg.norm(basis, axis=0)
    scale[scale == 0] = 1.0
    design = basis / scale
    coef = np.empty((design.shape[1], n_out * n_in))
    resid, jac = [], []
    if dpoles is not None:
        jw = 1j * 2 * np.pi * freq[:, None]
        phi2 = 1.0 / (jw - poles[None, :]) ** 2                # d phi / d lambda
        phi2_c = 1.0 / (jw - np.conj(poles)[None, :]) ** 2
        mode = np.argmax(np.abs(dpoles), axis=1) if len(dpoles) else np.zeros(0, int)
        d_phi = phi2[:, mode] * dpoles[np.arange(len(mode)), mode][None, :]
        d_phi_c = phi2_c[:, mode] * np.conj(dpoles[np.arange(len(mode)), mode])[None, :]
    for j, row in enumerate(H.reshape(n_out * n_in, n_freq)):
        w = weights[j]
        a = np.vstack([design.real * w[:, None], design.imag * w[:, None]])
        b = np.concatenate([row.real * w, row.imag * w])
        coef[:, j] = np.linalg.lstsq(a, b, rcond=None)[0]
        resid.append(b - a @ coef[:, j])
        if dpoles is not None:
            q = np.linalg.qr(a)[0]
            c = coef[:, j] / scale
            d_model = c[2 * mode] * (d_phi + d_phi_c) + c[2 * mode + 1] * 1j * (d_phi - d_phi_c)
            dm = np.vstack([d_model.real * w[:, None], d_model.imag * w[:, None]])
            jac.append(-(dm - q @ (q.T @ dm)))
    coef = (coef / scale[:, None]).T.reshape(n_out, n_in, -1)
    return coef, np.concatenate(resid), (np.vstack(jac) if dpoles is not None else None)


def refine_poles(freq: npt.ArrayLike, H: npt.ArrayLike, poles: npt.ArrayLike,
                 frf_form: str = 'receptance', sigma: npt.ArrayLike | None = None,
                 half_widths: float = 10.0, min_lines: int = 4) -> ResidueFit:
    """
    Refine each pole on the lines around it, then LSFD with all refined poles.

    Per mode r (in order of frequency): the lines within ``max(half_widths * zeta_r f_r,
    min_lines * line spacing)`` of ``f_r`` are fitted by the model of :func:`lsfd` with every
    pole in that window (the others fixed at their current values); ``ln |lambda_r|`` and
    ``ln zeta_r`` minimise the weighted residual (Levenberg-Marquardt, residues eliminated by
    variable projection). Local windows keep modes that were not selected from pulling the
    pole. A refined pole that leaves the window, or whose damping changes by more than a
    factor 3, is not taken.

    Parameters and returns as :func:`lsfd`; ``poles`` is the starting point.
    """
    freq = np.asarray(freq, dtype=float)
    H = as_frf_array(H, len(freq))
    poles = np.atleast_1d(np.asarray(poles, dtype=complex)).copy()
    weights = _line_weights(H, sigma)
    spacing = float(np.median(np.diff(np.sort(freq)))) if len(freq) > 1 else 1.0
    for r in np.argsort(np.abs(poles)):
        f_r, z_r = np.abs(poles[r]) / (2 * np.pi), -poles[r].real / np.abs(poles[r])
        half = max(half_widths * z_r * f_r, min_lines * spacing)
        window = np.abs(freq - f_r) <= half
        if np.count_nonzero(window) < 6:
            continue
        f_all = np.abs(poles) / (2 * np.pi)
        others = poles[(np.abs(f_all - f_r) <= half) & (np.arange(len(poles)) != r)]
        fit = _refine_one(freq[window], H[..., window], poles[r], others, frf_form,
                          weights[:, window])
        f_new, z_new = np.abs(fit) / (2 * np.pi), -fit.real / np.abs(fit)
        if abs(f_new - f_r) < half and 1 / 3 < z_new / z_r < 3:
            poles[r] = fit
    return lsfd(freq, H, poles, frf_form, sigma)


def _refine_one(freq: np.ndarray, H: np.ndarray, pole: complex, others: np.ndarray,
                frf_form: str, weights: np.ndarray) -> complex:
    """One pole minimising the weighted LSFD residual with ``others`` fixed."""

    def to_pole(x: np.ndarray) -> tuple[complex, np.ndarray]:
        wn, zeta = np.exp(x[0]), min(np.exp(x[1]), 0.999)
        root = np.sqrt(1 - zeta ** 2)
        lam = wn * (-zeta + 1j * root)
        dpoles = np.zeros((2, 1 + len(others)), dtype=complex)
        dpoles[0, 0], dpoles[1, 0] = lam, zeta * wn * (-1 - 1j * zeta / root)
        return lam, dpoles

    cache: dict[bytes, tuple[np.ndarray, np.ndarray | None]] = {}

    def evaluate(x: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        key = x.tobytes()
        if key not in cache:
            cache.clear()
            lam, dpoles = to_pole(x)
            cache[key] = _solve(freq, H, np.concatenate([[lam], others]), frf_form, weights,
                                dpoles)[1:]
        return cache[key]

    start = np.array([np.log(abs(pole)), np.log(-pole.real / abs(pole))])
    solution = scipy.optimize.least_squares(lambda x: evaluate(x)[0], start,
                                            jac=lambda x: evaluate(x)[1], method='lm')
    return to_pole(solution.x)[0]
