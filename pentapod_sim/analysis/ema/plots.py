"""
PNG plots of a modal identification: stability diagram, synthesised against measured FRFs.

Plotting is kept apart from computing (as in :mod:`pentapod_sim.analysis.frf.plots`): every
function takes results and writes one file.
"""
from __future__ import annotations

from pathlib import Path
from typing import Sequence

import matplotlib

matplotlib.use('Agg')
import matplotlib.pyplot as plt  # noqa: E402  (backend must be chosen first)
import numpy as np  # noqa: E402

from pentapod_sim.analysis.ema.identify import ModalModel  # noqa: E402
from pentapod_sim.figures import save_figure  # noqa: E402

#: marker, colour, legend text per stability class (pentapod_sim.analysis.ema.poles.CLASSES)
CLASS_STYLE = {'o': ('.', '0.6', 'new'), 'f': ('x', 'tab:orange', 'f stable'),
               'd': ('+', 'tab:blue', 'f, zeta stable'),
               's': ('o', 'tab:green', 'f, zeta, vector stable')}


def stability_plot(model: ModalModel, freq: np.ndarray, H: np.ndarray, path: str | Path,
                   title: str = '') -> Path:
    """
    Stability diagram: poles per model order over frequency, with the FRF magnitude sum.

    Parameters
    ----------
    model : ModalModel
        From :func:`pentapod_sim.analysis.ema.identify.identify_modes`.
    freq : (F,) ndarray
        Frequencies [Hz] of the measured FRFs.
    H : (No, Ni, F) ndarray
        Measured FRFs (their summed magnitude is drawn on a second axis, normalised).
    path : str or Path
        PNG file.
    title : str
        Figure title.

    Returns
    -------
    Path
    """
    fig, ax = plt.subplots(figsize=(9, 5.5))
    for code, (marker, colour, text) in CLASS_STYLE.items():
        f = np.concatenate([e.freq[e.classes == code] for e in model.diagram] + [[]])
        n = np.concatenate([np.full(np.sum(e.classes == code), e.order)
                            for e in model.diagram] + [[]])
        face = colour if code != 's' else 'none'
        ax.scatter(f, n, s=14 if code == 's' else 10, marker=marker, c=face,
                   edgecolors=colour if code == 's' else None, lw=0.8, label=text)
    for f_mode in model.freq_hz:
        ax.axvline(f_mode, color='tab:red', lw=0.7, alpha=0.6)
    band = (freq >= model.band[0]) & (freq <= model.band[1])
    twin = ax.twinx()
    total = np.sum(np.abs(H), axis=(0, 1))[band]
    twin.semilogy(freq[band], total / total.max(), 'k', lw=0.7, alpha=0.5)
    twin.set_ylabel('sum |H| (normalised)')
    ax.set_xlim(model.band)
    ax.set_xlabel('frequency [Hz]')
    ax.set_ylabel('model order')
    ax.legend(fontsize=7, loc='upper left')
    ax.grid(True, alpha=0.3)
    ax.set_title(title or f'stability diagram: {len(model.freq_hz)} modes selected (red)')
    return save_figure(fig, path)


def synthesis_plot(model: ModalModel, freq: np.ndarray, H: np.ndarray, labels: Sequence[str],
                   unit: str, path: str | Path, title: str = '') -> Path:
    """
    Measured FRFs against those synthesised from the identified modes (one input).

    Parameters
    ----------
    model : ModalModel
        Identified modes.
    freq : (F,) ndarray
        Frequencies [Hz].
    H : (No, Ni, F) ndarray
        Measured FRFs; the first input is drawn.
    labels : sequence of str
        One label per output.
    unit : str
        Unit of H, e.g. ``'m/N'``.
    path : str or Path
        PNG file.
    title : str
        Figure title.

    Returns
    -------
    Path
    """
    band = (freq >= model.band[0]) & (freq <= model.band[1])
    f = freq[band]
    dense = np.union1d(f, np.linspace(f.min(), f.max(), 4000))
    synth = model.synthesise(dense)
    fig, (ax_mag, ax_ph) = plt.subplots(2, 1, figsize=(8, 7), sharex=True,
                                        gridspec_kw={'height_ratios': [3, 2]})
    for o, label in enumerate(labels):
        line, = ax_mag.semilogy(f, np.abs(H[o, 0, band]), '.', ms=3, label=f'{label} measured')
        colour = line.get_color()
        ax_mag.semilogy(dense, np.abs(synth[o, 0]), '-', color=colour, lw=0.8,
                        label=f'{label} synthesised')
        ax_ph.plot(f, np.degrees(np.angle(H[o, 0, band])), '.', ms=3, color=colour)
        ax_ph.plot(dense, np.degrees(np.angle(synth[o, 0])), '-', color=colour, lw=0.8)
    for f_mode in model.freq_hz:
        ax_mag.axvline(f_mode, color='0.5', lw=0.5, ls=':')
    ax_mag.set_ylabel(f'|H| [{unit}]')
    ax_ph.set_ylabel('phase [deg]')
    ax_ph.set_xlabel('frequency [Hz]')
    ax_mag.legend(fontsize=7)
    for ax in (ax_mag, ax_ph):
        ax.grid(True, which='both', alpha=0.3)
    ax_mag.set_title(title)
    return save_figure(fig, path)
