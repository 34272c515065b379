"""
Which subassembly causes each mode: one elasticity at a time, and modal strain energy.

Two views, both on the stiffness groups of :class:`pentapod_sim.fe.model.FEModel`:

* **One elasticity at a time** (after Neuber): for group g the model is re-solved with
  ``K_g = K_group_g + alpha * (K - K_group_g)``, i.e. every other elasticity made (nearly)
  rigid. A full-model mode that reappears in that model (mass-weighted MAC above a limit) at a
  frequency close to its own is caused by group g. Because ``K_g >= K``, the i-th frequency
  can only rise; for a mode caused by g alone it stays put, and for a fundamental mode
  ``(f / f_g)^2`` estimates g's share (Dunkerley). ``alpha = 1e4`` moves modes of the other
  groups up by about ``sqrt(alpha) = 100``, far above the analysed band, while ``K_g`` stays
  well conditioned for LU in double precision; :func:`neuber_frequencies` can be rerun with
  other values to check the sensitivity.
* **Modal strain energy**: ``E_g = phi^T K_g phi / omega^2`` for mass-normalised ``phi``; the
  shares of one mode sum to one because the groups sum to K.

Units: frequencies [Hz], omega [rad/s], stiffness [N/m, N m/rad], mass [kg, kg m^2].
"""
from __future__ import annotations

import csv
from dataclasses import dataclass
import logging
import os
from typing import Callable, Mapping, TYPE_CHECKING

import numpy as np
import numpy.typing as npt
import scipy.sparse as sp

from pentapod_sim.modes.solver import ModalResult, solve_modes

if TYPE_CHECKING:
    from pentapod_sim.fe.model import FEModel

_LOG = logging.getLogger(__name__)

#: Stiffness factor for "rigid" groups in the one-elasticity-at-a-time models [-].
DEFAULT_ALPHA = 1.0e4
#: Least mass-weighted MAC for a mode of a one-elasticity model to count as the same mode.
DEFAULT_MAC_MIN = 0.5
#: Lever arm [m] that makes a rotation [rad] comparable with a translation [m] when naming a
#: mode's TCP direction: a tool-length scale (the TCP is 0.15 m below the spindle nose).
DEFAULT_ROTATION_LENGTH = 0.1
#: Names of the six components of a point's observation matrix.
DIRECTIONS = ('x', 'y', 'z', 'rx', 'ry', 'rz')


@dataclass(frozen=True)
class CauseTable:
    """
    Cause of every mode.

    Attributes
    ----------
    frequencies : (m,) ndarray
        Natural frequencies of the full model [Hz].
    group_names : tuple of str
        Stiffness groups, in column order of the arrays below.
    energy_shares : (m, G) ndarray
        Share of each group in the modal strain energy [-]; rows sum to one.
    cause : tuple of str
        Group with the largest strain-energy share, per mode.
    tcp_direction : tuple of str
        Dominant component of the mode at the TCP ('x', 'y', 'z' or 'rx', 'ry', 'rz';
        '-' if the model has no point 'tcp').
    neuber_frequency : (m, G) ndarray or None
        Frequency [Hz] of the best-matching mode of the model in which only group g is elastic
        (NaN when no mode reaches the MAC limit).
    neuber_mac : (m, G) ndarray or None
        Mass-weighted MAC of that match [-].
    neuber_cause : tuple of str or None
        Group whose one-elasticity model reproduces the mode at the frequency closest to the
        full model's ('-' if none matches).
    alpha : float
        Stiffness factor of the rigidified groups [-].
    """

    frequencies: npt.NDArray[np.float64]
    group_names: tuple[str, ...]
    energy_shares: npt.NDArray[np.float64]
    cause: tuple[str, ...]
    tcp_direction: tuple[str, ...]
    neuber_frequency: npt.NDArray[np.float64] | None = None
    neuber_mac: npt.NDArray[np.float64] | None = None
    neuber_cause: tuple[str, ...] | None = None
    alpha: float = DEFAULT_ALPHA

    def rows(self) -> list[dict[str, float | str]]:
        """Return one dict per mode (the CSV columns)."""
        out = []
        for j, f in enumerate(self.frequencies):
            row: dict[str, float | str] = {
                'mode': j + 1, 'frequency_hz': float(f), 'tcp_direction': self.tcp_direction[j],
                'cause': self.cause[j]}
            if self.neuber_cause is not None:
                row['neuber_cause'] = self.neuber_cause[j]
            for g, name in enumerate(self.group_names):
                row[f'share_{name}'] = float(self.energy_shares[j, g])
            if self.neuber_frequency is not None and self.neuber_mac is not None:
                for g, name in enumerate(self.group_names):
                    row[f'neuber_f_{name}_hz'] = float(self.neuber_frequency[j, g])
                    row[f'neuber_mac_{name}'] = float(self.neuber_mac[j, g])
            out.append(row)
        return out

    def to_csv(self, path: str | os.PathLike[str]) -> None:
        """Write :meth:`rows` to a CSV file (frequencies in Hz, shares as fractions)."""
        rows = self.rows()
        with open(path, 'w', newline='') as fh:
            writer = csv.DictWriter(fh, fieldnames=list(rows[0]) if rows else ['mode'])
            writer.writeheader()
            writer.writerows(rows)

    def format_table(self, n_rows: int | None = None) -> str:
        """Return a fixed-width text table of the first ``n_rows`` modes (shares in %)."""
        short = [name[:8] for name in self.group_names]
        head = f'{"no.":>4} {"f [Hz]":>9} {"TCP":>4} {"cause":>12} '
        if self.neuber_cause is not None:
            head += f'{"one-elast.":>12} '
        head += ' '.join(f'{s:>8}' for s in short)
        lines = [head]
        for j in range(self.frequencies.size if n_rows is None else n_rows):
            if j >= self.frequencies.size:
                break
            line = (f'{j + 1:>4} {self.frequencies[j]:>9.2f} {self.tcp_direction[j]:>4} '
                    f'{self.cause[j]:>12} ')
            if self.neuber_cause is not None:
                line += f'{self.neuber_cause[j]:>12} '
            line += ' '.join(f'{100 * s:>7.1f}%' for s in self.energy_shares[j])
            lines.append(line)
        return '\n'.join(lines)


