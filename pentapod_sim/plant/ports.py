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

Names, units and definitions follow docs/architecture.md. Every output is collocated with an
input (same vector), so velocity feedback ``u = -g * rate`` through a pair dissipates energy.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Mapping, Sequence

import numpy as np
import numpy.typing as npt
import scipy.sparse as sp

from pentapod_sim.errors import PortError

N_STRUTS = 5
AXES = ('x', 'y', 'z')
#: Default chord point of the chord ports: share of the way from the BP joint to the WP joint.
CHORD_POSITION = 0.5
KINDS = ('force', 'displacement', 'velocity')


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
        'force' for inputs, 'displacement' or 'velocity' for outputs.
    vector : (n,) ndarray
        Input: generalised load vector per unit input [1/N or 1/(N m) times DOF load];
        output: observation row applied to displacements (kind 'displacement') or to
        velocities (kind 'velocity').
    """

    name: str
    unit: str
    description: str
    kind: str
    vector: npt.NDArray[np.float64]

    @property
    def is_input(self) -> bool:
        """True for force inputs."""
        return self.kind == 'force'


#: (point name, 3-vector direction, 'translation' or 'rotation', sign)
_Term = tuple[str, npt.NDArray[np.float64], str, float]


@dataclass(frozen=True)
class _Definition:
    """Geometric definition of a port: ((point, component rows, sign), ...) and metadata."""

    unit: str
    description: str
    kind: str
    terms: tuple[_Term, ...]


def _strut_terms(i: int, what: str, k: int, frames: npt.NDArray[np.float64]
                 ) -> tuple[_Term, ...]:
    """Terms of the strut bending (what='bending', axis k=2/3) or axial (what='axial') ports."""
    if what == 'bending':
        e = frames[i - 1, k - 1]
        return ((f'strut{i}_wp_end', e, 'rotation', 1.0),
                (f'strut{i}_rear_end', e, 'rotation', -1.0))
    e1 = frames[i - 1, 0]
    return ((f'strut{i}_at_bp', e1, 'translation', 1.0),
            (f'bp_ring{i}', e1, 'translation', -1.0))


def _chord_terms(i: int, k: int, frames: npt.NDArray[np.float64], n_span: int,
                 position: float) -> tuple[_Term, ...]:
    """
    Terms of strut i's chord port along e_k: the chord point minus the chord between joints.

    The active span (BP joint ``strut<i>_at_bp`` to WP joint ``strut<i>_wp_end``) has
    ``n_span`` equal elements with the inner nodes ``strut<i>_span<j>``; the point at
    ``position`` (0..1) is interpolated linearly between its neighbouring nodes, the chord
    point linearly between the joints. As an input: a force at the point and the reactions
    ``-(1 - s)`` and ``-s`` of it at the joints (no net force or moment).
    """
    e = frames[i - 1, k - 1]
    nodes = ([f'strut{i}_at_bp'] + [f'strut{i}_span{j}' for j in range(1, n_span)]
             + [f'strut{i}_wp_end'])
    q = position * n_span
    j0 = min(int(np.floor(q)), n_span - 1)
    t = q - j0
    return ((nodes[j0], e, 'translation', 1.0 - t), (nodes[j0 + 1], e, 'translation', t),
            (nodes[0], e, 'translation', -(1.0 - position)),
            (nodes[-1], e, 'translation', -position))


def _definitions(frames: npt.NDArray[np.float64], n_span: dict[int, int] | None = None,
                 chord_position: float = CHORD_POSITION) -> dict[str, _Definition]:
    """
    All port definitions for the given strut frames (5, 3, 3), keyed by name.

    ``n_span`` gives each strut's number of elements on its active span (chord ports); without
    it the chord ports have no terms (names and metadata only).
    """
    defs: dict[str, _Definition] = {}
    unit_vectors = np.eye(3)
    for a, axis in enumerate(AXES):
        tcp = (('tcp', unit_vectors[a], 'translation', 1.0),)
        defs[f'tcp_force_{axis}'] = _Definition('N', f'force at the TCP along global {axis}',
                                                'force', tcp)
        defs[f'tcp_displacement_{axis}'] = _Definition(
            'm', f'TCP displacement along global {axis}', 'displacement', tcp)
        defs[f'tcp_velocity_{axis}'] = _Definition(
            'm/s', f'TCP velocity along global {axis}', 'velocity', tcp)
    for i in range(1, N_STRUTS + 1):
        for k in (2, 3):
            terms = _strut_terms(i, 'bending', k, frames)
            defs[f'strut{i}_bending_moment_{k}'] = _Definition(
                'N m', f'moment pair about e{k} of strut {i}: +M at the WP end, -M at the rear '
                'end', 'force', terms)
            defs[f'strut{i}_bending_{k}'] = _Definition(
                'rad', f'strut {i} bending about e{k}: rotation of the WP end minus the rear end',
                'displacement', terms)
            defs[f'strut{i}_bending_rate_{k}'] = _Definition(
                'rad/s', f'rate of strut {i} bending about e{k}', 'velocity', terms)
        terms = _strut_terms(i, 'axial', 1, frames)
        defs[f'strut{i}_axial_force'] = _Definition(
            'N', f'axial force pair along e1 of strut {i}: +F on the strut at the BP joint, '
            '-F on the outer cardan ring', 'force', terms)
        defs[f'strut{i}_axial_displacement'] = _Definition(
            'm', f'strut {i} axial motion relative to its BP cardan ring', 'displacement', terms)
        defs[f'strut{i}_axial_velocity'] = _Definition(
            'm/s', f'strut {i} axial velocity relative to its BP cardan ring', 'velocity', terms)
    for a, axis in enumerate(AXES):
        pma = (('pma_mount', unit_vectors[a], 'translation', 1.0),)
        defs[f'pma_force_{axis}'] = _Definition(
            'N', f'proof-mass actuator force at the PMA mount along global {axis}', 'force', pma)
        defs[f'pma_mount_velocity_{axis}'] = _Definition(
            'm/s', f'PMA mount velocity along global {axis}', 'velocity', pma)
    for i in range(1, N_STRUTS + 1):
        for k in (2, 3):
            terms = (_chord_terms(i, k, frames, n_span[i], chord_position)
                     if n_span and i in n_span else ())
            defs[f'strut{i}_chord_force_{k}'] = _Definition(
                'N', f'lateral force along e{k} on strut {i} at its chord point, reacted at its '
                'two joints in proportion to the chord interpolation', 'force', terms)
            defs[f'strut{i}_chord_{k}'] = _Definition(
                'm', f'strut {i} lateral displacement along e{k} of its chord point relative to '
                'the chord between its joints', 'displacement', terms)
            defs[f'strut{i}_chord_velocity_{k}'] = _Definition(
                'm/s', f'rate of strut {i} chord displacement along e{k}', 'velocity', terms)
    return defs


_NAMES = _definitions(np.tile(np.eye(3), (N_STRUTS, 1, 1)))
INPUT_NAMES: tuple[str, ...] = tuple(n for n, d in _NAMES.items() if d.kind == 'force')
OUTPUT_NAMES: tuple[str, ...] = tuple(
    [f'tcp_displacement_{a}' for a in AXES] + [f'tcp_velocity_{a}' for a in AXES]
    + [f'strut{i}_{what}' for i in range(1, N_STRUTS + 1)
       for what in ('bending_2', 'bending_3', 'bending_rate_2', 'bending_rate_3',
                    'axial_displacement', 'axial_velocity')]
    + [f'pma_mount_velocity_{a}' for a in AXES]
    + [f'strut{i}_{what}_{k}' for i in range(1, N_STRUTS + 1)
       for what in ('chord', 'chord_velocity') for k in (2, 3)])


def _collocated_table() -> dict[tuple[str, str], str]:
    """Map (input name, output kind) to the collocated output name."""
    table = {}
    for axis in AXES:
        table[(f'tcp_force_{axis}', 'displacement')] = f'tcp_displacement_{axis}'
        table[(f'tcp_force_{axis}', 'velocity')] = f'tcp_velocity_{axis}'
        table[(f'pma_force_{axis}', 'velocity')] = f'pma_mount_velocity_{axis}'
    for i in range(1, N_STRUTS + 1):
        for k in (2, 3):
            table[(f'strut{i}_bending_moment_{k}', 'displacement')] = f'strut{i}_bending_{k}'
            table[(f'strut{i}_bending_moment_{k}', 'velocity')] = f'strut{i}_bending_rate_{k}'
        table[(f'strut{i}_axial_force', 'displacement')] = f'strut{i}_axial_displacement'
        table[(f'strut{i}_axial_force', 'velocity')] = f'strut{i}_axial_velocity'
        for k in (2, 3):
            table[(f'strut{i}_chord_force_{k}', 'displacement')] = f'strut{i}_chord_{k}'
            table[(f'strut{i}_chord_force_{k}', 'velocity')] = f'strut{i}_chord_velocity_{k}'
    return table


_COLLOCATED = _collocated_table()


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
    definition = _definitions(frames, counts, chord_position)[name]
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
    return Port(name, definition.unit, definition.description, definition.kind, vector)


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
        ``y = C_disp u + C_vel du/dt``; a displacement port has its row in ``C_disp`` and
        zeros in ``C_vel``, a velocity port the reverse.

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
        (c_disp if p.kind == 'displacement' else c_vel)[row] = p.vector
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
