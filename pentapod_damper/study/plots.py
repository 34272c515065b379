"""PNG figures of the study (matplotlib, Agg); each function writes one file and returns it."""
from __future__ import annotations

from pathlib import Path
from typing import Mapping, Sequence

import matplotlib

matplotlib.use('Agg')
from matplotlib.axes import Axes  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import numpy.typing as npt  # noqa: E402

from pentapod_sim.figures import save_figure  # noqa: E402

Array = npt.NDArray[np.float64]
#: Fixed colour per scenario, so every figure reads the same way.
COLORS = {'baseline': 'black', 'strut_damping_all': 'tab:blue', 'strut_damping_12': 'tab:cyan',
          'axial_damping': 'tab:green', 'tcp_damping': 'tab:red', 'pma_5kg': 'tab:purple',
          'pma_1kg': 'tab:orange'}


def _save(fig: Figure, path: Path) -> Path:
    return save_figure(fig, path, tight=False)


def _mag_axes(title: str, unit: str) -> tuple[Figure, Axes, Axes]:
    fig, (ax_m, ax_p) = plt.subplots(2, 1, figsize=(9, 6.5), sharex=True,
                                     gridspec_kw={'height_ratios': [3, 1]})
    ax_m.set_title(title)
    ax_m.set_ylabel(f'|H| [{unit}]')
    ax_m.set_yscale('log')
    ax_p.set_ylabel('phase [deg]')
    ax_p.set_xlabel('frequency [Hz]')
    ax_p.set_yticks([-180, -90, 0, 90, 180])
    for ax in (ax_m, ax_p):
        ax.grid(True, which='both', alpha=0.3)
    return fig, ax_m, ax_p


def baseline_frf_plot(freq: np.ndarray, curves: Mapping[str, np.ndarray],
                      mode_freqs: np.ndarray, title: str, path: Path) -> Path:
    """Direct TCP FRFs (label -> complex H [m/N]) with the kept modes' frequencies ticked."""
    fig, ax_m, ax_p = _mag_axes(title, 'm/N')
    for label, h in curves.items():
        ax_m.plot(freq, np.abs(h), lw=1, label=label)
        ax_p.plot(freq, np.degrees(np.angle(h)), lw=0.8)
    top = ax_m.get_ylim()[1]
    for f in mode_freqs[mode_freqs <= freq[-1]]:
        ax_m.axvline(f, color='grey', lw=0.4, alpha=0.5)
    ax_m.set_ylim(top=top)
    ax_m.legend(loc='upper right')
    ax_m.text(0.01, 0.02, f'{np.sum(mode_freqs <= freq[-1])} modes of the reduced model below '
              f'{freq[-1]:.0f} Hz (grey lines)', transform=ax_m.transAxes, fontsize=8)
    return _save(fig, path)


def damping_plot(freq: np.ndarray, analytic: Mapping[str, np.ndarray],
                 measured: Mapping[str, tuple[Array, npt.NDArray[np.complex128]]],
                 title: str, path: Path,
                 unit: str = 'm/N') -> Path:
    """
    Compare scenarios: analytic FRFs as lines, FRFs measured on the testbed as dots.

    Parameters
    ----------
    analytic : mapping
        Scenario -> complex H on ``freq``.
    measured : mapping
        Scenario -> (freq, complex H) estimated from the run's bag (may be empty).
    """
    fig, ax_m, ax_p = _mag_axes(title, unit)
    for name, h in analytic.items():
        color = COLORS.get(name)
        ax_m.plot(freq, np.abs(h), color=color, lw=1.1, label=f'{name} (analytic)')
        ax_p.plot(freq, np.degrees(np.angle(h)), color=color, lw=0.8)
    for name, (f_m, h_m) in measured.items():
        keep = f_m <= freq[-1]
        ax_m.plot(f_m[keep], np.abs(h_m[keep]), '.', ms=2, color=COLORS.get(name),
                  label=f'{name} (testbed run)')
    ax_m.legend(fontsize=7, ncol=2, loc='upper right')
    return _save(fig, path)


