"""Pictures of the analytic FRFs and of the modes' static contributions (PNG files)."""
from __future__ import annotations

from pathlib import Path
from typing import Sequence

import numpy as np
import numpy.typing as npt

from pentapod_sim.figures import save_figure
from pentapod_sim.plant.frf import FrfResult


def frf_plot(results: Sequence[FrfResult], output: str, input_: str, path: str | Path,
             mode_freqs: Sequence[Sequence[float] | npt.NDArray[np.float64]] | None = None,
             title: str = '') -> Path:
    """
    Bode plot (log magnitude, phase) of one pair for several FRFs; PNG at ``path``.

    ``mode_freqs[k]`` [Hz], if given, are marked as ticks along the top for result k.
    """
    import matplotlib.pyplot as plt
    fig, (ax_mag, ax_ph) = plt.subplots(2, 1, sharex=True, figsize=(8, 6),
                                        gridspec_kw={'height_ratios': [2, 1]})
    for k, res in enumerate(results):
        h = res.pair(output, input_)
        line, = ax_mag.semilogy(res.freq, np.abs(h), lw=1, label=res.label or None)
        ax_ph.plot(res.freq, np.degrees(np.angle(h)), lw=1, color=line.get_color())
        if mode_freqs is not None:
            marks = [f for f in mode_freqs[k] if res.freq[0] <= f <= res.freq[-1]]
            ax_mag.plot(marks, np.full(len(marks), 1.0), '|', ms=8, color=line.get_color(),
                        transform=ax_mag.get_xaxis_transform(), clip_on=False)
    unit = f'{res.output_units[res.output_names.index(output)]}/' \
           f'{res.input_units[res.input_names.index(input_)]}'
    ax_mag.set_ylabel(f'|H| [{unit}]')
    ax_ph.set_ylabel('phase [deg]')
    ax_ph.set_xlabel('frequency [Hz]')
    ax_ph.set_yticks([-180, -90, 0, 90, 180])
    ax_mag.set_title(title or f'{output} / {input_}', pad=14)
    for ax in (ax_mag, ax_ph):
        ax.grid(True, which='both', alpha=0.3)
    if any(r.label for r in results):
        ax_mag.legend(loc='lower left')
    return save_figure(fig, path)


def dc_gain_plot(gains: npt.ArrayLike, freq_hz: npt.ArrayLike, path: str | Path,
                 limit: float | None = None, keep: npt.ArrayLike | None = None,
                 title: str = '', unit: str = 'm/N') -> Path:
    """
    Bar chart of |dc gain| per mode (log scale) with the relevance limit line; PNG.

    Parameters
    ----------
    gains : (m,) array_like
        Modal dc gains of one pair.
    freq_hz : (m,) array_like
        Mode frequencies [Hz] (secondary axis labels).
    limit : float, optional
        Absolute relevance limit drawn as a horizontal line.
    keep : array_like of int, optional
        Kept mode indices, drawn in a different colour.
    """
    import matplotlib.pyplot as plt
    g = np.abs(np.asarray(gains, float))
    kept = np.zeros(g.size, bool)
    if keep is not None:
        kept[np.asarray(keep, int)] = True
    fig, ax = plt.subplots(figsize=(9, 4))
    modes = np.arange(1, g.size + 1)
    ax.bar(modes[~kept], g[~kept], color='0.6', width=0.8, label='dropped')
    ax.bar(modes[kept], g[kept], color='tab:blue', width=0.8, label='kept')
    ax.set_yscale('log')
    if limit is not None:
        ax.axhline(limit, color='tab:red', lw=1, label=f'limit {limit:g} {unit}')
    ax.set_xlabel('mode number')
    ax.set_ylabel(f'|dc gain| [{unit}]')
    freq = np.asarray(freq_hz, float)
    ax.set_title(title or f'dc gain per mode ({freq[0]:.1f} .. {freq[-1]:.1f} Hz)')
    ax.set_ylim(bottom=max(g[g > 0].min() if np.any(g > 0) else 1e-20, 1e-6 * g.max()))
    ax.legend()
    ax.grid(True, axis='y', which='both', alpha=0.3)
    return save_figure(fig, path)

