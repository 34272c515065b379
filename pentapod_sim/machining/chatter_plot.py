"""
The figure and table of one cutting run's chatter verdict: PNG and CSV.

:func:`chatter_figure` draws the TCP displacement over time with the once-per-tooth samples
(the Poincare section) marked, the section itself in the x-y plane (a point for a stable cut,
a circle for Hopf chatter, two points for period doubling) and the displacement's spectrum
with the tooth-passing harmonics and the chatter frequency. :func:`write_chatter_csv` writes
the section (time [s], x, y [m]) and a one-row summary.
"""
from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np
import numpy.typing as npt

from pentapod_sim.figures import save_figure
from pentapod_sim.machining.chatter import ChatterVerdict

SUMMARY_COLUMNS = ('verdict', 'growth_rate_per_s', 'off_harmonic_share', 'chatter_Hz',
                   'tooth_passing_Hz', 'left_cut_share', 'poincare_samples')


def summary_row(verdict: ChatterVerdict) -> list[str | float | int]:
    """The verdict's figures in the order of :data:`SUMMARY_COLUMNS`."""
    return [verdict.verdict, verdict.growth_rate, verdict.off_harmonic_share,
            verdict.chatter_freq, verdict.tooth_freq, verdict.left_cut_share,
            int(verdict.poincare.shape[0])]


def section_times(verdict: ChatterVerdict, start: float) -> npt.NDArray[np.float64]:
    """Times [s] of the Poincare samples of a verdict whose window starts at ``start``."""
    return start + np.arange(verdict.poincare.shape[0]) / verdict.tooth_freq


def write_chatter_csv(verdict: ChatterVerdict, start: float, stem: Path,
                      extra: dict[str, float | str] | None = None) -> tuple[Path, Path]:
    """
    ``<stem>_poincare.csv`` (time [s], x, y [m]) and ``<stem>_summary.csv`` (one row).

    ``extra`` columns (the operation, speed, depth, ...) come first in the summary.
    """
    stem.parent.mkdir(parents=True, exist_ok=True)
    section = stem.with_name(stem.name + '_poincare.csv')
    with open(section, 'w', newline='', encoding='utf-8') as handle:
        writer = csv.writer(handle)
        writer.writerow(['time_s', 'tcp_x_m', 'tcp_y_m'])
        writer.writerows(zip(section_times(verdict, start).tolist(),
                             *verdict.poincare.T.tolist()))
    summary = stem.with_name(stem.name + '_summary.csv')
    extra = dict(extra or {})
    with open(summary, 'w', newline='', encoding='utf-8') as handle:
        writer = csv.writer(handle)
        writer.writerow([*extra, *SUMMARY_COLUMNS])
        writer.writerow([*extra.values(), *summary_row(verdict)])
    return section, summary


def chatter_figure(time: npt.ArrayLike, displacement: npt.ArrayLike, verdict: ChatterVerdict,
                   start: float, path: Path, title: str = '') -> Path:
    """
    Time record, Poincare section and spectrum of a cut (module docstring) as a PNG.

    Parameters
    ----------
    time, displacement : (n,) and (n, 2) array_like
        The whole record [s], TCP x, y [m].
    verdict : ChatterVerdict
        :func:`pentapod_sim.machining.chatter.detect_chatter` of the record.
    start : float
        Start [s] of the judged window (after the entry transient).
    """
    import matplotlib.pyplot as plt  # imported here: the numerical core loads without it
    t = np.asarray(time, dtype=float)
    x = np.asarray(displacement, dtype=float).reshape(t.size, -1) * 1e6
    times, section = section_times(verdict, start), verdict.poincare * 1e6
    fig = plt.figure(figsize=(11.0, 6.5))
    grid = fig.add_gridspec(2, 2, width_ratios=(2.2, 1.0))
    ax_t = fig.add_subplot(grid[0, 0])
    for axis, name in enumerate('xy'[:x.shape[1]]):
        line, = ax_t.plot(t, x[:, axis], lw=0.6, label=f'TCP {name}')
        ax_t.plot(times, section[:, axis], '.', ms=2.5, color=line.get_color())
    ax_t.axvline(start, color='k', ls=':', lw=0.8)
    ax_t.set_xlabel('time [s]')
    ax_t.set_ylabel('displacement [um]')
    ax_t.legend(fontsize=8, loc='upper left')
    ax_t.set_title('TCP displacement; dots: once per tooth (judged right of the dotted line)',
                   fontsize=9)
    ax_p = fig.add_subplot(grid[:, 1])
    if section.shape[1] >= 2:
        dots = ax_p.scatter(section[:, 0], section[:, 1], c=times, s=6, cmap='viridis')
        fig.colorbar(dots, ax=ax_p, label='time [s]')
        ax_p.set_xlabel('TCP x [um]')
        ax_p.set_ylabel('TCP y [um]')
        ax_p.set_aspect('equal', adjustable='datalim')
    ax_p.set_title('Poincare section (once per tooth)', fontsize=9)
    ax_f = fig.add_subplot(grid[1, 0])
    keep = t >= start
    part = x[keep] - x[keep].mean(axis=0)
    dt = float(np.median(np.diff(t)))
    spec = np.sqrt(np.sum(np.abs(np.fft.rfft(part * np.hanning(part.shape[0])[:, None],
                                             axis=0)) ** 2, axis=1))
    freq = np.fft.rfftfreq(part.shape[0], dt)
    top = min(freq[-1], 8.0 * verdict.tooth_freq)
    band = freq <= top
    ax_f.semilogy(freq[band], spec[band] / max(spec[band].max(), 1e-300), lw=0.7)
    for k in range(1, int(top / verdict.tooth_freq) + 1):
        ax_f.axvline(k * verdict.tooth_freq, color='grey', ls=':', lw=0.7)
    if math.isfinite(verdict.chatter_freq):
        ax_f.axvline(verdict.chatter_freq, color='r', lw=1.0,
                     label=f'chatter {verdict.chatter_freq:.1f} Hz')
        ax_f.legend(fontsize=8)
    ax_f.set_xlabel('frequency [Hz] (dotted: tooth-passing harmonics)')
    ax_f.set_ylabel('|X| (normalised)')
    ax_f.set_title(f'{verdict.off_harmonic_share:.1%} of the power off the harmonics',
                   fontsize=9)
    fig.suptitle(title or f'verdict: {verdict.verdict}', fontsize=10)
    return save_figure(fig, path)