def pma_requirements_plot(freq: np.ndarray, curves: Mapping[str, tuple[Array, Array]],
                          measured: Mapping[str, tuple[Array, Array, Array]],
                          force_amplitude: float, path: Path,
                          variants: Mapping[str, tuple[Array, Array]] | None = None,
                          band: Sequence[float] | None = None,
                          marks: Sequence[float] = ()) -> Path:
    """
    Stroke [mm] and force [N] amplitudes over frequency per PMA (analytic + measured).

    ``variants`` (name -> (stroke, force) on ``freq``) are drawn dashed, e.g. the high-pass
    variant of each PMA; ``band`` is shaded and ``marks`` (stated frequencies [Hz]) are
    drawn as vertical lines.
    """
    fig, (ax_s, ax_f) = plt.subplots(2, 1, figsize=(9, 6.5), sharex=True)
    ax_s.set_title(f'Proof-mass actuator requirements for a +-{force_amplitude:g} N '
                   'harmonic TCP force')
    for name, (stroke, force) in curves.items():
        ax_s.semilogy(freq, stroke * 1e3, color=COLORS.get(name), label=f'{name} (analytic)')
        ax_f.semilogy(freq, force, color=COLORS.get(name))
    for name, (stroke, force) in (variants or {}).items():
        color = COLORS.get(name.split()[0])
        ax_s.semilogy(freq, stroke * 1e3, '--', color=color, lw=1, label=name)
        ax_f.semilogy(freq, force, '--', color=color, lw=1)
    for name, (f_m, stroke, force) in measured.items():
        ax_s.semilogy(f_m, stroke * 1e3, '.', ms=2, color=COLORS.get(name),
                      label=f'{name} (testbed run)')
        ax_f.semilogy(f_m, force, '.', ms=2, color=COLORS.get(name))
    for ax in (ax_s, ax_f):
        if band is not None:
            ax.axvspan(band[0], band[1], color='grey', alpha=0.08)
        for f in marks:
            ax.axvline(f, color='grey', lw=0.8, ls=':')
        ax.set_xscale('log')            # the ideal law's stroke grows as 1/f at low frequency
        ax.grid(True, which='both', alpha=0.3)
    ax_s.set_ylabel('stroke amplitude [mm]')
    ax_f.set_ylabel('force amplitude [N]')
    ax_f.set_xlabel('frequency [Hz]')
    ax_s.legend(fontsize=7)
    return _save(fig, path)


def step_response_plot(runs: Mapping[str, tuple[Array, Array, Array]], amplitude: float,
                       path: Path) -> Path:
    """PMA stroke [mm] and force [N] after a TCP force step; runs: name -> (t, stroke, force)."""
    fig, (ax_s, ax_f) = plt.subplots(2, 1, figsize=(9, 6), sharex=True)
    ax_s.set_title(f'Proof-mass actuator after a {amplitude:g} N step force at the TCP')
    for name, (t, stroke, force) in runs.items():
        ax_s.plot(t, stroke * 1e3, color=COLORS.get(name), label=name)
        ax_f.plot(t, force, color=COLORS.get(name))
    ax_s.set_ylabel('stroke [mm]')
    ax_f.set_ylabel('force on the WP [N]')
    ax_f.set_xlabel('time [s]')
    for ax in (ax_s, ax_f):
        ax.grid(True, alpha=0.3)
    ax_s.legend()
    return _save(fig, path)


def gain_sweep_plot(gains: npt.ArrayLike, ratios: Mapping[str, np.ndarray], chosen: float,
                    title: str, path: Path, unit: str = 'N m s/rad',
                    marks: Mapping[str, float] | None = None) -> Path:
    """Peak reduction factor of the TCP FRF over a strut damper gain [``unit``]."""
    fig, ax = plt.subplots(figsize=(8, 4.5))
    for label, r in ratios.items():
        ax.semilogx(gains, r, marker='o', ms=3, label=label)
    ax.axvline(chosen, color='grey', ls='--', label=f'scenario gain {chosen:g} {unit}')
    for (label, value), style in zip((marks or {}).items(), (':', '-.', (0, (1, 3)), '--')):
        ax.axvline(value, color='k', ls=style, lw=0.8, label=label)
    ax.set_xlabel(f'damper gain b [{unit}]')
    ax.set_ylabel('peak |H| baseline / damped [-]')
    ax.set_title(title)
    ax.grid(True, which='both', alpha=0.3)
    ax.legend(fontsize=8)
    return _save(fig, path)
