"""
The plate frame as one FE model, and its Craig-Bampton superelement (cached on disk).

:func:`frame_fe` assembles the shell mesh of :mod:`pentapod_sim.fe.frame_mesh` (elements of
:mod:`pentapod_sim.fe.shell`) and ties every interface point's nodes to it rigidly; the
interface points' DOFs come last. The reduction (``pentapod_sim.modes.frame_reduction``, it
needs the modal solver of the next stage) keeps them (the boundary, ``b``) and replaces the
rest (``i``) by

* the static constraint modes ``Psi = -K_ii^-1 K_ib`` (the frame's exact static response to
  a unit motion of each interface DOF), and
* the fixed-interface normal modes ``K_ii phi = omega^2 M_ii phi`` below
  ``shell_frame.mode_multiple * shell_frame.f_interest`` (found by the spectrum-slicing solver
  of :mod:`pentapod_sim.modes.solver`, counted by Sturm sequence),

so ``u = [I 0; Psi Phi] [u_b; q]`` and ``K_r = T^T K T`` = diag(Guyan stiffness, omega^2),
``M_r = T^T M T``. The frame does not change with the pose, so this is done once per set of
frame parameters and kept in ``<cache>/frame_<hash>.npz``; :func:`load_reduced_frame` reads
it, and the pose's model couples it to the beams (:mod:`pentapod_sim.fe.assembly`).

Each stiffness group of the frame (``frame``: columns, rings, spokes, hub; ``frame_walls``:
the walls) is reduced with the same T, so the groups still sum to K_r and the cause analysis
can make the walls rigid on their own. Units: SI.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass
import hashlib
import json
import logging
import os
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
import scipy.sparse as sp

from pentapod_sim.errors import ConfigError
from pentapod_sim.fe.frame_mesh import FrameMesh, mesh_frame, PARTS
from pentapod_sim.fe.geometry import N_STRUTS
from pentapod_sim.fe.machine_data import MachineParams
from pentapod_sim.fe.rigid import node_dofs, rigid_elimination
from pentapod_sim.fe.shell import assemble, shell_element_matrices

__all__ = ['cache_dir', 'couple_frame', 'frame_fe', 'frame_on_feet', 'FrameFE',
           'FrameNotReducedError', 'interface_dofs', 'load_reduced', 'load_reduced_frame',
           'ReducedFrame', 'save_reduced', 'unreduced_frame']

LOG = logging.getLogger(__name__)
Array = npt.NDArray[np.float64]
#: Stiffness group of each shell part.
PART_GROUP = {'column': 'frame', 'ring': 'frame', 'spoke': 'frame', 'hub': 'frame',
              'wall': 'frame_walls'}
FRAME_GROUPS = ('frame', 'frame_walls')
#: Version of the reduction's file format and method; part of the cache key.
FORMAT = 2
#: Environment variable naming the folder of reduced frames (default ``out/frames``).
CACHE_ENV = 'PENTAPOD_FRAME_CACHE'
#: Triangles whose element matrices are computed at once (bounds the memory: ~20 kB each).
CHUNK = 4000


@dataclass(frozen=True)
class FrameFE:
    """
    The plate frame's FE model: free DOFs after the rigid couplings, interface DOFs last.

    Attributes
    ----------
    groups : dict of str to (n, n) csr_matrix
        Stiffness per group ('frame', 'frame_walls') [N/m, ...]; they sum to K.
    M : (n, n) csr_matrix
        Mass [kg, ...].
    interface : tuple of str
        Interface points in DOF order; point k has DOFs ``n - 6 * len(interface) + 6 k + (0..5)``.
    points : dict of str to (3,) ndarray
        Interface point positions [m].
    masses : dict of str to float
        Plate mass per stiffness group [kg].
    n_nodes : int
        Shell nodes of the mesh.
    """

    groups: dict[str, sp.csr_matrix]
    M: sp.csr_matrix
    interface: tuple[str, ...]
    points: dict[str, Array]
    masses: dict[str, float]
    n_nodes: int

    @property
    def n_dof(self) -> int:
        """Free DOFs of the frame."""
        return int(self.M.shape[0])

    @property
    def K(self) -> sp.csr_matrix:
        """Stiffness [N/m, ...]."""
        return sp.csr_matrix(sum(self.groups.values()))


def frame_fe(machine: MachineParams, element_size: float | None = None,
             mesh: FrameMesh | None = None) -> FrameFE:
    """Mesh (unless ``mesh`` is given) and assemble the plate frame of ``machine``."""
    fm = mesh_frame(machine, element_size) if mesh is None else mesh
    sh, steel = fm.shell, machine.materials.steel
    assert machine.shell_frame is not None
    n_nodes = sh.n_nodes
    names = tuple(fm.points)
    xyz = np.vstack([sh.xyz, np.array([fm.points[n] for n in names])])
    slaves: dict[int, int] = {}
    for k, name in enumerate(names):
        for node in fm.coupled[name]:
            if int(node) in slaves:
                raise ConfigError(f'shell frame: node {int(node)} is coupled to two interface '
                                  f'points ({name} and another); seats overlap')
            slaves[int(node)] = n_nodes + k
    n_full = 6 * xyz.shape[0]
    group_of_part = np.array([PART_GROUP[p] for p in PARTS])
    k_parts: dict[str, list[sp.csr_matrix]] = {g: [] for g in FRAME_GROUPS}
    m_parts: list[sp.csr_matrix] = []
    masses = dict.fromkeys(FRAME_GROUPS, 0.0)
    for lo in range(0, sh.triangles.shape[0], CHUNK):
        sel = np.arange(lo, min(lo + CHUNK, sh.triangles.shape[0]))
        k_el, m_el, dofs = shell_element_matrices(sh, steel.youngs_modulus,
                                                  machine.shell_frame.poisson_ratio,
                                                  steel.density, sel)
        m_parts.append(assemble(m_el, dofs, n_full))
        groups = group_of_part[sh.part[sel]]
        for g in FRAME_GROUPS:
            mine = groups == g
            if np.any(mine):
                k_parts[g].append(assemble(k_el[mine], dofs[mine], n_full))
                masses[g] += float(m_el[mine][:, 0::6, 0::6].sum())
    t_mat = rigid_elimination(xyz, slaves)
    t_t = t_mat.T.tocsr()
    groups_r = {g: sp.csr_matrix(t_t @ sum(parts) @ t_mat) for g, parts in k_parts.items()
                if parts}
    M = sp.csr_matrix(t_t @ sum(m_parts) @ t_mat)
    return FrameFE(groups_r, M, names, {n: fm.points[n] for n in names}, masses, n_nodes)


def frame_on_feet(machine: MachineParams, element_size: float | None = None
                  ) -> tuple[sp.csr_matrix, sp.csr_matrix, sp.csr_matrix, FrameFE]:
    """
    The frame alone: on its feet springs, with the bed's mass and inertia, nothing else.

    No struts, joints or platform: the cheap model in which the shell frame's own convergence
    with the mesh is seen (bench/frame_alone.py, test/test_shell_frame.py). The feet are
    ``shell_frame.foot_stiffness`` (x, y, z; the feet's rotations are free), the bed's mass
    and inertia ``frame.bed_mass``, ``frame.bed_inertia`` sit on interface point 'bed'.

    Returns
    -------
    K, M : (n, n) csr_matrix
        Stiffness with the feet [N/m, ...] and mass with the bed [kg, ...].
    K_feet : (n, n) csr_matrix
        The feet's share of K (for strain-energy shares).
    fe : FrameFE
        The assembled frame.
    """
    assert machine.shell_frame is not None
    fe = frame_fe(machine, element_size)
    n = fe.n_dof
    feet = np.concatenate([interface_dofs(fe, f'foot{i + 1}')[:3] for i in range(N_STRUTS)])
    k_feet = sp.csr_matrix((np.tile(np.asarray(machine.shell_frame.foot_stiffness, float),
                                    N_STRUTS), (feet, feet)), shape=(n, n))
    fr = machine.frame
    bed = interface_dofs(fe, 'bed')
    m_bed = sp.csr_matrix((np.array([fr.bed_mass] * 3 + list(fr.bed_inertia), float),
                           (bed, bed)), shape=(n, n))
    return sp.csr_matrix(fe.K + k_feet), sp.csr_matrix(fe.M + m_bed), k_feet, fe


@dataclass(frozen=True)
class ReducedFrame:
    """
    Craig-Bampton superelement of the frame.

    Attributes
    ----------
    interface : tuple of str
        Interface points; DOFs 6 k .. 6 k + 5 of the reduced matrices are point k's ux, uy,
        uz, rx, ry, rz (global frame); the fixed-interface modal coordinates follow.
    points : dict of str to (3,) ndarray
        Interface point positions [m].
    groups : dict of str to (r, r) ndarray
        Reduced stiffness per group [N/m, ...]; sum = diag(Guyan, omega^2) block matrix.
    M : (r, r) ndarray
        Reduced mass [kg, ...]; the modal block is the identity.
    frequencies : (m,) ndarray
        Frequencies of the modal coordinates [Hz]: the fixed-interface modes, then the
        residual pseudo-modes (``meta['n_residual']`` of them).
    masses : dict of str to float
        Plate mass per group [kg].
    meta : dict
        DOF and node counts, mesh size, cut-off, timings, parameter hash.
    """

    interface: tuple[str, ...]
    points: dict[str, Array]
    groups: dict[str, Array]
    M: Array
    frequencies: Array
    masses: dict[str, float]
    meta: dict[str, Any]

    @property
    def n_boundary(self) -> int:
        """Interface DOFs (6 per point)."""
        return 6 * len(self.interface)

    @property
    def n_modes(self) -> int:
        """Modal coordinates (fixed-interface modes and residual pseudo-modes)."""
        return int(self.frequencies.size)


def frame_key(machine: MachineParams, element_size: float, f_cut: float) -> str:
    """SHA-256 (hex, 16 chars) of everything the reduced frame depends on."""
    assert machine.shell_frame is not None
    # the bed's mass and inertia and the feet are added per pose (couple_frame), not reduced
    frame = {k: v for k, v in asdict(machine.frame).items()
             if k not in ('bed_mass', 'bed_inertia', 'model')}
    data = {'format': FORMAT, 'frame': frame,
            'shell_frame': {k: v for k, v in asdict(machine.shell_frame).items()
                            if k != 'foot_stiffness'},
            'steel': asdict(machine.materials.steel),
            'bp_joints': [list(machine.bp_joints.angles), list(machine.bp_joints.z),
                          machine.bp_joints.radius],
            'element_size': float(element_size), 'f_cut': float(f_cut)}
    text = json.dumps(data, sort_keys=True, default=float)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def cache_dir(path: str | os.PathLike[str] | None = None) -> Path:
    """``path``, else ``$PENTAPOD_FRAME_CACHE``, else ``out/frames``."""
    return Path(path if path is not None else os.environ.get(CACHE_ENV, 'out/frames'))


def save_reduced(frame: ReducedFrame, path: Path) -> None:
    """Write a reduced frame to an .npz file (written under a temporary name, then renamed)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    arrays: dict[str, Any] = {f'group_{g}': a for g, a in frame.groups.items()}
    header = {'interface': list(frame.interface), 'masses': frame.masses, 'meta': frame.meta,
              'points': {k: v.tolist() for k, v in frame.points.items()}}
    tmp = path.with_name(f'{path.stem}.{os.getpid()}.tmp.npz')
    arrays.update(M=frame.M, frequencies=frame.frequencies, header=np.array(json.dumps(header)))
    np.savez(tmp, **arrays)
    os.replace(tmp, path)


def load_reduced(path: Path) -> ReducedFrame:
    """Read a reduced frame written by :func:`save_reduced`."""
    with np.load(path) as data:
        header = json.loads(str(data['header']))
        groups = {k[len('group_'):]: data[k] for k in data.files if k.startswith('group_')}
        return ReducedFrame(tuple(header['interface']),
                            {k: np.asarray(v) for k, v in header['points'].items()},
                            groups, data['M'], data['frequencies'], header['masses'],
                            header['meta'])


_MEMO: dict[Path, ReducedFrame] = {}


class FrameNotReducedError(ConfigError):
    """The plate frame of these parameters has no reduction in the cache yet."""


def reduced_frame_path(machine: MachineParams, element_size: float | None = None,
                       cache: str | os.PathLike[str] | None = None) -> Path:
    """Cache file of the reduced frame of ``machine`` (:func:`frame_key`)."""
    sh = machine.shell_frame
    if sh is None:
        raise ConfigError('frame.model is shells but machine.yaml has no shell_frame section')
    h = sh.element_size if element_size is None else float(element_size)
    if not h > 0.0:
        raise ConfigError(f'shell_frame.element_size must be > 0 m, got {h!r}')
    key = frame_key(machine, h, sh.mode_multiple * sh.f_interest)
    return cache_dir(cache) / f'frame_{key}.npz'


def load_reduced_frame(machine: MachineParams, cache: str | os.PathLike[str] | None = None
                       ) -> ReducedFrame:
    """
    The reduced frame of ``machine`` from this process's memory or the cache file.

    Raises
    ------
    FrameNotReducedError
        If it was never reduced (``pentapod_sim.modes.frame_reduction.ensure_reduced_frame``
        reduces and caches it; the model builders of the later stages call it).
    """
    path = reduced_frame_path(machine, cache=cache)
    if path in _MEMO:
        return _MEMO[path]
    try:
        frame = load_reduced(path)
    except FileNotFoundError:
        raise FrameNotReducedError(
            f'the plate frame is not reduced yet (no {path}); run '
            '`python -m pentapod_sim.modes.frame_reduction` or build the model through '
            'pentapod_sim.modes.frame_reduction.build_model') from None
    except (OSError, ValueError, KeyError) as err:
        raise FrameNotReducedError(f'reduced frame {path} is unreadable ({err}); delete it '
                                   'to reduce the frame again') from None
    _MEMO[path] = frame
    return frame


def remember(path: Path, frame: ReducedFrame) -> None:
    """Keep a reduced frame in this process's memory (after it was saved to ``path``)."""
    _MEMO[path] = frame


def couple_frame(mesh: Any, cache: Any) -> tuple[list[int], dict[int, int], int]:
    """
    Add the plate frame superelement to a pose's mesh (``pentapod_sim.fe.assembly``).

    ``cache`` is the folder of reduced frames or a :class:`ReducedFrame` (e.g. the unreduced
    frame of :func:`unreduced_frame`). Makes the interface points' nodes, puts the bed mass on
    'bed' and returns the foot nodes, the BP seat node of each strut (0..4) and the bed node.
    """
    fr = mesh.machine.frame
    frame = cache if isinstance(cache, ReducedFrame) else load_reduced_frame(mesh.machine, cache)
    nodes = [mesh.node(frame.points[name], name) for name in frame.interface]
    mesh.superelement = (nodes, frame.groups, frame.M)
    feet = [mesh.named[f'foot{i + 1}'] for i in range(N_STRUTS)]
    seats = {i: mesh.named[f'bp_ring{i + 1}'] for i in range(N_STRUTS)}
    mesh.frame_nodes.update(feet + list(seats.values()))
    bed = mesh.named['bed']
    mesh.mass(bed, fr.bed_mass, np.diag(fr.bed_inertia), 'bed')
    for group, mass in frame.masses.items():
        mesh.mass_parts[group] = mesh.mass_parts.get(group, 0.0) + mass
    return feet, seats, bed


def unreduced_frame(fe: FrameFE) -> ReducedFrame:
    """
    The full frame in the superelement's form (interface DOFs first, then every other DOF).

    Coupled to a pose like the reduced frame, it gives the unreduced model: the reference the
    reduction is checked and timed against.
    """
    n, nb = fe.n_dof, 6 * len(fe.interface)
    order = np.concatenate([np.arange(n - nb, n), np.arange(n - nb)])
    groups = {g: sp.csr_matrix(A[order][:, order]) for g, A in fe.groups.items()}
    return ReducedFrame(fe.interface, dict(fe.points), groups,
                        sp.csr_matrix(fe.M[order][:, order]), np.zeros(0), dict(fe.masses),
                        {'n_dof': n, 'unreduced': True})


def interface_dofs(frame: FrameFE | ReducedFrame, name: str) -> npt.NDArray[np.int64]:
    """DOF indices of interface point ``name`` (in the full FrameFE or the reduced frame)."""
    k = frame.interface.index(name)
    if isinstance(frame, ReducedFrame):
        return node_dofs([k])[0]
    return frame.n_dof - 6 * len(frame.interface) + node_dofs([k])[0]
