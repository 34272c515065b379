"""
Pictures of the cause analysis: strain-energy shares per mode and the mode distribution.

Both take the results of :mod:`pentapod_sim.modes.causes`; local frame modes (plate frame)
are marked with a dot above their bar.
"""
from __future__ import annotations

import os
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

if TYPE_CHECKING:
    from pentapod_sim.modes.causes import CauseTable


def plot_energy_shares(table: CauseTable, path: str | os.PathLike[str],
                       n_modes: int | None = None, title: str = '') -> None:
    """
    Save a stacked-bar PNG of each mode's strain-energy shares per group.

    Parameters
    ----------
    table : CauseTable
        The cause table.
    path : path-like
        PNG file to write.
    n_modes : int, optional
        Plot only the first ``n_modes`` modes.
    title : str
        Figure title.
    """
    import matplotlib.pyplot as plt  # only the plots need matplotlib

    m = table.frequencies.size if n_modes is None else min(n_modes, table.frequencies.size)
    x = np.arange(1, m + 1)
    fig, ax = plt.subplots(figsize=(max(6.0, 0.14 * m + 2), 4.0))
    bottom = np.zeros(m)
    for g, name in enumerate(table.group_names):
        share = 100.0 * table.energy_shares[:m, g]
        ax.bar(x, share, bottom=bottom, width=0.85, label=name)
        bottom += share
    step = max(1, m // 15)
    ax.set_xticks(x[::step], [f'{j}\n{f:.0f}' for j, f in
                              zip(x[::step], table.frequencies[:m:step])], fontsize=7)
    if table.local_frame is not None:
        local = np.flatnonzero(np.asarray(table.local_frame[:m]))
        ax.plot(x[local], np.full(local.size, 102.0), 'k.', ms=3, clip_on=False,
                label='local frame mode')
    ax.set_xlabel('mode no. / frequency [Hz]')
    ax.set_ylabel('modal strain energy share [%]')
    ax.set_ylim(0, 100)
    ax.set_title(title or 'strain energy per stiffness group')
    ax.legend(fontsize=7, ncol=3, loc='upper center', bbox_to_anchor=(0.5, -0.2))
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def plot_mode_distribution(frequencies: npt.ArrayLike, path: str | os.PathLike[str],
                           f_max: float | None = None, bin_width: float = 25.0,
                           title: str = '') -> None:
    """
    Save a PNG of the mode distribution: modes per frequency band and count below f.

    Parameters
    ----------
    frequencies : (m,) array_like
        Natural frequencies [Hz].
    path : path-like
        PNG file to write.
    f_max : float, optional
        Upper end of the frequency axis [Hz]; default the highest frequency.
    bin_width : float
        Width of the histogram bands [Hz].
    title : str
        Figure title.
    """
    import matplotlib.pyplot as plt  # only the plots need matplotlib

    f = np.sort(np.asarray(frequencies, dtype=float))
    top = float(f_max if f_max is not None else (f[-1] if f.size else 1.0))
    f = f[f <= top]
    fig, ax = plt.subplots(figsize=(7.0, 3.8))
    bins = np.arange(0.0, top + bin_width, bin_width).tolist()
    ax.hist(f, bins=bins, color='tab:blue', alpha=0.7)
    ax.set_xlabel('frequency [Hz]')
    ax.set_ylabel(f'modes per {bin_width:g} Hz band')
    ax.set_xlim(0.0, top)
    ax2 = ax.twinx()
    ax2.step(np.concatenate([[0.0], f, [top]]), np.concatenate([[0], np.arange(1, f.size + 1),
                                                               [f.size]]),
             where='post', color='tab:red')
    ax2.set_ylabel('number of modes below f', color='tab:red')
    ax2.set_ylim(0, max(f.size, 1) * 1.05)
    ax.set_title(title or f'{f.size} modes below {top:g} Hz')
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
