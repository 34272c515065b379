"""
Model mode shapes out: UFF dataset 55 at named points and FE nodes, and the values at ports.

Each mode is one dataset 55 (structural model, normal mode analysis, displacement, 6 values
per node: ux, uy, uz [m], rx, ry, rz [rad] per unit modal coordinate of a mass-normalised
shape, modal mass 1 kg), written and read with pyuff; dataset 15 gives the nodes' coordinates.
UFF numbers its nodes, so a CSV beside the file (``<stem>_nodes.csv``: ``uff_node,name``) says
which point or FE node each number is. UFF 55 holds nodal values only; a port's modal value
(a relative rotation or a chord displacement is no nodal DOF) goes to ``<stem>_ports.csv``
(``mode,frequency_hz,<port>...``). pyuff writes 6 significant digits (E13.5).
"""
from __future__ import annotations

import csv
from dataclasses import dataclass
import os
from pathlib import Path
from typing import Any, Sequence

import numpy as np
import numpy.typing as npt

from pentapod_sim.errors import BagError
from pentapod_sim.fe.model import FEModel
from pentapod_sim.plant.ports import port

NODE_COLUMNS = ('uff_node', 'name')


@dataclass
class ModeShapes:
    """Frequencies [Hz] (m,), shapes (N, 6, m) at named nodes, and the names (N,)."""

    frequencies_hz: npt.NDArray[np.float64]
    shapes: npt.NDArray[np.float64]
    names: list[str]
    positions: npt.NDArray[np.float64] | None = None


def model_shapes(fe: FEModel, frequencies_hz: npt.ArrayLike, shapes: npt.NDArray[np.float64],
                 names: Sequence[str] | None = None) -> ModeShapes:
    """
    Shapes of the computed modes at named points (default all) or FE nodes (``'node:<N>'``).

    Parameters
    ----------
    fe : FEModel
        The model (points, DOF map).
    frequencies_hz, shapes
        Its modes: (m,) [Hz] and mass-normalised (n, m).
    names : sequence of str, optional
        Point names or ``node:<label>`` entries.
    """
    names = list(names or fe.points)
    rows, positions = [], []
    for name in names:
        if name.startswith('node:'):
            label = int(name.split(':', 1)[1])
            if fe.dofs is None:
                raise BagError(f'UFF 55 export: the model has no DOF map to find node {label}')
            T = np.zeros((6, fe.n_dof))
            for c in range(6):
                hit = np.flatnonzero((fe.dofs.nodes == label) & (fe.dofs.components == c))
                if hit.size:
                    T[c, hit[0]] = 1.0
            if not T.any():
                raise BagError(f'UFF 55 export: the model has no node {label}')
            where = np.flatnonzero(fe.dofs.labels == label)
            positions.append(fe.dofs.xyz[where[0]] if where.size else np.full(3, np.nan))
            rows.append(T @ shapes)
        else:
            rows.append(np.asarray(fe.point(name) @ shapes))
            positions.append(fe.point_positions.get(name, np.full(3, np.nan)))
    return ModeShapes(np.asarray(frequencies_hz, dtype=float), np.array(rows), names,
                      np.array(positions))


