"""
Build the sparse FE model (:class:`pentapod_sim.fe.model.FEModel`) of the pentapod at a pose.

Model (all SI units):

* Frame: five columns, base and top ring, five spokes to the lumped bed/table, five brackets
  carrying the BP joints; Timoshenko beams (:mod:`pentapod_sim.fe.beam`), or with
  ``frame.model: shells`` the plate frame's Craig-Bampton superelement
  (:mod:`pentapod_sim.fe.frame_model`) coupled at its feet, BP joint seats and bed.
* Installation: one translational spring triple (x, y, z) per foot to the ground.
* Struts: beams re-meshed per pose with nodes at the WP joint, at the BP joint and at the free
  rear end (overhang = tube length - active length), plus the ball-screw mass per length.
* Feed drive: 6-DOF zero-length spring strut node at the BP joint <-> gimbal (nut axial, guide
  lateral, bending "rigid" by a stiff penalty, torsion).
* BP joints: spring gimbal <-> frame-side outer cardan ring (needle bearings: axial and the two
  lateral stiffnesses, torsion locked by a penalty, both cardan rotations free).
* WP joints: spring strut end <-> platform (translations and torsion; cardan rotations free).
* Platform (spindle housing): one rigid body; its points are slaves of a master node at its
  centre of gravity, eliminated exactly by ``u = T q`` and ``K_r = T^T K T``.

Zero-length springs act in the strut frame (e1, e2, e3) of :mod:`pentapod_sim.fe.geometry`.
"""
from __future__ import annotations

import hashlib
import logging
import time
from typing import Any

import numpy as np
import numpy.typing as npt
import scipy.sparse as sp

from pentapod_sim.errors import ConfigError
from pentapod_sim.fe import beam
from pentapod_sim.fe.geometry import layout_from_params, N_STRUTS, solve_pose, StrutState
from pentapod_sim.fe.machine_data import load_positions, MachineParams, RhsSection
from pentapod_sim.fe.model import DofMap, FEModel
from pentapod_sim.fe.rigid import node_dofs, rigid_elimination

LOG = logging.getLogger(__name__)
Array = npt.NDArray[np.float64]
#: COO rows, columns and values of element blocks
Triplet = tuple[Array, Array, Array]
GROUPS = ('frame', 'installation', 'struts', 'feed_drives', 'bp_joints', 'wp_joints')
#: Extra stiffness group of the plate frame (frame.model: shells): its walls.
WALL_GROUP = 'frame_walls'


class _Mesh:
    """Collects nodes, beam elements, springs, masses and rigid-body slaves."""

    def __init__(self, machine: MachineParams, element_size: float) -> None:
        self.machine = machine
        self.h = element_size
        self.min_el = machine.mesh.min_elements_per_member
        self.xyz: list[Array] = []
        self.n_nodes = 0
        self.named: dict[str, int] = {}
        self.beams: list[dict[str, Any]] = []
        #: node a, node b (None: ground), frame (rows e1, e2, e3), k along/about them, group
        self.springs: list[tuple[int, int | None, Array, Array, str]] = []
        self.masses: list[tuple[int, float, Array]] = []
        self.slaves: dict[int, int] = {}
        self.mass_parts: dict[str, float] = {}
        #: nodes of the machine frame (to tell local frame modes), and a superelement:
        #: its node per interface DOF block, dense K per group, dense M (modal DOFs appended)
        self.frame_nodes: set[int] = set()
        self.superelement: tuple[list[int], dict[str, Array], Array] | None = None

    def node(self, xyz: npt.ArrayLike, name: str | None = None) -> int:
        self.xyz.append(np.asarray(xyz, dtype=float).reshape(1, 3))
        self.n_nodes += 1
        if name is not None:
            self.named[name] = self.n_nodes - 1
        return self.n_nodes - 1

    def member(self, a: int, b: int, section: RhsSection, orientation: npt.ArrayLike,
               group: str, part: str, added_mass: float = 0.0) -> None:
        """Mesh a straight beam from node a to node b with elements of about self.h."""
        pa, pb = self.position(a), self.position(b)
        n_el = max(self.min_el, int(np.ceil(np.linalg.norm(pb - pa) / self.h - 1e-9)))
        inner = pa + np.outer(np.arange(1, n_el) / n_el, pb - pa)
        first = self.n_nodes
        if n_el > 1:
            self.xyz.append(inner)
            self.n_nodes += n_el - 1
        ids = np.concatenate([[a], np.arange(first, first + n_el - 1), [b]])
        sec = beam.rhs_section(section.width, section.height, section.thickness)
        mat = self.machine.materials.steel
        length = float(np.linalg.norm(pb - pa))
        self.mass_parts[part] = self.mass_parts.get(part, 0.0) + mat.density * sec.area * length
        if added_mass:
            self.mass_parts['ball_screws'] = (self.mass_parts.get('ball_screws', 0.0)
                                              + added_mass * length)
        self.beams.append({'n1': ids[:-1], 'n2': ids[1:], 'sec': sec, 'orient': orientation,
                               'group': group, 'nsm': added_mass})
        if group == 'frame':
            self.frame_nodes.update(int(n) for n in ids)

    def spring(self, a: int, b: int | None, frame: Array, k_diag: npt.ArrayLike,
               group: str) -> None:
        """Zero-length spring between a and b (None = ground); k along/about frame rows."""
        self.springs.append((a, b, np.asarray(frame, float), np.asarray(k_diag, float), group))

    def mass(self, a: int, m: float, inertia: Array, part: str) -> None:
        self.masses.append((a, m, inertia))
        self.mass_parts[part] = self.mass_parts.get(part, 0.0) + m

    def position(self, i: int) -> Array:
        return self.positions()[i]

    def positions(self) -> Array:
        if len(self.xyz) > 1:
            self.xyz = [np.concatenate(self.xyz)]
        return self.xyz[0]


