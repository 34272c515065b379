"""
Geometry and shell mesh of the plate frame (``frame.model: shells`` in config/machine.yaml).

The frame is built from the mid-surfaces of welded steel plates with gmsh's OpenCASCADE kernel:

* five columns: open boxes (``frame.column``: outer width x height x wall) from the floor to
  ``frame.column_height`` on the column circle, as the beam frame's columns;
* the base ring (centred at ``frame.base_ring_z``) and the top ring (flush with the column
  tops): boxes (``frame.ring``) along the chords between neighbouring column axes;
* five spokes (``frame.spoke``) from the columns at base-ring height to the bed's hub, a box
  of ``shell_frame.hub_width`` around the machine axis from the spokes' bottom to
  ``frame.bed_z``, with the spokes' wall;
* walls (``shell_frame.wall_thickness``) in the chord planes between neighbouring columns,
  from the base ring to the top ring, in the bays ``shell_frame.walls`` names; a bay without
  a wall is a door with a lintel (a wall ``shell_frame.door_lintel`` high under the top
  ring; 0: open to the top ring).

The plates are fragmented so that the mesh is conforming along every weld line; the pieces of
a plate that lie inside another part's box (a ring's end inside a column) are removed, so
each box ends at the faces of the box it is welded to. gmsh meshes the surfaces with
triangles of edge ``shell_frame.element_size`` and makes them quadratic (6 nodes).

Interface points (rigid couplings, RBE2-like: the coupled nodes follow the point as a rigid
body): ``foot{i}`` (the nodes of column i's bottom edge, at the floor), ``bp_ring{i}`` (BP joint
seat i: every node of column i within ``shell_frame.seat_height`` / 2 of the joint height,
i.e. a bracket that clamps the whole column section), ``bed`` (the hub's top edge, where the
bed and rotary table sit). SI units.
"""
from __future__ import annotations

from dataclasses import dataclass
import logging

import numpy as np
import numpy.typing as npt

from pentapod_sim.errors import ConfigError
from pentapod_sim.fe.geometry import layout_from_params, N_STRUTS
from pentapod_sim.fe.machine_data import MachineParams, RhsSection
from pentapod_sim.fe.shell import ShellMesh

LOG = logging.getLogger(__name__)
Array = npt.NDArray[np.float64]
#: Part names of the shell triangles; 'wall' triangles form the stiffness group frame_walls.
PARTS = ('column', 'ring', 'spoke', 'hub', 'wall')
_EPS = 1e-6


@dataclass(frozen=True)
class _Box:
    """Open box: axis a -> b, cross-section axes u, v, mid-surface half sizes, wall, part."""

    a: Array
    b: Array
    u: Array
    v: Array
    half_u: float
    half_v: float
    thickness: float
    part: str

    def contains(self, p: Array) -> bool:
        """True if p lies strictly inside the box (not on its plates)."""
        axis = self.b - self.a
        length = float(np.linalg.norm(axis))
        s = float(np.dot(p - self.a, axis / length))
        return bool(_EPS < s < length - _EPS
                    and abs(np.dot(p - self.a, self.u)) < self.half_u - 1e-4
                    and abs(np.dot(p - self.a, self.v)) < self.half_v - 1e-4)

    def plates(self) -> list[Array]:
        """The four side plates as (4, 3) corner arrays."""
        out = []
        for su, sv, du, dv in ((1, 1, 0, -1), (1, -1, -1, 0), (-1, -1, 0, 1), (-1, 1, 1, 0)):
            c1 = su * self.half_u * self.u + sv * self.half_v * self.v
            c2 = (su + 2 * du) * self.half_u * self.u + (sv + 2 * dv) * self.half_v * self.v
            out.append(np.array([self.a + c1, self.b + c1, self.b + c2, self.a + c2]))
        return out


def _box(a: Array, b: Array, v_dir: Array, sec: RhsSection, part: str,
         thickness: float | None = None) -> _Box:
    """Box along a -> b; v = the section's height direction (made normal to the axis)."""
    axis = (b - a) / np.linalg.norm(b - a)
    v = v_dir - np.dot(v_dir, axis) * axis
    v /= np.linalg.norm(v)
    u = np.cross(v, axis)
    t = sec.thickness if thickness is None else thickness
    return _Box(a, b, u, v, (sec.width - sec.thickness) / 2, (sec.height - sec.thickness) / 2,
                t, part)


@dataclass(frozen=True)
class FramePlates:
    """Plates of the frame before meshing: corners (4, 3), wall thickness, part name."""

    plates: list[tuple[Array, float, str]]
    boxes: list[_Box]
    columns: Array          # (5, 3) column axis points at the floor
    seats: Array            # (5, 3) BP joint centres
    bed: Array              # (3,) bed point