def strain_energy_shares(groups: Mapping[str, sp.spmatrix],
                         modes: ModalResult, chunk: int = 64) -> npt.NDArray[np.float64]:
    """
    Return the share of each stiffness group in each mode's strain energy.

    Parameters
    ----------
    groups : mapping of str to (n, n) sparse matrix
        Stiffness groups [N/m, ...] that sum to K.
    modes : ModalResult
        Mass-normalised modes of K.
    chunk : int
        Modes processed at once (bounds the memory of ``K_g @ phi``).

    Returns
    -------
    (m, G) ndarray
        ``phi_j^T K_g phi_j / sum_g(...)``; the denominator equals ``omega_j^2``.
    """
    phi = modes.shapes
    energy = np.empty((phi.shape[1], len(groups)))
    for lo in range(0, phi.shape[1], chunk):
        block = phi[:, lo:lo + chunk]
        for g, Kg in enumerate(groups.values()):
            energy[lo:lo + chunk, g] = np.einsum('ij,ij->j', block, Kg @ block)
    total = energy.sum(axis=1, keepdims=True)
    return energy / np.where(total > 0.0, total, 1.0)


def rigidified_stiffness(groups: Mapping[str, sp.spmatrix], name: str,
                         alpha: float = DEFAULT_ALPHA) -> sp.csr_matrix:
    """
    Return ``K_name + alpha * sum(other groups)``: only group ``name`` keeps its elasticity.

    Raises
    ------
    KeyError
        If ``name`` is not a group; the message lists the groups.
    """
    if name not in groups:
        raise KeyError(f'unknown stiffness group {name!r}; groups: {", ".join(groups)}')
    if not alpha >= 1.0:
        raise ValueError(f'alpha={alpha} must be >= 1 to stiffen the other groups')
    K = sum(groups.values())
    return sp.csr_matrix(groups[name] + alpha * (K - groups[name]))


def mass_mac(phi: npt.NDArray[np.float64], psi: npt.NDArray[np.float64],
             M: sp.spmatrix) -> npt.NDArray[np.float64]:
    """
    Return the mass-weighted modal assurance criterion between two mode sets.

    ``MAC_ij = (phi_i^T M psi_j)^2 / ((phi_i^T M phi_i) (psi_j^T M psi_j))`` in [0, 1].
    """
    Mpsi = M @ psi
    cross = phi.T @ Mpsi
    norm_phi = np.einsum('ij,ij->j', phi, M @ phi)
    norm_psi = np.einsum('ij,ij->j', psi, Mpsi)
    return cross ** 2 / np.outer(norm_phi, norm_psi)