def _column_and_frame(mesh: _Mesh) -> tuple[list[int], dict[int, int], int]:
    """Frame beams and bed; returns foot nodes, BP bracket column nodes, bed node."""
    fr = mesh.machine.frame
    bp = mesh.machine.bp_joints
    angles = np.asarray(bp.angles)
    feet, ring_base, ring_top, bracket_col = [], [], [], {}
    for i, th in enumerate(angles):
        radial = np.array([np.cos(th), np.sin(th), 0.0])
        tang = np.array([-np.sin(th), np.cos(th), 0.0])
        levels = sorted({0.0, fr.base_ring_z, bp.z[i], fr.column_height})
        ids = [mesh.node(fr.column_radius * radial + [0, 0, z]) for z in levels]
        for a, b in zip(ids[:-1], ids[1:]):
            mesh.member(a, b, fr.column, tang, 'frame', 'frame')
        feet.append(ids[0])
        ring_base.append(ids[levels.index(fr.base_ring_z)])
        ring_top.append(ids[-1])
        bracket_col[i] = ids[levels.index(bp.z[i])]
    order = np.argsort(np.mod(angles, 2 * np.pi))
    vertical = np.array([0.0, 0.0, 1.0])
    for ring in (ring_base, ring_top):
        for k in range(N_STRUTS):
            mesh.member(ring[order[k]], ring[order[(k + 1) % N_STRUTS]], fr.ring, vertical,
                        'frame', 'frame')
    bed = mesh.node([0.0, 0.0, fr.bed_z], 'bed')
    mesh.mass(bed, fr.bed_mass, np.diag(fr.bed_inertia), 'bed')
    for node in ring_base:
        mesh.member(bed, node, fr.spoke, vertical, 'frame', 'frame')
    mesh.frame_nodes.discard(bed)               # the bed's mass is not the frame's
    return feet, bracket_col, bed


