"""
The report's figures (PNG).

TCP compliance per direction, the controller's identified FRF, the return-difference margin
of its loop, the stability lobes.
"""
from __future__ import annotations

from pathlib import Path
from typing import Sequence

import numpy as np

from pentapod_damper.judge.battery import Judged, PositionResult
from pentapod_sim.figures import save_figure
from pentapod_sim.sim.nyquist import controller_frf

COLOURS = ('0.35', 'tab:red', 'tab:blue', 'tab:green')


def compliance(res: PositionResult, labels: Sequence[str], path: Path) -> Path:
    """|H_dd| per direction: lines (dots), identified model (line), analytic (dashed)."""
    import matplotlib.pyplot as plt
    directions = list(res.dominant)
    fig, axes = plt.subplots(len(directions), 1, figsize=(8, 2.8 * len(directions)),
                             squeeze=False)
    for ax, d in zip(axes[:, 0], directions):
        for colour, label in zip(COLOURS, labels):
            j = res.judged.get(label)
            if j is None or d not in j.multisine:
                continue
            run = j.multisine[d]
            grid = np.geomspace(run.freq[0], run.freq[-1], 4000)
            ax.loglog(run.freq, 1e6 * np.abs(run.H[run.direct]), '.', ms=2, color=colour)
            ax.loglog(grid, 1e6 * np.abs(run.synthesise(grid)), '-', lw=0.8, color=colour,
                      label=f'{label}: measured lines, identified model')
            if d in j.analytic:
                ax.loglog(run.freq, 1e6 * np.abs(j.analytic[d].H), '--', lw=0.8, color=colour,
                          alpha=0.7)
        ax.set_ylabel(f'|x_{d} / F_{d}| [um/N]')
        ax.grid(True, which='both', alpha=0.3)
    axes[0, 0].legend(fontsize=7)
    axes[0, 0].set_title(f'{res.position.name}: TCP compliance from the multisine runs '
                         '(dashed: analytic sampled loop)')
    axes[-1, 0].set_xlabel('frequency [Hz]')
    return save_figure(fig, path)


def controller(j: Judged, dt: float, path: Path) -> Path | None:
    """The identified controller FRF (magnitude, phase, coherence) and the published model."""
    rob = j.robustness
    if rob is None:
        return None
    import matplotlib.pyplot as plt
    frf = rob.frf
    f = frf.freq[1:]
    fig, (mag, phase, coh) = plt.subplots(3, 1, figsize=(8, 7.5), sharex=True)
    model = controller_frf(rob.model, dt)(f) if rob.model is not None else None
    for i, port in enumerate(rob.ports):
        for k, sensor in enumerate(rob.sensors):
            h = frf.H[1:, i, k]
            if not np.any(np.abs(h) > 1e-12 * np.nanmax(np.abs(frf.H[1:]))):
                continue
            line, = mag.loglog(f, np.abs(h), lw=0.9, label=f'{port} / {sensor}')
            phase.semilogx(f, np.degrees(np.angle(h)), lw=0.9, color=line.get_color())
            if model is not None:
                mag.loglog(f, np.abs(model[:, i, k]), '--', color='k', lw=0.6)
                phase.semilogx(f, np.degrees(np.angle(model[:, i, k])), '--', color='k', lw=0.6)
        coh.semilogx(f, frf.coherence[1:, i], lw=0.9, label=port)
    mag.set_ylabel('|K|')
    mag.legend(fontsize=7)
    mag.set_title(f'{j.controller.label}: FRF identified in the loop'
                  + (' (dashed: published model)' if model is not None else ''))
    phase.set_ylabel('phase [deg]')
    coh.set_ylabel('multiple coherence')
    coh.set_ylim(min(0.9, float(np.nanmin(frf.coherence[1:]))) - 0.01, 1.005)
    coh.set_xlabel('frequency [Hz]')
    for ax in (mag, phase, coh):
        ax.grid(True, which='both', alpha=0.3)
    return save_figure(fig, path)


def margins(j: Judged, path: Path) -> Path | None:
    """sigma_min(I - L) over frequency on the plant and the check model."""
    rob = j.robustness
    if rob is None:
        return None
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(8, 3.4))
    for (name, delay), check in sorted(rob.black_box.items()):
        style = '-' if delay == 0 else ':'
        ax.semilogy(check.freq, check.sigma, style, lw=0.8,
                    label=f'identified, {name}{", +1 sample" if delay else ""}: '
                    f'{check.verdict}')
        model = rob.model_nyquist.get((name, delay))
        if model is not None and delay == 0:
            ax.semilogy(model.freq, model.sigma, '--', lw=0.6, color='k',
                        label=f'model, {name}: {model.verdict}')
    ax.set_xlabel('frequency [Hz]')
    ax.set_ylabel('sigma_min(I - L)')
    ax.set_title(f'{j.controller.label}: return difference of the sampled loop')
    ax.grid(True, which='both', alpha=0.3)
    ax.legend(fontsize=7)
    return save_figure(fig, path)