def write_uff55(path: str | os.PathLike[str], data: ModeShapes,
                zeta: npt.ArrayLike | None = None) -> Path:
    """Write datasets 15 (coordinates) and 55 (one per mode) and the node name CSV."""
    import pyuff
    path = Path(path)
    numbers = np.arange(1, len(data.names) + 1)
    sets: list[dict[str, Any]] = []           # pyuff's datasets
    if data.positions is not None and np.all(np.isfinite(data.positions)):
        xyz = np.asarray(data.positions, dtype=float)
        sets.append(pyuff.prepare_15(node_nums=numbers, def_cs=np.zeros(len(numbers), int),
                                     disp_cs=np.zeros(len(numbers), int),
                                     color=np.ones(len(numbers), int), x=xyz[:, 0], y=xyz[:, 1],
                                     z=xyz[:, 2], return_full_dict=True))
    damping = np.broadcast_to(np.asarray(0.0 if zeta is None else zeta, float),
                              data.frequencies_hz.shape)
    for j, f in enumerate(data.frequencies_hz):
        values = data.shapes[:, :, j]
        sets.append(pyuff.prepare_55(
            id1=f'mode {j + 1} at {f:.4f} Hz (mass-normalised, modal mass 1 kg)',
            id2='pentapod_testbed model mode shapes', id3='', id4='', id5='', model_type=1,
            analysis_type=2, data_ch=2, spec_data_type=8, data_type=2, n_data_per_node=6,
            r1=values[:, 0], r2=values[:, 1], r3=values[:, 2], r4=values[:, 3],
            r5=values[:, 4], r6=values[:, 5], load_case=1, mode_n=j + 1, freq=float(f),
            modal_m=1.0, modal_damp_vis=float(damping[j]), modal_damp_his=0.0,
            node_nums=numbers, return_full_dict=True))
    if path.exists():
        path.unlink()
    pyuff.UFF(os.fspath(path)).write_sets(sets, mode='add')
    with open(_names_path(path), 'w', newline='', encoding='utf-8') as stream:
        writer = csv.writer(stream)
        writer.writerow(NODE_COLUMNS)
        writer.writerows(zip(numbers.tolist(), data.names))
    return path


def _names_path(path: Path) -> Path:
    return path.with_name(f'{path.stem}_nodes.csv')


def read_uff55(path: str | os.PathLike[str]) -> ModeShapes:
    """Read datasets 55 (and the node name CSV beside the file, if there)."""
    import pyuff
    path = Path(path)
    try:
        sets = pyuff.UFF(os.fspath(path)).read_sets()
    except Exception as err:      # pyuff raises bare Exceptions for malformed files
        raise BagError(f'{path}: not a readable UFF file: {err}') from None
    sets = sets if isinstance(sets, list) else [sets]
    modes = sorted((s for s in sets if s.get('type') == 55 and s.get('analysis_type') == 2),
                   key=lambda s: s['mode_n'])
    if not modes:
        raise BagError(f'{path}: no UFF 55 normal-mode dataset')
    nodes = np.asarray(modes[0]['node_nums'], dtype=int)
    shapes = np.zeros((nodes.size, 6, len(modes)))
    for j, s in enumerate(modes):
        if not np.array_equal(np.asarray(s['node_nums'], dtype=int), nodes):
            raise BagError(f'{path}: mode {s["mode_n"]} has other nodes than mode 1')
        for c in range(6 if s.get('n_data_per_node') == 6 else 3):
            shapes[:, c, j] = s[f'r{c + 1}']
    names = {str(n): str(n) for n in nodes}
    if _names_path(path).exists():
        with open(_names_path(path), newline='', encoding='utf-8') as stream:
            names.update({r['uff_node']: r['name'] for r in csv.DictReader(stream)})
    coords = next((s for s in sets if s.get('type') in (15, 2411)), None)
    positions = None
    if coords is not None:
        where = {int(n): k for k, n in enumerate(coords['node_nums'])}
        positions = np.array([[coords[a][where[int(n)]] for a in 'xyz'] for n in nodes])
    return ModeShapes(np.array([float(s['freq']) for s in modes]), shapes,
                      [names[str(n)] for n in nodes], positions)


def write_port_values(path: str | os.PathLike[str], fe: FEModel,
                      frequencies_hz: npt.NDArray[np.float64], shapes: npt.NDArray[np.float64],
                      port_names: Sequence[str]) -> Path:
    """Modal value of each port per mode (``p^T phi``) as CSV: mode, frequency, ports."""
    vectors = np.array([port(fe.points, fe.strut_frames, n).vector for n in port_names])
    values = vectors @ shapes
    path = Path(path)
    with open(path, 'w', newline='', encoding='utf-8') as stream:
        writer = csv.writer(stream)
        writer.writerow(['mode', 'frequency_hz', *port_names])
        for j, f in enumerate(frequencies_hz):
            writer.writerow([j + 1, repr(float(f)), *[repr(float(v)) for v in values[:, j]]])
    return path
