"""
Named plant inputs and outputs tied to physical degrees of freedom.

A port is defined on named points (6-row observation matrices ``T``, see
:class:`pentapod_sim.fe.model.FEModel`) and the strut frames. The same definitions work on
two kinds of coordinates:

* FE coordinates: ``points`` are the FE model's (6, n) matrices; a port's vector is then a
  load vector (input) or an observation row (output) over the n FE DOFs.
* Modal coordinates: ``points`` are the mode shapes at the points, ``T @ Phi`` (6, m); the
  same formulas then give the modal input column ``Phi^T B`` and modal output row ``C Phi``.
  This is how external modal data (ANSYS, Abaqus) enters, see :func:`modal_points`.

Names, units and definitions follow docs/architecture.md
(:mod:`pentapod_sim.plant.port_definitions`). Every output is collocated with an input (same
vector), so velocity feedback ``u = -g * rate`` through a pair dissipates energy. The strut
force outputs are loads: the force of the feed-drive link computed from displacements through
its stiffness (the load points of :func:`load_points`), plus the drive force as a direct term.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Mapping, Sequence

import numpy as np
import numpy.typing as npt
import scipy.sparse as sp

from pentapod_sim.errors import PortError
from pentapod_sim.plant.port_definitions import (  # noqa: F401 (re-exported)
    AXES as AXES,
)
from pentapod_sim.plant.port_definitions import (
    CHORD_POSITION as CHORD_POSITION,
)
from pentapod_sim.plant.port_definitions import (
    COLLOCATED,
    definitions,
    drive_link_point,
)
from pentapod_sim.plant.port_definitions import (
    INPUT_NAMES as INPUT_NAMES,
)
from pentapod_sim.plant.port_definitions import (
    KINDS as KINDS,
)
from pentapod_sim.plant.port_definitions import (
    N_STRUTS as N_STRUTS,
)
from pentapod_sim.plant.port_definitions import (
    OUTPUT_NAMES as OUTPUT_NAMES,
)

_COLLOCATED = COLLOCATED


@dataclass(frozen=True)
class Port:
    """
    One named plant input or output.

    Attributes
    ----------
    name : str
        Port name from docs/architecture.md, e.g. 'tcp_force_y'.
    unit : str
        SI unit of the port signal ('N', 'N m', 'm', 'm/s', 'rad', 'rad/s').
    description : str
        What the port acts on or measures.
    kind : str
        'force' for inputs; 'displacement', 'velocity' or 'load' (a force measured in the
        structure: computed from displacements, plus direct terms) for outputs.
    vector : (n,) ndarray
        Input: generalised load vector per unit input [1/N or 1/(N m) times DOF load];
        output: observation row applied to displacements (kinds 'displacement' and 'load') or
        to velocities (kind 'velocity').
    direct : tuple of (str, float)
        Output's feed-through from inputs: (input port, coefficient); only 'load' outputs.
    """

    name: str
    unit: str
    description: str
    kind: str
    vector: npt.NDArray[np.float64]
    direct: tuple[tuple[str, float], ...] = ()

    @property
    def is_input(self) -> bool:
        """True for force inputs."""
        return self.kind == 'force'


def check_names(names: Sequence[str], direction: str = 'any') -> None:
    """
    Raise PortError unless every name is a known port of the given direction.

    Parameters
    ----------
    names : sequence of str
        Port names to check.
    direction : {'input', 'output', 'any'}
        Which ports are allowed.
    """
    known = {'input': INPUT_NAMES, 'output': OUTPUT_NAMES,
             'any': INPUT_NAMES + OUTPUT_NAMES}[direction]
    kind = '' if direction == 'any' else f'{direction} '
    for name in names:
        if name not in known:
            raise PortError(f'unknown {kind}port {name!r}; known {kind}ports: '
                            + ', '.join(known))


def collocated_output(input_name: str, kind: str = 'velocity') -> str:
    """
    Return the output collocated with an input, of kind 'velocity' or 'displacement'.

    Raises
    ------
    PortError
        If the input is unknown or has no collocated output of that kind (the PMA has no
        displacement output).
    """
    check_names([input_name], 'input')
    try:
        return _COLLOCATED[(input_name, kind)]
    except KeyError:
        raise PortError(f'input {input_name!r} has no collocated {kind!r} output') from None


def collocated_input_of(output_name: str) -> str:
    """
    Return the input collocated with an output (displacement or velocity).

    Raises
    ------
    PortError
        If the output is unknown or no input acts where it measures.
    """
    check_names([output_name], 'output')
    for (inp, _), out in _COLLOCATED.items():
        if out == output_name:
            return inp
    raise PortError(f'output {output_name!r} has no collocated input')

def _point_rows(points: Mapping[str, Any], name: str) -> npt.NDArray[np.float64]:
    """Dense (6, n) observation matrix of a point; PortError names missing points."""
    try:
        matrix = points[name]
    except KeyError:
        if name.endswith('_drive_link'):
            raise PortError(f'the model has no load point {name!r}: the strut force outputs '
                            "need the FE model's stiffness group 'feed_drives' (load_points) "
                            'or, for modal data, the point given as the force of the drive '
                            'link on the strut per unit modal coordinate') from None
        raise PortError(f'the model has no point {name!r} needed by a port; known points: '
                        + ', '.join(sorted(points))) from None
    return matrix.toarray() if sp.issparse(matrix) else np.asarray(matrix, dtype=float)


def _span_counts(points: Mapping[str, Any]) -> dict[int, int]:
    """Elements of each strut's active span: one more than its ``strut<i>_span<j>`` points."""
    counts = {}
    for i in range(1, N_STRUTS + 1):
        n = 1
        while f'strut{i}_span{n}' in points:
            n += 1
        if n > 1:
            counts[i] = n
    return counts