def neuber_frequencies(groups: Mapping[str, sp.spmatrix], M: sp.spmatrix, modes: ModalResult,
                       *, alpha: float = DEFAULT_ALPHA, band_factor: float = 2.0,
                       mac_min: float = DEFAULT_MAC_MIN,
                       progress: Callable[[str], None] | None = None
                       ) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """
    Match every mode to the modes of the one-elasticity-at-a-time models.

    Parameters
    ----------
    groups : mapping of str to (n, n) sparse matrix
        Stiffness groups summing to K.
    M : (n, n) sparse matrix
        Mass matrix [kg, ...].
    modes : ModalResult
        Modes of the full model.
    alpha : float
        Stiffness factor of the groups made rigid.
    band_factor : float
        Each one-elasticity model is solved up to ``band_factor * max(modes.frequencies)``.
    mac_min : float
        Least MAC of a valid match.
    progress : callable, optional
        Called with one message per group.

    Returns
    -------
    frequency : (m, G) ndarray
        Frequency [Hz] of the best match per group (NaN below ``mac_min``).
    mac : (m, G) ndarray
        MAC of the best match.
    """
    m = modes.n_modes
    freq, mac = np.full((m, len(groups)), np.nan), np.zeros((m, len(groups)))
    f_top = band_factor * float(modes.frequencies.max())
    for g, name in enumerate(groups):
        Kg = rigidified_stiffness(groups, name, alpha)
        sub = solve_modes(Kg, M, f_max=f_top)
        msg = f'only {name} elastic: {sub.n_modes} modes below {f_top:.4g} Hz'
        _LOG.info(msg)
        if progress is not None:
            progress(msg)
        if sub.n_modes == 0:
            continue
        table = mass_mac(modes.shapes, sub.shapes, M)
        best = table.argmax(axis=1)
        mac[:, g] = table[np.arange(m), best]
        ok = mac[:, g] >= mac_min
        freq[ok, g] = sub.frequencies[best[ok]]
    return freq, mac


def tcp_directions(modes: ModalResult, T: sp.spmatrix | npt.ArrayLike,
                   rotation_length: float = DEFAULT_ROTATION_LENGTH) -> tuple[str, ...]:
    """
    Return the dominant component of each mode at a point.

    Parameters
    ----------
    modes : ModalResult
        Mode shapes.
    T : (6, n) sparse matrix or array
        The point's observation matrix (ux, uy, uz, rx, ry, rz).
    rotation_length : float
        Lever arm [m] that turns a rotation [rad] into a comparable displacement [m]:
        a rotation wins only if ``rotation_length * |r| > |u|`` for every translation.
    """
    amp = np.abs(modes.shapes_at(T))
    amp[3:] *= rotation_length
    return tuple(DIRECTIONS[i] for i in amp.argmax(axis=0))


def _neuber_cause(freq: np.ndarray, f_full: np.ndarray,
                  names: tuple[str, ...]) -> tuple[str, ...]:
    """Group whose matched one-elasticity frequency is closest (in ratio) to the full one."""
    out = []
    for row, f in zip(freq, f_full):
        if np.all(np.isnan(row)):
            out.append('-')
            continue
        out.append(names[int(np.nanargmin(np.abs(np.log(row / f))))])
    return tuple(out)


def analyse_causes(model: FEModel, modes: ModalResult, *, neuber: bool = True,
                   alpha: float = DEFAULT_ALPHA, mac_min: float = DEFAULT_MAC_MIN,
                   rotation_length: float = DEFAULT_ROTATION_LENGTH,
                   progress: Callable[[str], None] | None = None) -> CauseTable:
    """
    Build the cause table of a model's modes.

    Parameters
    ----------
    model : FEModel
        Uses ``stiffness_groups``, ``M`` and, if present, the point 'tcp'.
    modes : ModalResult
        Modes of ``model.K``, ``model.M``.
    neuber : bool
        Also solve the one-elasticity-at-a-time models (one modal solve per group).
    alpha, mac_min, rotation_length, progress
        See :func:`neuber_frequencies` and :func:`tcp_directions`.
    """
    names = tuple(model.stiffness_groups)
    shares = strain_energy_shares(model.stiffness_groups, modes)
    cause = tuple(names[i] for i in shares.argmax(axis=1))
    if 'tcp' in model.points:
        direction = tcp_directions(modes, model.points['tcp'], rotation_length)
    else:
        direction = ('-',) * modes.n_modes
    freq = mac = ncause = None
    if neuber:
        freq, mac = neuber_frequencies(model.stiffness_groups, model.M, modes, alpha=alpha,
                                       mac_min=mac_min, progress=progress)
        ncause = _neuber_cause(freq, modes.frequencies, names)
    return CauseTable(modes.frequencies, names, shares, cause, direction, freq, mac, ncause,
                      alpha)


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
