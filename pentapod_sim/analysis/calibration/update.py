"""
Calibrate modal damping: measured FRFs + the model's modes -> damping per mode, updated FRFs.

Identification runs per sub-band of about ``modes_per_band`` model modes (edges between model
modes, each band widened by 30 % of the gap to its neighbours so a measured mode shifted
against the model stays inside one); a mode found in two overlapping bands is kept from the
band whose centre it is nearer. Its shape at the responses is the leading left singular
vector of its modal constants (No x Ni, rank one for a real mode).

The model FRFs at the measured DOFs are the modal sum over every computed mode plus the static
residual of the modes not computed, ``R K^-1 Q^T - sum_r c_r b_r / omega_r^2`` (R, Q the
response and reference rows), so they agree with the plant's own FRFs.
"""
from __future__ import annotations

from dataclasses import dataclass, field
import logging
from typing import Callable

import numpy as np
import numpy.typing as npt
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from pentapod_sim.analysis.calibration.fill import band_values, rayleigh_fit
from pentapod_sim.analysis.calibration.pairing import pair_modes, Pairing
from pentapod_sim.analysis.calibration.settings import CalibrationSettings
from pentapod_sim.analysis.ema.identify import identify_modes
from pentapod_sim.analysis.ema.poles import Tolerances
from pentapod_sim.analysis.measured.frf_files import MeasuredFrfs
from pentapod_sim.analysis.measured.model_dofs import label_rows
from pentapod_sim.errors import BagError
from pentapod_sim.fe.model import FEModel
from pentapod_sim.plant.config import DampingGroup
from pentapod_sim.plant.damping_file import DampingFile, PairedMode, Rayleigh

LOG = logging.getLogger(__name__)
#: Share of the gap to the neighbouring model mode by which a sub-band is widened.
BAND_OVERLAP = 0.3
#: An identified mode: f [Hz], zeta, shape (No,), centrality in its sub-band, constants (No, Ni).
_Found = tuple[float, float, npt.NDArray[np.complex128], float, npt.NDArray[np.complex128]]


@dataclass
class Calibration:
    """
    Result of :func:`calibrate`.

    Attributes
    ----------
    identified_hz, identified_zeta : (p,) ndarray
        Identified natural frequencies [Hz] and damping ratios [-].
    identified_shapes : (No, p) complex ndarray
        Identified shapes at the responses.
    identified_constants : (No, Ni, p) complex ndarray
        Identified modal constants [unit of H * (rad/s)^2].
    model_hz : (m,) ndarray
        Model natural frequencies [Hz] (all computed modes).
    zeta_before, zeta_after : (m,) ndarray
        Model damping ratios before and after the calibration.
    pairing : Pairing
        Pairs over the model modes in the band (``model`` indexes ``model_hz``).
    damping : DampingFile
        What the plant reads (:mod:`pentapod_sim.plant.damping_file`).
    freq : (F,) ndarray
        Lines [Hz] of the band.
    measured, before, after : (No, Ni, F) complex ndarray
        Measured and model receptances at the measured DOFs.
    sub_bands : list of (float, float)
        Identification sub-bands [Hz].
    """

    identified_hz: npt.NDArray[np.float64]
    identified_zeta: npt.NDArray[np.float64]
    identified_shapes: npt.NDArray[np.complex128]
    identified_constants: npt.NDArray[np.complex128]
    model_hz: npt.NDArray[np.float64]
    zeta_before: npt.NDArray[np.float64]
    zeta_after: npt.NDArray[np.float64]
    pairing: Pairing
    damping: DampingFile
    freq: npt.NDArray[np.float64]
    measured: npt.NDArray[np.complex128]
    before: npt.NDArray[np.complex128]
    after: npt.NDArray[np.complex128]
    sub_bands: list[tuple[float, float]] = field(default_factory=list)