def frame_plates(machine: MachineParams) -> FramePlates:
    """Plate layout of the frame from the machine parameters (see the module docstring)."""
    fr, sh = machine.frame, machine.shell_frame
    if sh is None:
        raise ConfigError('frame.model is shells but machine.yaml has no shell_frame section')
    angles = np.asarray(machine.bp_joints.angles)
    radial = np.column_stack([np.cos(angles), np.sin(angles), np.zeros(N_STRUTS)])
    z_axis = np.array([0.0, 0.0, 1.0])
    foot = fr.column_radius * radial
    top = fr.column_height
    boxes = [_box(foot[i], foot[i] + top * z_axis, radial[i], fr.column, 'column')
             for i in range(N_STRUTS)]
    order = np.argsort(np.mod(angles, 2 * np.pi))
    z_ring = (fr.base_ring_z, top - fr.ring.height / 2)
    plates: list[tuple[Array, float, str]] = []
    for k in range(N_STRUTS):
        i, j = order[k], order[(k + 1) % N_STRUTS]
        for z in z_ring:
            boxes.append(_box(foot[i] + z * z_axis, foot[j] + z * z_axis, z_axis, fr.ring,
                              'ring'))
        lo, hi = z_ring
        if not sh.walls[i]:         # the door: only its lintel, if any
            lo = hi - sh.door_lintel
        if hi - lo > _EPS:
            plates.append((np.array([foot[i] + lo * z_axis, foot[j] + lo * z_axis,
                                     foot[j] + hi * z_axis, foot[i] + hi * z_axis]),
                           sh.wall_thickness, 'wall'))
    if not sh.door_lintel < z_ring[1] - z_ring[0]:
        raise ConfigError(f'shell_frame.door_lintel {sh.door_lintel!r} m must be below the '
                          f'{z_ring[1] - z_ring[0]:.3f} m between the rings')
    z_spoke = fr.base_ring_z
    hub_lo = z_spoke - (fr.spoke.height - fr.spoke.thickness) / 2
    if not hub_lo < fr.bed_z:
        raise ConfigError(f"frame.bed_z {fr.bed_z!r} must lie above the spokes' bottom "
                          f'{hub_lo:.3f} m (the hub runs from there up to the bed)')
    hub_sec = RhsSection(sh.hub_width, sh.hub_width, fr.spoke.thickness)
    boxes.append(_box(np.array([0.0, 0.0, hub_lo]), np.array([0.0, 0.0, fr.bed_z]),
                      np.array([1.0, 0.0, 0.0]), hub_sec, 'hub'))
    for i in range(N_STRUTS):
        boxes.append(_box(foot[i] + z_spoke * z_axis, np.array([0.0, 0.0, z_spoke]), z_axis,
                          fr.spoke, 'spoke'))
    for box in boxes:
        plates.extend((c, box.thickness, box.part) for c in box.plates())
    seats = layout_from_params(machine).bp_joints
    return FramePlates(plates, boxes, foot, seats, np.array([0.0, 0.0, fr.bed_z]))


