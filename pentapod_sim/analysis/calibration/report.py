"""
Report of a calibration: pairing table, remaining error per FRF, overlay of measured and model.

Error per FRF (what it rests on): its *peaks* are the resonances of paired modes that
dominate it there: the identified mode alone, ``|rA_oi| / (2 zeta omega^2)``, makes at least
half of ``|H_measured|`` at its resonance, which lies within 20 dB of the FRF's largest value.
A peak's level is the largest ``|H|`` within the half-power band ``f (1 +- zeta)`` around the
measured frequency (measurement) or the model frequency (model: the calibration leaves
frequencies as they are). ``peak_db`` is the largest ``|20 log10(model / measured)|`` over an
FRF's peaks; ``rms_db`` the RMS of ``20 log10 |H_model / H_measured|`` over all lines of the
band, which also sees frequency shifts, anti-resonances and unpaired modes.
"""
from __future__ import annotations

import csv
import os
from pathlib import Path
from typing import Mapping, Sequence, TypedDict

import numpy as np
import numpy.typing as npt

from pentapod_sim.analysis.calibration.update import Calibration
from pentapod_sim.analysis.measured.labels import DofLabel
from pentapod_sim.figures import save_figure

PAIR_COLUMNS = ('model_mode', 'model_f_hz', 'measured_f_hz', 'mac', 'zeta_model',
                'zeta_measured')
ERROR_COLUMNS = ('response', 'reference', 'peaks', 'peak_db_before', 'peak_db_after',
                 'rms_db_before', 'rms_db_after')
#: Peaks lower than this below an FRF's largest value are not counted [dB].
PEAK_FLOOR_DB = 20.0
#: Least share of the FRF at a resonance that the mode alone makes for it to count as a peak.
DOMINANCE = 0.5


class PairRow(TypedDict):
    """A line of the pairing table (PAIR_COLUMNS)."""

    model_mode: int
    model_f_hz: float
    measured_f_hz: float
    mac: float
    zeta_model: float
    zeta_measured: float


class ErrorRow(TypedDict):
    """Remaining error of one FRF (ERROR_COLUMNS), in dB (module docstring)."""

    response: str
    reference: str
    peaks: int
    peak_db_before: float
    peak_db_after: float
    rms_db_before: float
    rms_db_after: float


def pairing_rows(cal: Calibration) -> list[PairRow]:
    """One row per paired mode (PAIR_COLUMNS), by model frequency."""
    return [{'model_mode': int(j) + 1, 'model_f_hz': float(cal.model_hz[j]),
             'measured_f_hz': float(cal.identified_hz[i]), 'mac': float(m),
             'zeta_model': float(cal.zeta_before[j]),
             'zeta_measured': float(cal.identified_zeta[i])}
            for i, j, m in zip(cal.pairing.measured, cal.pairing.model, cal.pairing.mac)]


def _peak(freq: npt.NDArray[np.float64], mag: npt.NDArray[np.float64], f0: float,
          w: float) -> float:
    """Largest ``mag`` within ``f0 (1 +- w)`` (the line nearest f0 if the window holds none)."""
    window = (freq >= f0 * (1 - w)) & (freq <= f0 * (1 + w))
    if not window.any():
        return float(mag[np.argmin(np.abs(freq - f0))])
    return float(mag[window].max())


def counted_peaks(cal: Calibration, o: int, i: int) -> list[tuple[int, int]]:
    """(identified, model) index of the paired modes that make a peak of FRF (o, i)."""
    meas = np.abs(cal.measured[o, i])
    floor = meas.max() * 10 ** (-PEAK_FLOOR_DB / 20)
    out = []
    for r, j in zip(cal.pairing.measured, cal.pairing.model):
        f, z = cal.identified_hz[r], cal.identified_zeta[r]
        single = np.abs(cal.identified_constants[o, i, r]) / (2 * z * (2 * np.pi * f) ** 2)
        level = _peak(cal.freq, meas, f, max(z, 1e-3))
        if level >= floor and single >= DOMINANCE * level:
            out.append((int(r), int(j)))
    return out


def peak_errors(cal: Calibration, model: npt.NDArray[np.complex128], o: int,
                i: int) -> tuple[int, float]:
    """(number of counted peaks, largest |dB| error) of FRF (o, i) of ``model``."""
    meas, mag = np.abs(cal.measured[o, i]), np.abs(model[o, i])
    worst, peaks = 0.0, counted_peaks(cal, o, i)
    for r, j in peaks:
        w = max(cal.identified_zeta[r], 1e-3)
        ratio = _peak(cal.freq, mag, cal.model_hz[j], w) / _peak(cal.freq, meas,
                                                                cal.identified_hz[r], w)
        worst = max(worst, abs(20 * np.log10(ratio)))
    return len(peaks), (worst if peaks else np.nan)