def _struts_and_joints(mesh: _Mesh, state: StrutState, bracket_col: dict[int, int],
                       seats: dict[int, int] | None = None) -> None:
    """
    Struts, gimbals, BP and WP joints (springs) and the platform's slave points.

    ``seats``: the frame's node of each BP joint's outer ring (plate frame); without it the
    ring node is made here and tied to ``bracket_col`` by a bracket beam.
    """
    m = mesh.machine
    layout = layout_from_params(m)
    bp, fd, wp = m.bp_joints, m.feed_drives, m.wp_joints
    vertical = np.array([0.0, 0.0, 1.0])
    for i in range(N_STRUTS):
        s = i + 1
        frame = state.frames[i]
        e1 = frame[0]
        b_pt, w_pt = layout.bp_joints[i], state.wp_joints[i]
        overhang = m.struts.tube_length[i] - state.lengths[i]
        if seats is not None:
            ring = seats[i]
        else:
            ring = mesh.node(b_pt, f'bp_ring{s}')
            mesh.member(bracket_col[i], ring, m.frame.bp_bracket, vertical, 'frame', 'frame')
        gimbal = mesh.node(b_pt, f'gimbal{s}')
        at_bp = mesh.node(b_pt, f'strut{s}_at_bp')
        wp_end = mesh.node(w_pt, f'strut{s}_wp_end')
        rear = mesh.node(b_pt - overhang * e1, f'strut{s}_rear_end')
        for a, b in ((rear, at_bp), (at_bp, wp_end)):
            first = mesh.n_nodes
            mesh.member(a, b, m.struts.section, frame[1], 'struts', 'struts',
                        m.struts.screw_mass_per_length)
        for j, node in enumerate(range(first, mesh.n_nodes), start=1):   # chord ports
            mesh.named[f'strut{s}_span{j}'] = node
        mesh.spring(at_bp, gimbal, frame,
                    [fd.nut_axial_stiffness, fd.guide_lateral_stiffness,
                     fd.guide_lateral_stiffness, fd.torsion_stiffness, fd.bending_stiffness,
                     fd.bending_stiffness], 'feed_drives')
        mesh.spring(gimbal, ring, frame,
                    [bp.needle_axial_stiffness, bp.needle_cardan1_stiffness,
                     bp.needle_cardan2_stiffness, bp.torsion_stiffness, 0.0, 0.0], 'bp_joints')
        mesh.mass(gimbal, bp.gimbal_mass, frame.T @ np.diag(bp.gimbal_inertia) @ frame,
                  'gimbals')
        joint = mesh.node(w_pt, f'wp_joint{s}')
        mesh.spring(wp_end, joint, frame,
                    [wp.axial_stiffness, wp.lateral_stiffness, wp.lateral_stiffness,
                     wp.torsion_stiffness, 0.0, 0.0], 'wp_joints')


def _platform(mesh: _Mesh, state: StrutState) -> None:
    """Rigid platform: master node at the CoG, slaves = WP joints, TCP, nose, PMA mount."""
    pf = mesh.machine.platform
    rot, tcp = state.rotation, state.pose[:3]
    axis = rot[:, 2]
    master = mesh.node(tcp + (pf.tcp_below_nose + pf.cog_above_nose) * axis, 'platform_cog')
    mesh.mass(master, pf.mass, rot @ np.diag(pf.inertia) @ rot.T, 'platform')
    mesh.node(tcp, 'tcp')
    mesh.node(tcp + pf.tcp_below_nose * axis, 'spindle_nose')
    mesh.node(tcp + pf.pma_mount_above_tcp * axis, 'pma_mount')
    for name in ['tcp', 'spindle_nose', 'pma_mount'] + [f'wp_joint{i}' for i in range(1, 6)]:
        mesh.slaves[mesh.named[name]] = master


_dofs = node_dofs


def _triplets(blocks: Array, dofs: npt.NDArray[Any]) -> Triplet:
    """Element blocks (e, d, d) at DOF indices (e, d) -> COO rows, cols, values."""
    d = dofs.shape[1]
    return (np.repeat(dofs, d, axis=1).ravel(), np.tile(dofs, (1, d)).ravel(), blocks.ravel())


def _super_triplets(blk: Any, dofs: npt.NDArray[Any]) -> Triplet:
    """Triplets of a superelement matrix (dense, or sparse for an unreduced frame)."""
    coo = sp.coo_matrix(blk)
    return dofs[coo.row], dofs[coo.col], coo.data


def _to_csr(parts: list[Triplet], n: int) -> sp.csr_matrix:
    """One COO -> CSR conversion (duplicates summed) of all collected triplets."""
    if not parts:
        return sp.csr_matrix((n, n))
    rows, cols, vals = (np.concatenate(x) for x in zip(*parts))
    return sp.coo_matrix((vals, (rows, cols)), shape=(n, n)).tocsr()