def port(points: Mapping[str, Any], strut_frames: npt.ArrayLike, name: str,
         chord_position: float = CHORD_POSITION) -> Port:
    """
    Build one port on the given point matrices.

    Parameters
    ----------
    points : mapping of str to (6, n) matrix
        Observation matrices of the named points (FE DOFs or modal coordinates).
    strut_frames : (5, 3, 3) array_like
        Rows e1, e2, e3 of each strut frame (unit vectors, global frame).
    name : str
        Port name.
    chord_position : float
        Chord point of the chord ports: share of the way from the BP joint to the WP joint
        (0..1, default mid-span). They need the points ``strut<i>_span<j>``.

    Returns
    -------
    Port
        With ``vector`` of length n.
    """
    check_names([name])
    if not 0.0 <= chord_position <= 1.0:
        raise PortError(f'chord_position must be within 0..1, got {chord_position!r}')
    frames = np.asarray(strut_frames, dtype=float)
    counts = _span_counts(points) if '_chord' in name else None
    definition = definitions(frames, counts, chord_position)[name]
    if '_chord' in name and not definition.terms:
        raise PortError(f"port {name!r} needs the points of the strut's active span "
                        f'(strut<i>_span<j>); the model has none')
    vector: np.ndarray | None = None
    for point_name, direction, part, sign in definition.terms:
        rows = _point_rows(points, point_name)
        block = rows[0:3] if part == 'translation' else rows[3:6]
        term = sign * (direction @ block)
        vector = term if vector is None else vector + term
    if vector is None:
        raise PortError(f'port {name!r} has no terms')
    return Port(name, definition.unit, definition.description, definition.kind, vector,
                definition.direct)


def ports(points: Mapping[str, Any], strut_frames: npt.ArrayLike, names: Sequence[str],
          chord_position: float = CHORD_POSITION) -> list[Port]:
    """Build several ports; see :func:`port`."""
    return [port(points, strut_frames, name, chord_position) for name in names]


