"""
FRF matrix of a multi-input system from records: ``H = S_uy S_yy^-1`` (H1), with coherence.

Used to identify a controller in the loop: its inputs are the plant outputs it reads (y), its
outputs the efforts it answers (u). With a controller inside a feedback loop, y and u are both
driven by the external excitation; as long as no noise enters between them, ``u = K y`` holds
exactly and the H1 estimate from auto and cross spectra is unbiased up to leakage, provided
the spectra of y have full rank: at least as many independent excitations as inputs
(:mod:`pentapod_sim.sim.disturbance`). Spectra are Welch averages (Hann window, 50 % overlap,
:func:`scipy.signal.csd`), summed over several records (independent experiments) if given.
Segments are not detrended: removing each segment's mean from y and from u separately breaks
``u = K y`` for a controller with memory, which cost the lowest bins their estimate (multiple
coherence 0.87 at 5.9 Hz for the shipped TCP damper, 1.0000 without).

The *multiple coherence* of output i, ``gamma_i^2 = (S_uy S_yy^-1 S_yu)_ii / S_uu,ii``, is the
share of its power that is a linear function of all inputs: 1 for a linear time-invariant
system without noise, less where the system is nonlinear (saturation), time-varying or driven
by something else, and where leakage of lightly damped peaks biases the spectra.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np
import numpy.typing as npt
import scipy.signal

#: Largest condition number of S_yy at a frequency for H to be estimated there.
MAX_CONDITION = 1e10


@dataclass(frozen=True)
class MimoFrf:
    """
    Estimated FRF matrix.

    Attributes
    ----------
    freq : (F,) ndarray
        Frequencies [Hz], 0 to Nyquist.
    H : (F, n_out, n_in) complex ndarray
        FRF [output unit / input unit]; NaN where S_yy is singular (:attr:`identifiable`).
    coherence : (F, n_out) ndarray
        Multiple coherence of each output [-].
    condition : (F,) ndarray
        Condition number of S_yy (how independent the inputs were).
    inputs, outputs : tuple of str
        Names of the inputs (columns) and outputs (rows).
    n_averages : int
        Welch segments averaged, summed over the records.
    """

    freq: npt.NDArray[np.float64]
    H: npt.NDArray[np.complex128]
    coherence: npt.NDArray[np.float64]
    condition: npt.NDArray[np.float64]
    inputs: tuple[str, ...]
    outputs: tuple[str, ...]
    n_averages: int

    @property
    def identifiable(self) -> npt.NDArray[np.bool_]:
        """(F,) True where S_yy was well enough conditioned to solve for H."""
        return self.condition < MAX_CONDITION

    def at(self, freq_hz: npt.ArrayLike) -> npt.NDArray[np.complex128]:
        """
        ``H`` at other frequencies [Hz] in [0, Nyquist]: linear in real and imaginary part.

        The estimate is taken as smooth between its bins (a controller's FRF is, unless it has
        resonances narrower than the bin spacing).
        """
        f = np.asarray(freq_hz, dtype=float)
        out = np.empty(f.shape + self.H.shape[1:], dtype=complex)
        for i in range(self.H.shape[1]):
            for j in range(self.H.shape[2]):
                h = self.H[:, i, j]
                out[..., i, j] = (np.interp(f, self.freq, h.real)
                                  + 1j * np.interp(f, self.freq, h.imag))
        return out


def _spectra(a: npt.NDArray[np.float64], b: npt.NDArray[np.float64], fs: float,
             nperseg: int) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.complex128]]:
    """Cross spectral matrix S[f, i, j] = csd(a_i, b_j) = E[conj(A_i) B_j] of two column sets."""
    freq, s = scipy.signal.csd(a.T[:, None, :], b.T[None, :, :], fs=fs, window='hann',
                               nperseg=nperseg, detrend=False, axis=-1)
    return freq, np.moveaxis(s, -1, 0)


def mimo_frf(records: Sequence[tuple[npt.ArrayLike, npt.ArrayLike]], dt: float, nperseg: int,
             inputs: Sequence[str] = (), outputs: Sequence[str] = ()) -> MimoFrf:
    """
    H1 estimate of the FRF matrix from the inputs to the outputs of one or more records.

    Parameters
    ----------
    records : sequence of (y, u)
        Each record's inputs ``y`` (N, n_in) and outputs ``u`` (N, n_out), sampled at ``dt``;
        records may differ in length, not in columns.
    dt : float
        Sample time [s].
    nperseg : int
        Samples per Welch segment (bin spacing ``1 / (nperseg dt)``).
    inputs, outputs : sequence of str
        Column names (stored in the result).

    Raises
    ------
    ValueError
        On mismatched shapes, or records shorter than one segment.
    """
    if not records:
        raise ValueError('no record to estimate an FRF from')
    fs = 1.0 / dt
    sums: list[npt.NDArray[np.complex128]] = []
    freq = np.zeros(0)
    segments = 0
    n_in = n_out = -1
    for y_raw, u_raw in records:
        y_arr, u_arr = np.asarray(y_raw, dtype=float), np.asarray(u_raw, dtype=float)
        y = y_arr.reshape(y_arr.shape[0], -1)
        u = u_arr.reshape(u_arr.shape[0], -1)
        if y.shape[0] != u.shape[0]:
            raise ValueError(f'inputs have {y.shape[0]} samples, outputs {u.shape[0]}')
        if n_in >= 0 and (y.shape[1], u.shape[1]) != (n_in, n_out):
            raise ValueError('the records have different numbers of inputs or outputs')
        n_in, n_out = y.shape[1], u.shape[1]
        if y.shape[0] < nperseg:
            raise ValueError(f'a record of {y.shape[0]} samples is shorter than one Welch '
                             f'segment ({nperseg})')
        weight = 1 + (y.shape[0] - nperseg) // (nperseg // 2)   # segments in this record
        parts = [_spectra(a, b, fs, nperseg) for a, b in ((y, y), (y, u), (u, u))]
        freq = parts[0][0]
        sums = [weight * s for _, s in parts] if not sums else [
            total + weight * s for total, (_, s) in zip(sums, parts)]
        segments += weight
    # A[j, k] = E[conj(Y_j) Y_k], B[j, i] = E[conj(Y_j) U_i]; U = H Y gives B = A H^T
    s_yy, s_yu, s_uu = sums
    condition = np.linalg.cond(s_yy)
    good = condition < MAX_CONDITION
    h = np.full((freq.size, n_out, n_in), np.nan, dtype=complex)
    h[good] = np.swapaxes(np.linalg.solve(s_yy[good], s_yu[good]), 1, 2)
    # power of U_i explained by the inputs: (H A^T H^H)_ii
    explained = np.einsum('fij,fkj,fik->fi', h, s_yy, h.conj()).real
    power = np.einsum('fii->fi', s_uu).real
    with np.errstate(divide='ignore', invalid='ignore'):
        coherence = np.where(power > 0, explained / power, np.nan)
    return MimoFrf(freq, h, coherence, condition, tuple(inputs), tuple(outputs), segments)
