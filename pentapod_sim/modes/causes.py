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
* **Local frame modes**: a mode whose strain energy lies mostly in the frame's groups
  (``frame``, and ``frame_walls`` of the plate frame) and whose kinetic energy stays in the
  frame (share ``phi_F^T (M phi)_F`` of the frame DOFs ``FEModel.frame_dofs`` at least
  :data:`DEFAULT_LOCAL_SHARE`) is a local frame mode: a wall or ring vibrating on its own,
  which moves neither struts nor platform (the paper's "local frame vibrations").

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
#: Least kinetic-energy share of the frame DOFs for a frame-caused mode to count as local.
DEFAULT_LOCAL_SHARE = 0.99
#: Stiffness groups of the machine frame.
FRAME_GROUPS = ('frame', 'frame_walls')
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
    frame_kinetic_share : (m,) ndarray or None
        Share of each mode's kinetic energy in the frame DOFs [-] (None if the model does
        not say which DOFs are the frame's).
    local_frame : tuple of bool or None
        Whether each mode is a local frame mode (see the module docstring).
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
    frame_kinetic_share: npt.NDArray[np.float64] | None = None
    local_frame: tuple[bool, ...] | None = None

    def rows(self) -> list[dict[str, float | str]]:
        """Return one dict per mode (the CSV columns)."""
        out = []
        for j, f in enumerate(self.frequencies):
            row: dict[str, float | str] = {
                'mode': j + 1, 'frequency_hz': float(f), 'tcp_direction': self.tcp_direction[j],
                'cause': self.cause[j]}
            if self.neuber_cause is not None:
                row['neuber_cause'] = self.neuber_cause[j]
            if self.local_frame is not None and self.frame_kinetic_share is not None:
                row['local_frame'] = int(self.local_frame[j])
                row['frame_kinetic_share'] = float(self.frame_kinetic_share[j])
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
            local = self.local_frame is not None and self.local_frame[j]
            line = (f'{j + 1:>4} {self.frequencies[j]:>9.2f} {self.tcp_direction[j]:>4} '
                    f'{self.cause[j] + ("*" if local else ""):>12} ')
            if self.neuber_cause is not None:
                line += f'{self.neuber_cause[j]:>12} '
            line += ' '.join(f'{100 * s:>7.1f}%' for s in self.energy_shares[j])
            lines.append(line)
        if self.local_frame is not None and any(self.local_frame):
            lines.append(f'* local frame mode ({sum(self.local_frame)} of '
                         f'{len(self.local_frame)}): its kinetic energy stays in the frame')
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


def frame_kinetic_shares(M: sp.spmatrix, modes: ModalResult,
                         frame_dofs: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """
    Share of each mode's kinetic energy in the DOFs ``frame_dofs``: ``phi_F^T (M phi)_F``.

    For mass-normalised modes the shares of the frame and of the rest sum to one; the cross
    terms of M between the two are split evenly, so a share may leave [0, 1] by a little.
    """
    dofs = np.asarray(frame_dofs, dtype=np.int64)
    phi = modes.shapes
    return np.einsum('ij,ij->j', phi[dofs], (M @ phi)[dofs])


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
                   local_share: float = DEFAULT_LOCAL_SHARE,
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
    local_share : float
        Least frame kinetic-energy share of a local frame mode (used if ``model.frame_dofs``
        is known).
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
    kinetic = local = None
    frame_dofs = getattr(model, 'frame_dofs', None)
    if frame_dofs is not None:
        kinetic = frame_kinetic_shares(model.M, modes, frame_dofs)
        in_frame = shares[:, [g for g, n in enumerate(names) if n in FRAME_GROUPS]].sum(axis=1)
        local = tuple(bool(v) for v in (in_frame > 0.5) & (kinetic >= local_share))
    return CauseTable(modes.frequencies, names, shares, cause, direction, freq, mac, ncause,
                      alpha, kinetic, local)