def sub_bands(model_hz: npt.ArrayLike, band: tuple[float, float],
              per_band: int) -> list[tuple[float, float]]:
    """Identification sub-bands of about ``per_band`` model modes each (module docstring)."""
    lo, hi = band
    f = np.sort(np.asarray(model_hz, dtype=float))
    inside = f[(f >= lo) & (f <= hi)]
    if inside.size <= per_band:
        return [(float(lo), float(hi))]
    n_bands = int(np.ceil(inside.size / per_band))
    groups = np.array_split(inside, n_bands)
    edges = [lo] + [0.5 * (a[-1] + b[0]) for a, b in zip(groups[:-1], groups[1:])] + [hi]
    out = []
    for k, group in enumerate(groups):
        left = edges[k] - (BAND_OVERLAP * (group[0] - groups[k - 1][-1]) if k > 0 else 0.0)
        right = edges[k + 1] + (BAND_OVERLAP * (groups[k + 1][0] - group[-1])
                                if k + 1 < n_bands else 0.0)
        out.append((float(max(lo, left)), float(min(hi, right))))
    return out


def _identify(measured: MeasuredFrfs, bands: list[tuple[float, float]],
              settings: CalibrationSettings, say: Callable[[str], None]
              ) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64],
                         npt.NDArray[np.complex128], npt.NDArray[np.complex128]]:
    found: list[_Found] = []
    for k, (lo, hi) in enumerate(bands, start=1):
        say(f'identifying modes in {lo:.2f}-{hi:.2f} Hz (sub-band {k} of {len(bands)})')
        try:
            model = identify_modes(measured.freq, measured.H, band=(lo, hi),
                                   orders=range(1, settings.max_order + 1),
                                   tol=Tolerances(), refine=settings.refine)
        except ValueError as err:
            LOG.warning('sub-band %.2f-%.2f Hz: %s', lo, hi, err)
            continue
        constants = model.fit.modal_constants           # (No, Ni, R)
        for r, (f, z) in enumerate(zip(model.freq_hz, model.damping)):
            u, s, _ = np.linalg.svd(constants[:, :, r], full_matrices=False)
            centrality = 1.0 - abs(f - 0.5 * (lo + hi)) / (0.5 * (hi - lo))
            found.append((float(f), float(z), u[:, 0] * s[0], centrality, constants[:, :, r]))
    found.sort(key=lambda item: item[0])
    kept: list[_Found] = []
    for item in found:                                  # one mode seen by two bands: keep one
        if kept and abs(item[0] / kept[-1][0] - 1.0) < Tolerances().tol_freq:
            if item[3] > kept[-1][3]:
                kept[-1] = item
            continue
        kept.append(item)
    n_out, n_in = measured.H.shape[:2]
    if not kept:
        return (np.zeros(0), np.zeros(0), np.zeros((n_out, 0), dtype=complex),
                np.zeros((n_out, n_in, 0), dtype=complex))
    return (np.array([k[0] for k in kept]), np.array([k[1] for k in kept]),
            np.column_stack([k[2] for k in kept]), np.stack([k[4] for k in kept], axis=2))


def model_receptance(c: npt.NDArray[np.float64], b: npt.NDArray[np.float64],
                     omega: npt.NDArray[np.float64], zeta: npt.NDArray[np.float64],
                     residual: npt.NDArray[np.float64], freq: npt.ArrayLike
                     ) -> npt.NDArray[np.complex128]:
    """``sum_r c_r b_r / (omega_r^2 - w^2 + 2 j zeta_r omega_r w) + residual``, (No, Ni, F)."""
    w = 2 * np.pi * np.asarray(freq, dtype=float)
    out = np.empty((c.shape[0], b.shape[1], w.size), dtype=complex)
    for start in range(0, w.size, 512):                 # bound the (m, chunk) temporary
        ww = w[start:start + 512]
        den = omega[:, None] ** 2 - ww[None, :] ** 2 + 2j * (zeta * omega)[:, None] * ww[None, :]
        out[:, :, start:start + 512] = np.einsum('or,ri,rf->oif', c, b, 1.0 / den)
    out += residual[:, :, None]
    return out