def _rms_db(cal: Calibration, model: npt.NDArray[np.complex128], o: int, i: int) -> float:
    """RMS of ``20 log10 |H_model / H_measured|`` of FRF (o, i) over the band's lines."""
    ratio = np.abs(model[o, i]) / np.abs(cal.measured[o, i])
    return float(np.sqrt(np.mean((20 * np.log10(ratio)) ** 2)))


def error_rows(cal: Calibration, responses: Sequence[DofLabel],
               references: Sequence[DofLabel]) -> list[ErrorRow]:
    """Remaining error of every FRF before and after the calibration (ERROR_COLUMNS)."""
    rows: list[ErrorRow] = []
    for o, r in enumerate(responses):
        for i, q in enumerate(references):
            peaks, before = peak_errors(cal, cal.before, o, i)
            _, after = peak_errors(cal, cal.after, o, i)     # the same peaks (of the measurement)
            rows.append({'response': str(r), 'reference': str(q), 'peaks': peaks,
                         'peak_db_before': before, 'peak_db_after': after,
                         'rms_db_before': _rms_db(cal, cal.before, o, i),
                         'rms_db_after': _rms_db(cal, cal.after, o, i)})
    return rows


def format_pairing(rows: Sequence[PairRow]) -> str:
    """The pairing table as text."""
    lines = [f'{"mode":>4} {"f model":>9} {"f meas.":>9} {"MAC":>6} {"ζ model":>9} '
             f'{"ζ meas.":>9}']
    lines += [f'{r["model_mode"]:4d} {r["model_f_hz"]:9.3f} {r["measured_f_hz"]:9.3f} '
              f'{r["mac"]:6.3f} {r["zeta_model"]:9.5f} {r["zeta_measured"]:9.5f}' for r in rows]
    return '\n'.join(lines)


def write_rows(path: str | os.PathLike[str], rows: Sequence[Mapping[str, object]],
               columns: Sequence[str]) -> Path:
    """Write rows as CSV."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, 'w', newline='', encoding='utf-8') as stream:
        writer = csv.DictWriter(stream, columns)
        writer.writeheader()
        writer.writerows(rows)
    return path


def overlay_plot(cal: Calibration, responses: Sequence[DofLabel], references: Sequence[DofLabel],
                 path: str | os.PathLike[str], max_panels: int = 6, title: str = '') -> Path:
    """PNG: |H| of measured, model before and updated model, for the driving points first."""
    import matplotlib.pyplot as plt
    pairs = [(o, i) for i, q in enumerate(references) for o, r in enumerate(responses)
             if str(r) == str(q)]
    rest = [(o, i) for o in range(len(responses)) for i in range(len(references))
            if (o, i) not in pairs]
    pairs += sorted(rest, key=lambda oi: -np.abs(cal.measured[oi]).max())   # largest first
    pairs = pairs[:max_panels]
    fig, axes = plt.subplots(len(pairs), 1, figsize=(9, 2.4 * len(pairs)), sharex=True,
                             squeeze=False)
    for ax, (o, i) in zip(axes[:, 0], pairs):
        ax.semilogy(cal.freq, np.abs(cal.measured[o, i]), color='0.3', lw=1.0,
                    label='measured')
        ax.semilogy(cal.freq, np.abs(cal.before[o, i]), color='tab:orange', lw=0.8,
                    label='model before')
        ax.semilogy(cal.freq, np.abs(cal.after[o, i]), color='tab:blue', lw=0.8, ls='--',
                    label='model updated')
        for j in cal.pairing.model:
            ax.axvline(cal.model_hz[j], color='tab:green', lw=0.4, alpha=0.5)
        ax.set_ylabel(f'{responses[o]} / {references[i]}\n|H| [m/N]', fontsize=7)
        ax.grid(True, which='both', alpha=0.3)
    axes[0, 0].legend(fontsize=7, loc='upper right')
    axes[0, 0].set_title(title or 'measured and model receptances (green: paired modes)',
                         fontsize=9)
    axes[-1, 0].set_xlabel('frequency [Hz]')
    return save_figure(fig, Path(path))
