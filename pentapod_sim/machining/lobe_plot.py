"""
The lobe diagram: stable depth against spindle speed, one curve per scenario, as PNG and CSV.

:func:`lobe_diagram` takes one :class:`~pentapod_sim.machining.lobes.StabilityLimit` per
scenario (analytic or measured FRF, same cut), computes the envelopes on one speed grid and
writes ``<stem>.png``, ``<stem>.csv`` (speed, then depth [m], chatter frequency [Hz] and lobe
number per scenario) and ``<stem>_summary.csv`` (one row per scenario: the minimum stable
depth over all speeds, the lowest depth in the speed range and the deepest pocket).
"""
from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np
import numpy.typing as npt

from pentapod_sim.errors import ConfigError
from pentapod_sim.figures import save_figure
from pentapod_sim.machining.lobes import LobeEnvelope, StabilityLimit

SUMMARY_COLUMNS = ('label', 'min_depth_m', 'min_depth_chatter_Hz', 'min_depth_resolved',
                   'lowest_in_range_m', 'lowest_in_range_rpm', 'best_pocket_m',
                   'best_pocket_rpm')


@dataclass(frozen=True)
class LobeSummary:
    """
    The figures of one scenario's lobe diagram.

    Attributes
    ----------
    label : str
        Scenario.
    min_depth, min_depth_freq : float
        Minimum stable depth over all speeds [m] (the absolute stability limit) and its
        chatter frequency [Hz].
    resolved : bool
        False if the FRF's frequency grid is too coarse at that minimum (it may be lower).
    lowest_in_range, lowest_speed : float
        Lowest limiting depth within the speed range [m] and its speed [rpm].
    pocket_depth, pocket_speed : float
        Depth [m] and speed [rpm] of the deepest pocket between lobes in the range.
    """

    label: str
    min_depth: float
    min_depth_freq: float
    resolved: bool
    lowest_in_range: float
    lowest_speed: float
    pocket_depth: float
    pocket_speed: float

    def row(self) -> list[str | float | bool]:
        """The values in the order of :data:`SUMMARY_COLUMNS`."""
        return [self.label, self.min_depth, self.min_depth_freq, self.resolved,
                self.lowest_in_range, self.lowest_speed, self.pocket_depth, self.pocket_speed]


@dataclass(frozen=True)
class LobeDiagram:
    """What :func:`lobe_diagram` computed and wrote."""

    envelopes: list[LobeEnvelope]
    summaries: list[LobeSummary]
    png: Path
    csv: Path
    summary_csv: Path


def summarise(limit: StabilityLimit, envelope: LobeEnvelope) -> LobeSummary:
    """The minimum stable depth and the best pocket of one scenario."""
    low = limit.minimum()
    speed, depth = envelope.lowest()
    pocket_speed, pocket_depth = envelope.best_pocket()
    return LobeSummary(limit.label, low.depth, low.freq_hz, low.resolved, depth, speed,
                       pocket_depth, pocket_speed)


def lobe_diagram(limits: Sequence[StabilityLimit], speeds_rpm: npt.ArrayLike,
                 stem: str | Path, title: str = '') -> LobeDiagram:
    """
    Envelopes, summaries and the PNG/CSV files of one lobe diagram.

    Parameters
    ----------
    limits : sequence of StabilityLimit
        One per scenario; their labels name the curves (and must differ).
    speeds_rpm : array_like
        Increasing spindle speeds [rpm].
    stem : str or Path
        Output path without suffix; folders are created.
    title : str
        Figure title.
    """
    labels = [lim.label for lim in limits]
    if not limits or len(set(labels)) != len(labels):
        raise ConfigError(f'a lobe diagram needs scenarios with distinct labels, got {labels}')
    speeds = np.asarray(speeds_rpm, dtype=float)
    envelopes = [lim.envelope(speeds) for lim in limits]
    summaries = [summarise(lim, env) for lim, env in zip(limits, envelopes)]
    stem = Path(stem)
    stem.parent.mkdir(parents=True, exist_ok=True)
    table = stem.with_name(stem.name + '.csv')
    with open(table, 'w', newline='', encoding='utf-8') as handle:
        writer = csv.writer(handle)
        writer.writerow(['speed_rpm'] + [f'{e.label}:{c}' for e in envelopes
                                         for c in ('depth_m', 'chatter_Hz', 'lobe')])
        columns = [speeds] + [c for e in envelopes for c in (e.depth, e.chatter_freq, e.lobe)]
        writer.writerows(zip(*[c.tolist() for c in columns]))
    summary = stem.with_name(stem.name + '_summary.csv')
    with open(summary, 'w', newline='', encoding='utf-8') as handle:
        writer = csv.writer(handle)
        writer.writerow(SUMMARY_COLUMNS)
        writer.writerows(s.row() for s in summaries)
    png = _plot(envelopes, summaries, stem.with_name(stem.name + '.png'), title)
    return LobeDiagram(envelopes, summaries, png, table, summary)


def _plot(envelopes: Sequence[LobeEnvelope], summaries: Sequence[LobeSummary], path: Path,
          title: str) -> Path:
    import matplotlib.pyplot as plt  # imported here: the numerical core loads without it
    fig, ax = plt.subplots(figsize=(8.0, 4.5))
    lows = [s.min_depth for s in summaries if np.isfinite(s.min_depth)]
    finite = [e.depth[np.isfinite(e.depth)] for e in envelopes]
    top = max((np.percentile(f, 90) for f in finite if f.size), default=1e-3) * 1.5e3
    for env, summ in zip(envelopes, summaries):
        line, = ax.plot(env.speed, np.minimum(env.depth, 1e3) * 1e3,
                        label=f'{env.label}: min {summ.min_depth * 1e3:.3g} mm')
        ax.axhline(summ.min_depth * 1e3, color=line.get_color(), ls=':', lw=0.8)
        ax.plot(summ.pocket_speed, summ.pocket_depth * 1e3, 'v', color=line.get_color())
    if lows and max(lows) > 5 * min(lows):      # scenarios far apart: a log axis shows both
        ax.set_yscale('log')
        ax.set_ylim(0.5e3 * min(lows), top)
    else:
        ax.set_ylim(0.0, top)
    ax.set_xlabel('spindle speed [rpm]')
    ax.set_ylabel('limiting axial depth [mm]')
    ax.set_title(title or 'stability lobes (stable below the curve)')
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    return save_figure(fig, path)