def _beam_triplets(mesh: _Mesh, k_parts: dict[str, list[Triplet]], m_parts: list[Triplet],
                   chunk: int = 20000) -> None:
    """Beam stiffness (per group) and mass triplets (vectorised over elements, chunked)."""
    xyz = mesh.positions()
    mat = mesh.machine.materials.steel
    kappa = mesh.machine.struts.shear_factor
    for bm in mesh.beams:
        for lo in range(0, len(bm['n1']), chunk):
            n1, n2 = bm['n1'][lo:lo + chunk], bm['n2'][lo:lo + chunk]
            length, axes = beam.local_axes(xyz[n1], xyz[n2], bm['orient'])
            sec = bm['sec']
            k_loc, m_loc = beam.local_matrices(length, mat.youngs_modulus, mat.shear_modulus,
                                               mat.density, sec.area, sec.iy, sec.iz,
                                               sec.torsion, kappa, bm['nsm'])
            dofs = np.concatenate([_dofs(n1), _dofs(n2)], axis=1)
            k_parts.setdefault(bm['group'], []).append(
                _triplets(beam.to_global(k_loc, axes), dofs))
            m_parts.append(_triplets(beam.to_global(m_loc, axes), dofs))


def _spring_triplets(mesh: _Mesh, k_parts: dict[str, list[Triplet]]) -> None:
    """Zero-length springs (two-node and to-ground) triplets per group."""
    for a, b, frame, k_diag, group in mesh.springs:
        big = np.kron(np.eye(2), frame)            # 6x6 rotation for translations, rotations
        k6 = big.T @ np.diag(k_diag) @ big
        if b is None:
            blk, dofs = k6[None], _dofs([a]).reshape(1, 6)
        else:
            blk = np.block([[k6, -k6], [-k6, k6]])[None]
            dofs = np.concatenate([_dofs([a]), _dofs([b])], axis=1)
        k_parts.setdefault(group, []).append(_triplets(blk, dofs))


def _lumped_mass_triplets(mesh: _Mesh, m_parts: list[Triplet]) -> None:
    for a, m, inertia in mesh.masses:
        blk = np.zeros((6, 6))
        blk[:3, :3] = m * np.eye(3)
        blk[3:, 3:] = inertia
        m_parts.append(_triplets(blk[None], _dofs([a])))


def _assemble(mesh: _Mesh) -> tuple[sp.csr_matrix, dict[str, sp.csr_matrix], sp.csr_matrix]:
    """Return T, the reduced stiffness groups and the reduced mass matrix of a mesh."""
    n_modal = 0
    k_parts: dict[str, list[Triplet]] = {}
    m_parts: list[Triplet] = []
    _beam_triplets(mesh, k_parts, m_parts)
    _spring_triplets(mesh, k_parts)
    _lumped_mass_triplets(mesh, m_parts)
    if mesh.superelement is not None:
        nodes, k_super, m_super = mesh.superelement
        n_modal = m_super.shape[0] - 6 * len(nodes)
        dofs = np.concatenate([_dofs(nodes).ravel(), 6 * mesh.n_nodes + np.arange(n_modal)])
        for g, blk in k_super.items():
            k_parts.setdefault(g, []).append(_super_triplets(blk, dofs))
        m_parts.append(_super_triplets(m_super, dofs))
    n_full = 6 * mesh.n_nodes + n_modal
    k_full = {g: _to_csr(parts, n_full) for g, parts in k_parts.items()}
    m_full = _to_csr(m_parts, n_full)
    LOG.debug('full matrices assembled (%d DOF); eliminating the rigid platform', n_full)
    t_mat = rigid_elimination(mesh.positions(), mesh.slaves, n_modal)
    t_t = t_mat.T.tocsr()
    n_free = t_mat.shape[1]
    names = GROUPS + ((WALL_GROUP,) if WALL_GROUP in k_full else ())
    groups = {g: (t_t @ k_full[g] @ t_mat).tocsr() if g in k_full
              else sp.csr_matrix((n_free, n_free)) for g in names}
    return t_mat, groups, (t_t @ m_full @ t_mat).tocsr()


def _resolve_pose(pose: npt.ArrayLike | str) -> Array:
    if isinstance(pose, str):
        positions = load_positions()
        if pose not in positions:
            raise ConfigError(f'unknown position {pose!r}; known: {", ".join(positions)}')
        return positions[pose]
    return np.asarray(pose, dtype=float).reshape(5)


