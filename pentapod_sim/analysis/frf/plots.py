"""
PNG plots of measured FRFs, time signals and actuator amplitudes (matplotlib, Agg backend).

Plotting is kept apart from computing: every function takes results and writes one file.
"""
from pathlib import Path
from typing import Optional, Sequence

import matplotlib

matplotlib.use('Agg')
import matplotlib.pyplot as plt  # noqa: E402  (backend must be chosen first)
import numpy as np  # noqa: E402

from pentapod_sim.analysis.bag.reader import Series  # noqa: E402
from pentapod_sim.analysis.frf.estimation import FrfResult  # noqa: E402
from pentapod_sim.analysis.frf.peaks import Resonance  # noqa: E402
from pentapod_sim.figures import save_figure  # noqa: E402


def frf_plot(results: Sequence[FrfResult], path: str | Path,
             analytic: Optional[tuple[np.ndarray, np.ndarray, str]] = None,
             resonances: Optional[Sequence[Resonance]] = None, fmin: float = 0.0,
             fmax: Optional[float] = None, title: str = '') -> Path:
    """
    Bode magnitude, phase and coherence of measured FRFs, optionally with an analytic FRF.

    Parameters
    ----------
    results : sequence of FrfResult
        Measured FRFs (labels from ``result.label``).
    path : str or Path
        PNG file to write.
    analytic : (freq [Hz], H, label), optional
        Reference FRF given as arrays (e.g. from pentapod_sim.plant.frf), same unit as results.
    resonances : sequence of Resonance, optional
        Peaks to mark on the magnitude of the first result.
    fmin, fmax : float
        Plotted band [Hz].
    title : str
        Figure title.

    Returns
    -------
    Path
    """
    fig, (ax_mag, ax_ph, ax_coh) = plt.subplots(3, 1, figsize=(8, 8), sharex=True,
                                                gridspec_kw={'height_ratios': [3, 2, 1]})
    for res in results:
        band = (res.freq > max(fmin, 0.0)) & (res.freq <= (fmax or res.freq[-1]))
        ax_mag.semilogy(res.freq[band], np.abs(res.H[band]), label=res.label or 'measured')
        ax_ph.plot(res.freq[band], np.degrees(np.unwrap(np.angle(res.H[band]))))
        ax_coh.plot(res.freq[band], res.coherence[band])
    if analytic is not None:
        freq, h, label = analytic
        band = (freq > max(fmin, 0.0)) & (freq <= (fmax or freq[-1]))
        ax_mag.semilogy(freq[band], np.abs(h[band]), 'k--', lw=1, label=label)
        ax_ph.plot(freq[band], np.degrees(np.unwrap(np.angle(h[band]))), 'k--', lw=1)
    resonances = list(resonances or ())
    for peak in resonances:
        ax_mag.plot(peak.freq, peak.magnitude, 'rv')
        if len(resonances) > 8:
            continue  # markers only; the numbers are in the _peaks.csv table
        ax_mag.annotate(f'{peak.freq:.1f} Hz\nζ={peak.damping_ratio:.3%}',
                        (peak.freq, peak.magnitude), textcoords='offset points',
                        xytext=(4, 4), fontsize=7)
    unit = results[0].unit if results else ''
    ax_mag.set_ylabel(f'|H| [{unit}]')
    ax_ph.set_ylabel('phase [deg]')
    ax_coh.set_ylabel('coherence')
    ax_coh.set_ylim(0, 1.05)
    ax_coh.set_xlabel('frequency [Hz]')
    ax_mag.legend(fontsize=7)
    for ax in (ax_mag, ax_ph, ax_coh):
        ax.grid(True, which='both', alpha=0.3)
    ax_mag.set_title(title)
    return save_figure(fig, path)


def time_plot(series: Sequence[Series], path: str | Path, title: str = '') -> Path:
    """
    Plot recorded series over time, one axis per series.

    Parameters
    ----------
    series : sequence of Series
        From :meth:`pentapod_sim.analysis.bag.reader.Bag.series`.
    path : str or Path
        PNG file.
    title : str
        Figure title.

    Returns
    -------
    Path
    """
    fig, axes = plt.subplots(len(series), 1, figsize=(8, 2.2 * len(series) + 0.5),
                             sharex=True, squeeze=False)
    for ax, ser in zip(axes[:, 0], series):
        ax.plot(ser.time, ser.values, lw=0.8)
        ax.set_ylabel(f'[{ser.unit}]')
        ax.set_title(ser.label, fontsize=8)
        ax.grid(True, alpha=0.3)
    axes[-1, 0].set_xlabel('time [s]')
    fig.suptitle(title)
    return save_figure(fig, path)


def amplitude_plot(freq: np.ndarray, amplitudes: dict[str, np.ndarray], units: dict[str, str],
                   path: str | Path, title: str = '') -> Path:
    """
    Plot amplitude spectra (e.g. actuator stroke [m] and force [N]) over frequency.

    Parameters
    ----------
    freq : (F,) ndarray
        Frequency [Hz].
    amplitudes : dict
        ``{label: (F,) amplitude}``.
    units : dict
        ``{label: unit}``; labels with the same unit share an axis.
    path : str or Path
        PNG file.
    title : str
        Figure title.

    Returns
    -------
    Path
    """
    by_unit: dict[str, list[tuple[str, np.ndarray]]] = {}
    for label, amp in amplitudes.items():
        by_unit.setdefault(units.get(label, ''), []).append((label, amp))
    fig, axes = plt.subplots(len(by_unit), 1, figsize=(8, 3 * len(by_unit)), sharex=True,
                             squeeze=False)
    for ax, (unit, curves) in zip(axes[:, 0], by_unit.items()):
        for label, amp in curves:
            ax.semilogy(freq[1:], amp[1:], label=label, lw=0.8)
        ax.set_ylabel(f'amplitude [{unit}]')
        ax.legend(fontsize=7)
        ax.grid(True, which='both', alpha=0.3)
    axes[-1, 0].set_xlabel('frequency [Hz]')
    fig.suptitle(title)
    return save_figure(fig, path)

