"""
Tables and CSV files of identified modes and of measured against synthesised FRFs.

Modal constants are ``rA = 2 j w_d A_r`` (:mod:`pentapod_sim.analysis.ema.lsfd`), in the FRF
unit times (rad/s)^2; for a displacement per force FRF (m/N) that is 1/kg.
"""
from __future__ import annotations

import csv
from pathlib import Path
from typing import Sequence

import numpy as np

from pentapod_sim.analysis.ema.identify import ModalModel


def constant_unit(frf_unit: str) -> str:
    """Unit of a modal constant of an FRF in ``frf_unit``: ``m/N`` -> ``1/kg``."""
    return '1/kg' if frf_unit == 'm/N' else f'{frf_unit} (rad/s)^2'


def mode_table(model: ModalModel, labels: Sequence[str], frf_unit: str) -> list[str]:
    """
    Lines of a text table: mode, f [Hz], zeta [-], modal constant per output (|rA|, phase).

    Parameters
    ----------
    model : ModalModel
        Identified modes (first input).
    labels : sequence of str
        One name per output.
    frf_unit : str
        Unit of the FRFs, e.g. ``'m/N'``.
    """
    unit = constant_unit(frf_unit)
    short = [label.rsplit('.', 1)[-1] for label in labels]
    head = f'{"mode":>4s} {"f [Hz]":>11s} {"zeta [-]":>10s}' + ''.join(
        f'  {"rA " + s + " [" + unit + "]":>26s}' for s in short)
    lines = [head]
    constants = model.fit.modal_constants[:, 0, :]
    for r, (f, zeta) in enumerate(zip(model.freq_hz, model.damping)):
        cells = ''.join(f'  {abs(c):13.4e} {np.degrees(np.angle(c)):+7.1f} deg'
                        for c in constants[:, r])
        lines.append(f'{r + 1:4d} {f:11.4f} {zeta:10.5f}{cells}')
    return lines


def write_modes_csv(path: str | Path, model: ModalModel, labels: Sequence[str],
                    frf_unit: str) -> Path:
    """
    Write one row per mode: freq_Hz, damping_ratio, then per output rA re/im and |rA|.

    Returns
    -------
    Path
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    unit = constant_unit(frf_unit)
    constants = model.fit.modal_constants[:, 0, :]
    with open(path, 'w', newline='', encoding='utf-8') as handle:
        writer = csv.writer(handle)
        writer.writerow(['mode', 'freq_Hz', 'damping_ratio', 'pole_re_rad_s', 'pole_im_rad_s']
                        + [f'{label} rA_{part} [{unit}]' for label in labels
                           for part in ('re', 'im', 'abs')])
        for r, (f, zeta, pole) in enumerate(zip(model.freq_hz, model.damping, model.poles)):
            cells: list[float] = []
            for c in constants[:, r]:
                cells += [c.real, c.imag, abs(c)]
            writer.writerow([r + 1, f, zeta, pole.real, pole.imag] + cells)
    return path


def write_frf_csv(path: str | Path, freq: np.ndarray, H: np.ndarray, synth: np.ndarray,
                  labels: Sequence[str], frf_unit: str, sigma: np.ndarray | None = None,
                  transient: np.ndarray | None = None) -> Path:
    """
    Write measured and synthesised FRFs (first input) per line, with their error estimates.

    Columns: freq_Hz, then per output measured re/im, synthesised re/im and, when given, the
    noise standard deviation and the transient error [FRF unit].
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    header, columns = ['freq_Hz'], [freq]
    for o, label in enumerate(labels):
        header += [f'{label} {name} [{frf_unit}]' for name in
                   ('measured_re', 'measured_im', 'synthesised_re', 'synthesised_im')]
        columns += [H[o, 0].real, H[o, 0].imag, synth[o, 0].real, synth[o, 0].imag]
        for name, values in (('noise_std', sigma), ('transient', transient)):
            if values is not None:
                header.append(f'{label} {name} [{frf_unit}]')
                columns.append(values[o, 0])
    with open(path, 'w', newline='', encoding='utf-8') as handle:
        writer = csv.writer(handle)
        writer.writerow(header)
        writer.writerows(np.column_stack(columns).tolist())
    return path