def _gmsh_surfaces(layout: FramePlates, element_size: float
                   ) -> tuple[Array, npt.NDArray[np.int64], Array, npt.NDArray[np.int64]]:
    """Fragment, trim and mesh the plates; nodes, 6-node triangles, thickness, part index."""
    import gmsh  # only the plate frame needs gmsh (a compiled library: imported late)

    gmsh.initialize(['-noenv'], readConfigFiles=False)
    try:
        gmsh.option.setNumber('General.Terminal', 0)
        gmsh.option.setNumber('General.NumThreads', 1)
        gmsh.model.add('frame')
        occ = gmsh.model.occ
        tags = []
        for corners, _, _ in layout.plates:
            pts = [occ.addPoint(*c) for c in corners]
            lines = [occ.addLine(pts[k], pts[(k + 1) % 4]) for k in range(4)]
            tags.append(occ.addPlaneSurface([occ.addCurveLoop(lines)]))
        _, pieces = occ.fragment([(2, t) for t in tags], [])
        occ.synchronize()
        owner: dict[int, int] = {}
        for plate, out in enumerate(pieces):
            for dim, tag in out:
                if dim == 2:
                    owner.setdefault(tag, plate)
        drop = []
        for tag, plate in owner.items():
            centre = np.array(occ.getCenterOfMass(2, tag))
            part = layout.plates[plate][2]
            if any(box.contains(centre) for box in layout.boxes if box.part != part):
                drop.append(tag)
        occ.remove([(2, t) for t in drop], recursive=True)
        occ.synchronize()
        gmsh.option.setNumber('Mesh.MeshSizeMax', element_size)
        gmsh.option.setNumber('Mesh.MeshSizeMin', element_size / 3.0)
        gmsh.option.setNumber('Mesh.MeshSizeFromPoints', 0)
        gmsh.option.setNumber('Mesh.MeshSizeExtendFromBoundary', 0)
        gmsh.option.setNumber('Mesh.Algorithm', 6)
        gmsh.model.mesh.generate(2)
        gmsh.model.mesh.setOrder(2)
        node_tags, coords, _ = gmsh.model.mesh.getNodes()
        index = np.full(int(node_tags.max()) + 1, -1, dtype=np.int64)
        index[node_tags.astype(np.int64)] = np.arange(node_tags.size)
        tris: list[npt.NDArray[np.int64]] = []
        thick: list[Array] = []
        part_of: list[npt.NDArray[np.int64]] = []
        for _, tag in gmsh.model.getEntities(2):
            types, _, nodes = gmsh.model.mesh.getElements(2, tag)
            _, wall, part_name = layout.plates[owner[tag]]
            for etype, enodes in zip(types, nodes):
                if etype != 9:      # 6-node triangle
                    raise RuntimeError(f'gmsh made element type {etype}, expected 9')
                tri = index[enodes.astype(np.int64)].reshape(-1, 6)
                tris.append(tri)
                thick.append(np.full(tri.shape[0], wall))
                part_of.append(np.full(tri.shape[0], PARTS.index(part_name), dtype=np.int64))
        xyz = coords.reshape(-1, 3)
    finally:
        gmsh.finalize()
    tri_all = np.concatenate(tris)
    used = np.unique(tri_all)
    renumber = np.full(xyz.shape[0], -1, dtype=np.int64)
    renumber[used] = np.arange(used.size)
    return xyz[used], renumber[tri_all], np.concatenate(thick), np.concatenate(part_of)


@dataclass(frozen=True)
class FrameMesh:
    """
    Shell mesh of the frame and its interface points.

    Attributes
    ----------
    shell : ShellMesh
        Nodes and triangles.
    points : dict of str to (3,) ndarray
        Interface points ('foot1'.., 'bp_ring1'.., 'bed') [m].
    coupled : dict of str to ndarray of int
        Shell nodes rigidly coupled to each interface point.
    """

    shell: ShellMesh
    points: dict[str, Array]
    coupled: dict[str, npt.NDArray[np.int64]]


def mesh_frame(machine: MachineParams, element_size: float | None = None) -> FrameMesh:
    """
    Mesh the plate frame of ``machine`` (gmsh) and find the nodes of its interface points.

    Parameters
    ----------
    machine : MachineParams
        Needs the ``shell_frame`` section.
    element_size : float, optional
        Target triangle edge [m]; default ``shell_frame.element_size``.
    """
    layout = frame_plates(machine)
    sh = machine.shell_frame
    assert sh is not None           # frame_plates checked it
    h = sh.element_size if element_size is None else float(element_size)
    if not h > 0.0:
        raise ConfigError(f'shell frame element_size must be > 0 m, got {h!r}')
    xyz, tri, thick, part = _gmsh_surfaces(layout, h)
    shell = ShellMesh(xyz, tri, thick, part, PARTS)
    col = machine.frame.column
    reach = 0.5 * np.hypot(col.width, col.height) + 1e-6
    column_nodes = np.unique(tri[part == PARTS.index('column')])
    hub_nodes = np.unique(tri[part == PARTS.index('hub')])
    points: dict[str, Array] = {}
    coupled: dict[str, npt.NDArray[np.int64]] = {}
    for i in range(N_STRUTS):
        near = column_nodes[np.linalg.norm(xyz[column_nodes, :2] - layout.columns[i, :2],
                                           axis=1) < reach]
        points[f'foot{i + 1}'] = layout.columns[i].copy()
        coupled[f'foot{i + 1}'] = near[np.abs(xyz[near, 2]) < 1e-6]
        points[f'bp_ring{i + 1}'] = layout.seats[i].copy()
        coupled[f'bp_ring{i + 1}'] = near[np.abs(xyz[near, 2] - layout.seats[i, 2])
                                          <= sh.seat_height / 2 + 1e-6]
    points['bed'] = layout.bed.copy()
    coupled['bed'] = hub_nodes[np.abs(xyz[hub_nodes, 2] - layout.bed[2]) < 1e-6]
    for name, nodes in coupled.items():
        if nodes.size < 3:
            raise ConfigError(f'shell frame: interface point {name} couples only {nodes.size} '
                              f'nodes (element_size {h} m too coarse for the seat height or '
                              'the geometry is inconsistent)')
    LOG.info('plate frame meshed: %d nodes, %d triangles (element size %.3g m)',
             shell.n_nodes, tri.shape[0], h)
    return FrameMesh(shell, points, coupled)