def build_model(machine: MachineParams, pose: npt.ArrayLike | str,
                element_size: float | None = None, installed: bool = True,
                frame_cache: Any = None) -> FEModel:
    """
    Assemble the FE model of the machine at a pose.

    Parameters
    ----------
    machine : MachineParams
        Machine parameters (:func:`pentapod_sim.fe.machine_data.load_machine`).
    pose : (5,) array_like or str
        TCP pose x, y, z [m], a, b [rad], or a position name of ``config/positions.yaml``.
    element_size : float, optional
        Beam element length [m]; default ``machine.mesh.element_size``. About 0.4 mm gives the
        paper's ~800,000 DOF.
    installed : bool
        If False, the foundation springs are left out (free structure, six rigid-body modes).
    frame_cache : str or ReducedFrame, optional
        Folder of reduced plate frames (``frame.model: shells``; default
        ``$PENTAPOD_FRAME_CACHE`` or ``out/frames``), or the frame superelement itself. The frame
        must have been reduced (``pentapod_sim.modes.frame_reduction.build_model`` does both).

    Returns
    -------
    FEModel

    Raises
    ------
    UnreachablePoseError
        If the pose violates a stroke or joint-angle limit.
    """
    t0 = time.perf_counter()
    pose = _resolve_pose(pose)
    h = machine.mesh.element_size if element_size is None else float(element_size)
    if not h > 0.0:
        raise ConfigError(f'element_size must be > 0 m, got {h!r}')
    state = solve_pose(layout_from_params(machine), pose)
    mesh = _Mesh(machine, h)
    seats = None
    if machine.frame.model == 'shells':
        from pentapod_sim.fe.frame_model import couple_frame  # needs scikit-fem, gmsh
        feet, seats, _ = couple_frame(mesh, frame_cache)
        bracket_col: dict[int, int] = {}
    else:
        feet, bracket_col, _ = _column_and_frame(mesh)
    inst = machine.installation
    k_feet = [inst.foot_stiffness_x, inst.foot_stiffness_y, inst.foot_stiffness_z]
    if seats is not None and machine.shell_frame and machine.shell_frame.foot_stiffness:
        k_feet = list(machine.shell_frame.foot_stiffness)
    for foot in feet if installed else []:
        mesh.spring(foot, None, np.eye(3), k_feet + [0.0, 0.0, 0.0], 'installation')
    _struts_and_joints(mesh, state, bracket_col, seats)
    _platform(mesh, state)
    LOG.debug('mesh: %d nodes, %d beam members; assembling', mesh.n_nodes, len(mesh.beams))
    t_mat, groups, mass = _assemble(mesh)
    stiffness = sum(groups.values()).tocsr()
    xyz = mesh.positions()
    points = {name: t_mat[_dofs([node])[0]].tocsr() for name, node in mesh.named.items()}
    meta = {'parameter_file': machine.source, 'element_size': h, 'installed': installed,
            'params_sha256': hashlib.sha256(repr(machine).encode()).hexdigest(),
            'n_nodes': mesh.n_nodes, 'n_beam_elements': int(sum(len(b['n1']) for b in mesh.beams)),
            'build_seconds': time.perf_counter() - t0, 'frame_model': machine.frame.model}
    LOG.info('built FE model: %d DOF, %d beam elements in %.2f s', stiffness.shape[0],
             meta['n_beam_elements'], meta['build_seconds'])
    free = np.setdiff1d(np.arange(mesh.n_nodes), list(mesh.slaves))  # T's column order
    n_modal = stiffness.shape[0] - 6 * free.size       # plate frame's modal coordinates
    # labels: node index + 1; a modal coordinate: a label of its own, no component
    dofs = DofMap(np.concatenate([np.repeat(free + 1, 6), mesh.n_nodes + 1 + np.arange(n_modal)]),
                  np.concatenate([np.tile(np.arange(6), free.size), np.full(n_modal, -1)]),
                  np.arange(1, mesh.n_nodes + 1), xyz.copy())
    frame_rows = _dofs(sorted(mesh.frame_nodes)).ravel()
    frame_dofs = np.union1d(t_mat[frame_rows].indices, 6 * free.size + np.arange(n_modal))
    return FEModel(K=stiffness, M=mass, stiffness_groups=groups, points=points,
                   point_positions={n: xyz[i].copy() for n, i in mesh.named.items()},
                   strut_frames=state.frames.copy(), mass_parts=dict(mesh.mass_parts),
                   pose=pose.copy(), meta=meta, dofs=dofs,
                   frame_dofs=frame_dofs.astype(np.int64))
