"""
Figures of a sweep (matplotlib, Agg): x-y maps per slice, the share map, the claim summary.

A slice is one (z, a, b) of the poses; its map shows a metric over x and y, with unreachable
poses marked ``x`` (grey) and failed ones ``!`` (red). The share map draws the paper's 70 %
line. Every function writes PNGs through :func:`pentapod_sim.figures.save_figure` and returns
their paths.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use('Agg')
from matplotlib.axes import Axes  # noqa: E402
from matplotlib.colors import Normalize, TwoSlopeNorm  # noqa: E402
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import numpy.typing as npt  # noqa: E402
import pyarrow as pa  # noqa: E402

from pentapod_damper.sweep.store import as_arrays  # noqa: E402
from pentapod_sim.figures import save_figure  # noqa: E402

#: Columns of a result table as arrays (:func:`pentapod_damper.sweep.store.as_arrays`).
Data = dict[str, npt.NDArray[Any]]
#: One slice of the poses: z [m], a [rad], b [rad].
Slice = tuple[float, float, float]
#: x and y axes [m], the (ny, nx) values and the status of each pose of one slice.
Grid = tuple[npt.NDArray[Any], npt.NDArray[Any], npt.NDArray[Any], npt.NDArray[Any]]
#: The paper's claim: struts 1 and 2 give at least this share of the all-struts benefit.
CLAIM = 0.7
DIRS = ('xx', 'yy', 'zz')
#: Display scale and unit of stored units.
DISPLAY = {'m/N': (1e6, 'um/N'), 'm': (1e3, 'mm'), '-': (1.0, '-'), 'Hz': (1.0, 'Hz'),
           'N': (1.0, 'N')}


def slices(data: Data) -> list[Slice]:
    """Distinct (z [m], a [rad], b [rad]) of the poses, rounded to 1 um / 1 urad."""
    keys = np.round(np.stack([data['z'], data['a'], data['b']], axis=1), 6)
    return [(float(z), float(a), float(b)) for z, a, b in np.unique(keys, axis=0)]


def slice_name(zab: Slice) -> str:
    """File-name part of a slice, e.g. ``z0.850_a0.0_b10.0`` (tilts in degrees)."""
    z, a, b = zab
    return f'z{z:.3f}_a{np.degrees(a):.1f}_b{np.degrees(b):.1f}'


def _grid(data: Data, zab: Slice, name: str) -> Grid | None:
    """x, y axes and the (ny, nx) values of one slice; None if it is not a 2-D grid."""
    sel = np.all(np.isclose(np.stack([data['z'], data['a'], data['b']], axis=1), zab,
                            atol=1e-6), axis=1)
    xs, ys = np.unique(np.round(data['x'][sel], 6)), np.unique(np.round(data['y'][sel], 6))
    if xs.size < 2 or ys.size < 2:
        return None
    values = np.full((ys.size, xs.size), np.nan)
    status = np.full((ys.size, xs.size), '', dtype=object)
    ix = np.searchsorted(xs, np.round(data['x'][sel], 6))
    iy = np.searchsorted(ys, np.round(data['y'][sel], 6))
    values[iy, ix] = data[name][sel] if name in data else np.nan
    status[iy, ix] = data['status'][sel]
    return xs, ys, values, status


def _panel(ax: Axes, grid: Grid, title: str, unit: str, contour: float | None = None,
           vlim: tuple[float, float] | None = None, cmap: str = 'viridis') -> None:
    xs, ys, values, status = grid
    scale, shown = DISPLAY.get(unit, (1.0, unit))
    if unit == '-' and contour is not None:
        scale, shown = 100.0, '%'
    z = values * scale
    finite = z[np.isfinite(z)]
    if vlim is None and finite.size:
        vlim = (finite.min(), finite.max())
    norm: Normalize | None
    if contour is not None and vlim is not None:    # the claim's value in the colour map's middle
        norm = TwoSlopeNorm(contour * scale, vlim[0], vlim[1])
    else:
        norm = Normalize(*vlim) if vlim is not None else None
    mesh = ax.pcolormesh(xs, ys, np.ma.masked_invalid(z), shading='nearest', cmap=cmap,
                         norm=norm)
    plt.colorbar(mesh, ax=ax, label=shown, shrink=0.9)
    if contour is not None and finite.size and np.nanmin(z) < contour * scale < np.nanmax(z):
        lines = ax.contour(xs, ys, np.ma.masked_invalid(z), levels=[contour * scale],
                           colors='k', linewidths=1.5)
        ax.clabel(lines, fmt=lambda v: f'{v:.0f} %', fontsize=8)
    for mark, state, color in (('x', 'unreachable', '0.5'), ('$!$', 'failed', 'red')):
        iy, ix = np.nonzero(status == state)
        ax.scatter(xs[ix], ys[iy], marker=mark, c=color, s=20, linewidths=0.8)
    ax.set_title(title, fontsize=9)
    ax.set_xlabel('x [m]')
    ax.set_ylabel('y [m]')
    ax.set_aspect('equal')


def map_figure(data: Data, units: dict[str, str], zab: Slice, panels: list[tuple[str, str]],
               path: Path, title: str, contour: float | None = None,
               vlim: tuple[float, float] | None = None, cmap: str = 'viridis',
               ncols: int = 3) -> Path | None:
    """
    One figure of x-y maps of a slice, a panel per (column, panel title).

    Returns None if the slice is not a 2-D grid or no column is present.
    """
    panels = [(c, t) for c, t in panels if c in data]
    if not panels or _grid(data, zab, panels[0][0]) is None:
        return None
    nrows = int(np.ceil(len(panels) / ncols))
    ncols = min(ncols, len(panels))
    fig, axes = plt.subplots(nrows, ncols, figsize=(4.3 * ncols, 3.6 * nrows), squeeze=False)
    for ax, (col, text) in zip(axes.flat, panels):
        grid = _grid(data, zab, col)
        assert grid is not None                 # the same poses as the first panel's
        _panel(ax, grid, text, units.get(col, '-'), contour, vlim, cmap)
    for ax in list(axes.flat)[len(panels):]:
        ax.set_visible(False)
    z, a, b = zab
    fig.suptitle(f'{title}  (z = {z:.3f} m, a = {np.degrees(a):.1f} deg, '
                 f'b = {np.degrees(b):.1f} deg; x: unreachable)', fontsize=10)
    return save_figure(fig, path)


def _labels(data: Data) -> list[str]:
    """Damped loop labels present in the columns."""
    return sorted({c[len('peak_xx_'):] for c in data if c.startswith('peak_xx_')} - {'open'})


def _reductions(data: Data) -> None:
    """Add ``red_{kind}_{dd}_{label}`` = open / damped (peak and RMS) columns."""
    for label in _labels(data):
        for kind in ('peak', 'rms'):
            for dd in DIRS:
                data[f'red_{kind}_{dd}_{label}'] = (data[f'{kind}_{dd}_open']
                                                    / data[f'{kind}_{dd}_{label}'])


def all_figures(table: pa.Table, schema: pa.Schema, fig_dir: str | Path,
                groups: tuple[str, ...] | None = None) -> list[Path]:
    """
    Maps of every slice and the claim summary; returns the written files.

    ``groups`` limits the maps to some of ``modes``, ``compliance``, ``share`` and ``loop``
    (default all).
    """
    fig_dir = Path(fig_dir)
    data = as_arrays(table)
    if not data.get('key', np.array([])).size:
        return []
    units = {f.name: (f.metadata or {}).get(b'unit', b'-').decode() for f in schema}
    _reductions(data)
    paths = []
    for zab in slices(data):
        name = slice_name(zab)
        figures: list[tuple[str, str, list[tuple[str, str]], dict[str, Any]]] = [
            ('modes', 'First frame and strut mode, dominant modes',
             [('frame_mode_f', 'first frame mode'), ('strut_mode_f', 'first strut mode'),
              ('n_modes_kept', 'modes kept')]
             + [(f'dom_f_{dd}', f'dominant mode of {dd}') for dd in DIRS], {}),
            ('compliance', 'TCP compliance without added damping',
             [(f'{k}_{dd}_open', f'{k} |H_{dd}|') for k in ('peak', 'rms') for dd in DIRS], {}),
            ('share', 'Struts 1+2 share of the all-struts improvement (70 % line)',
             [(f'share_{k}_{dd}', f'share by {k}, {dd}') for k in ('peak', 'rms')
              for dd in DIRS], {'contour': CLAIM, 'vlim': (0, 100), 'cmap': 'RdYlGn'})]
        for label in _labels(data):
            figures.append((f'loop_{label}', f'{label}: reduction open/damped and damping',
                            [(f'red_{k}_{dd}_{label}', f'{k} reduction {dd}')
                             for k in ('peak', 'rms') for dd in DIRS]
                            + [(f'zeta_{dd}_{label}', f'zeta of the {dd} dominant mode')
                               for dd in DIRS]
                            + [(c, c.split('_' + label)[0].replace('_', ' ')) for c in data
                               if c.startswith('pma_') and c.endswith('_' + label)], {}))
        for stem, title, panels, style in figures:
            if groups is not None and stem.split('_')[0] not in groups:
                continue
            units.update({c: units.get(c, '-') for c, _ in panels})
            units.update({c: '-' for c, _ in panels if c.startswith('red_')})
            path = map_figure(data, units, zab, panels, fig_dir / f'{stem}_{name}.png', title,
                              **style)
            if path is not None:
                paths.append(path)
    summary = claim_summary(data, fig_dir / 'claim_summary.png')
    return paths + ([summary] if summary else [])


def claim_fractions(data: Data) -> dict[tuple[str, str], tuple[int, int]]:
    """(kind, dd) -> (poses where the share is >= 70 %, poses with a share) over ok poses."""
    ok = data['status'] == 'ok'
    out = {}
    for kind in ('peak', 'rms'):
        for dd in DIRS:
            col = f'share_{kind}_{dd}'
            if col not in data:
                continue
            share = data[col][ok]
            valid = np.isfinite(share)
            out[(kind, dd)] = (int(np.sum(share[valid] >= CLAIM)), int(valid.sum()))
    return out


def claim_lines(table: pa.Table) -> list[str]:
    """Text summary: where the 70 % claim holds, by direction."""
    data = as_arrays(table)
    if not data.get('key', np.array([])).size:
        return []
    fractions = claim_fractions(data)
    lines = [f'struts 1+2 share >= {CLAIM:.0%} of the all-struts improvement '
             f'({int(np.sum(data["status"] == "ok"))} reachable poses):']
    for (kind, dd), (hold, n) in fractions.items():
        lines.append(f'  {kind:4} {dd}: {hold}/{n} poses ({hold / n:.0%})' if n else
                     f'  {kind:4} {dd}: no pose with a share')
    return lines


def claim_summary(data: Data, path: Path) -> Path | None:
    """Bar chart: fraction of reachable poses where the 70 % claim holds, by direction."""
    fractions = claim_fractions(data)
    if not fractions:
        return None
    fig, ax = plt.subplots(figsize=(6.0, 3.8))
    width = 0.38
    for k, kind in enumerate(('peak', 'rms')):
        vals = [fractions.get((kind, dd), (0, 0)) for dd in DIRS]
        frac = [100.0 * h / n if n else 0.0 for h, n in vals]
        bars = ax.bar(np.arange(3) + (k - 0.5) * width, frac, width, label=f'by {kind}')
        for bar, (h, n) in zip(bars, vals):
            ax.annotate(f'{h}/{n}', (bar.get_x() + bar.get_width() / 2, bar.get_height()),
                        ha='center', va='bottom', fontsize=8)
    ax.set_xticks(range(3), [f'TCP {dd}' for dd in DIRS])
    ax.set_ylim(0, 110)
    ax.set_ylabel(f'poses with share >= {CLAIM:.0%} [%]')
    ax.set_title('Where damping struts 1+2 gives >= 70 % of the all-struts benefit', fontsize=10)
    ax.legend(fontsize=8, loc='upper right')
    ax.grid(True, axis='y', alpha=0.3)
    return save_figure(fig, path)