def input_matrix(port_list: Sequence[Port]) -> npt.NDArray[np.float64]:
    """
    Stack input ports into the load matrix B (n, n_in).

    Raises
    ------
    PortError
        If one of the ports is an output.
    """
    for p in port_list:
        if not p.is_input:
            raise PortError(f'{p.name!r} is an output, not an input')
    return np.column_stack([p.vector for p in port_list])


def output_matrices(port_list: Sequence[Port]
                    ) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """
    Stack output ports into displacement and velocity observation matrices.

    Returns
    -------
    C_disp, C_vel : (n_out, n) ndarray
        ``y = C_disp u + C_vel du/dt``; a displacement (or load) port has its row in
        ``C_disp`` and zeros in ``C_vel``, a velocity port the reverse. The direct terms of
        load ports are :func:`direct_matrix`.

    Raises
    ------
    PortError
        If one of the ports is an input.
    """
    n = len(port_list[0].vector) if port_list else 0
    c_disp = np.zeros((len(port_list), n))
    c_vel = np.zeros((len(port_list), n))
    for row, p in enumerate(port_list):
        if p.is_input:
            raise PortError(f'{p.name!r} is an input, not an output')
        (c_vel if p.kind == 'velocity' else c_disp)[row] = p.vector
    return c_disp, c_vel


def modal_points(points: Mapping[str, Any], shapes: npt.ArrayLike
                 ) -> dict[str, npt.NDArray[np.float64]]:
    """
    Project point observation matrices onto mode shapes.

    Parameters
    ----------
    points : mapping of str to (6, n) matrix
        FE observation matrices.
    shapes : (n, m) array_like
        Mass-normalised mode shapes [1/sqrt(kg)].

    Returns
    -------
    dict of str to (6, m) ndarray
        ``T @ Phi`` per point: the modal displacements/rotations at the point.
    """
    phi = np.asarray(shapes, dtype=float)
    return {name: np.asarray(matrix @ phi) for name, matrix in points.items()}


def direct_matrix(output_ports: Sequence[Port], input_names: Sequence[str]
                  ) -> npt.NDArray[np.float64]:
    """
    Feed-through (n_out, n_in) of the outputs' direct terms from the named inputs.

    Only load outputs have direct terms (``strut<i>_force``: 1 from ``strut<i>_drive_force``);
    an input that is not among ``input_names`` contributes nothing.
    """
    index = {name: j for j, name in enumerate(input_names)}
    d = np.zeros((len(output_ports), len(input_names)))
    for row, p in enumerate(output_ports):
        for name, coefficient in p.direct:
            if name in index:
                d[row, index[name]] += coefficient
    return d


def load_points(points: Mapping[str, Any], stiffness_groups: Mapping[str, Any],
                group: str = 'feed_drives') -> dict[str, sp.csr_matrix]:
    """
    Load points of the feed-drive links: the force on each strut at its BP joint from the link.

    ``strut<i>_drive_link`` is ``-T K_g`` (6, n) with ``T`` the observation matrix of
    ``strut<i>_at_bp`` and ``K_g`` the stiffness of the element group ``group`` (the FE
    model's ``stiffness_groups``): its rows give the force [N] and moment [N m] that the
    group's elements exert on the strut node per unit DOF displacement. Only the link between
    strut and gimbal (the feed drive's nut spring) of that group touches the strut node, so
    along e1 this is ``-k_a (u_at_bp - u_gimbal) . e1``. Returns {} when the model has no such
    group or no strut points (an imported FE model may lack them); the ``strut<i>_force``
    ports then cannot be built.
    """
    k_group = stiffness_groups.get(group)
    if k_group is None:
        return {}
    out = {}
    for i in range(1, N_STRUTS + 1):
        name = f'strut{i}_at_bp'
        if name in points:
            out[drive_link_point(i)] = sp.csr_matrix(-(sp.csr_matrix(points[name])
                                                       @ sp.csr_matrix(k_group)))
    return out