def calibrate(fe: FEModel, frequencies_hz: npt.ArrayLike, shapes: npt.ArrayLike,
              zeta_model: npt.ArrayLike, measured: MeasuredFrfs,
              settings: CalibrationSettings = CalibrationSettings(),
              progress: Callable[[str], None] | None = None) -> Calibration:
    """
    Calibrate the model's modal damping on measured receptances.

    Parameters
    ----------
    fe : FEModel
        The model the measurement is mapped onto (points, DOF map, K for the residual).
    frequencies_hz, shapes
        Its computed modes: (m,) [Hz] and mass-normalised (n, m).
    zeta_model : float or (m,) array_like
        Its damping before calibration [-].
    measured : MeasuredFrfs
        Measured receptances with their DOF labels.
    settings : CalibrationSettings
        Band, sub-bands, pairing and fill settings.
    progress : callable, optional
        Receives one message per step.
    """
    say = progress or (lambda msg: LOG.info('%s', msg))
    model_hz = np.asarray(frequencies_hz, dtype=float)
    omega = 2 * np.pi * model_hz
    zeta_before = np.broadcast_to(np.asarray(zeta_model, dtype=float), model_hz.shape).copy()
    rows_out = label_rows(fe, measured.responses)
    rows_in = label_rows(fe, measured.references)
    c = np.asarray(rows_out @ shapes)                   # (No, m)
    b = np.asarray(rows_in @ shapes).T                  # (m, Ni)
    say(f'static residual of the modes not computed ({fe.n_dof} DOF)')
    static = np.asarray(rows_out @ spla.splu(sp.csc_matrix(fe.K)).solve(rows_in.T.toarray()))
    residual = static - np.einsum('or,ri->oi', c, b / (omega ** 2)[:, None])
    lo, hi = settings.band or (float(measured.freq[measured.freq > 0].min()),
                               float(measured.freq.max()))
    bands = sub_bands(model_hz, (lo, hi), settings.modes_per_band)
    f_id, z_id, psi, constants = _identify(measured, bands, settings, say)
    in_band = np.flatnonzero((model_hz >= lo * (1 - settings.frequency_tolerance))
                             & (model_hz <= hi * (1 + settings.frequency_tolerance)))
    pairing = pair_modes(f_id, psi, model_hz[in_band], c[:, in_band], settings.mac_min,
                         settings.frequency_tolerance)
    pairing = Pairing(pairing.measured, in_band[pairing.model], pairing.mac, pairing.mac_matrix)
    say(f'{f_id.size} modes identified, {pairing.model.size} paired with the {in_band.size} '
        f'model modes of {lo:g}-{hi:g} Hz (MAC >= {settings.mac_min:g})')
    if pairing.model.size == 0:
        raise BagError(f'{measured.source}: no measured mode pairs with a model mode (MAC >= '
                       f'{settings.mac_min:g}, frequencies within '
                       f'{100 * settings.frequency_tolerance:g} %); {f_id.size} identified')
    paired_zeta = z_id[pairing.measured]
    paired = tuple(PairedMode(float(model_hz[j]), float(z_id[i]), float(f_id[i]), float(m))
                   for i, j, m in zip(pairing.measured, pairing.model, pairing.mac))
    if settings.fill == 'rayleigh':
        alpha, beta = rayleigh_fit(2 * np.pi * f_id[pairing.measured], paired_zeta)
        damping = DampingFile(paired, rayleigh=Rayleigh(alpha, beta), measured=measured.source,
                              model=str(fe.meta.get('source', fe.meta.get('parameter_file', ''))))
    else:
        bands_fill = tuple(DampingGroup(*v) for v in band_values(
            f_id[pairing.measured], paired_zeta, settings.fill_edges))
        damping = DampingFile(paired, bands=bands_fill,
                              default_ratio=float(np.median(paired_zeta)),
                              measured=measured.source,
                              model=str(fe.meta.get('source', fe.meta.get('parameter_file', ''))))
    zeta_after = damping.ratios(model_hz)
    inside = (measured.freq >= lo) & (measured.freq <= hi)
    freq = measured.freq[inside]
    say(f'model FRFs before and after at {freq.size} lines')
    return Calibration(f_id, z_id, psi, constants, model_hz, zeta_before, zeta_after, pairing,
                       damping, freq, measured.H[..., inside],
                       model_receptance(c, b, omega, zeta_before, residual, freq),
                       model_receptance(c, b, omega, zeta_after, residual, freq), bands)
