"""
Geometric definitions of the plant's ports: which points, directions and signs make each one.

The one home of the port names, units, descriptions and collocated pairs
(docs/architecture.md); :mod:`pentapod_sim.plant.ports` turns a definition into a load vector
or an observation row on FE DOFs or modal coordinates.

Besides displacement points, a definition may name a *load point*: a (6, n) matrix whose rows
give the force and moment an element group exerts on a node per unit DOF displacement
(:func:`pentapod_sim.plant.ports.load_points`). The strut force outputs ``strut<i>_force``
read the feed-drive link's load point and add the drive force itself as a direct term.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

N_STRUTS = 5
AXES = ('x', 'y', 'z')
#: Default chord point of the chord ports: share of the way from the BP joint to the WP joint.
CHORD_POSITION = 0.5
#: Port kinds: inputs are 'force'; outputs act on displacements ('displacement', and 'load':
#: a force computed from displacements plus direct terms) or on velocities ('velocity').
KINDS = ('force', 'displacement', 'velocity', 'load')

#: (point name, 3-vector direction, 'translation' or 'rotation', sign)
_Term = tuple[str, npt.NDArray[np.float64], str, float]


@dataclass(frozen=True)
class Definition:
    """
    Geometric definition of a port and its metadata.

    ``terms`` are (point, direction, part, sign); ``direct`` are (input port, coefficient):
    the output's feed-through from those inputs (only 'load' outputs have them).
    """

    unit: str
    description: str
    kind: str
    terms: tuple[_Term, ...]
    direct: tuple[tuple[str, float], ...] = ()


def drive_link_point(i: int) -> str:
    """Name of the load point of strut i's feed-drive link (force on the strut at its BP joint)."""
    return f'strut{i}_drive_link'


def _strut_terms(i: int, what: str, k: int, frames: npt.NDArray[np.float64]
                 ) -> tuple[_Term, ...]:
    """
    Terms of strut i's bending, axial or drive ports.

    Bending (what='bending', axis k=2/3), axial ('axial': strut against its BP ring) or
    drive ('drive': strut against its gimbal, across the feed-drive link) ports.
    """
    if what == 'bending':
        e = frames[i - 1, k - 1]
        return ((f'strut{i}_wp_end', e, 'rotation', 1.0),
                (f'strut{i}_rear_end', e, 'rotation', -1.0))
    e1 = frames[i - 1, 0]
    other = f'bp_ring{i}' if what == 'axial' else f'gimbal{i}'
    return ((f'strut{i}_at_bp', e1, 'translation', 1.0), (other, e1, 'translation', -1.0))


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


def _tcp_and_pma(defs: dict[str, Definition]) -> None:
    unit_vectors = np.eye(3)
    for a, axis in enumerate(AXES):
        tcp = (('tcp', unit_vectors[a], 'translation', 1.0),)
        defs[f'tcp_force_{axis}'] = Definition('N', f'force at the TCP along global {axis}',
                                               'force', tcp)
        defs[f'tcp_displacement_{axis}'] = Definition(
            'm', f'TCP displacement along global {axis}', 'displacement', tcp)
        defs[f'tcp_velocity_{axis}'] = Definition(
            'm/s', f'TCP velocity along global {axis}', 'velocity', tcp)


def _strut_ports(defs: dict[str, Definition], frames: npt.NDArray[np.float64]) -> None:
    for i in range(1, N_STRUTS + 1):
        for k in (2, 3):
            terms = _strut_terms(i, 'bending', k, frames)
            defs[f'strut{i}_bending_moment_{k}'] = Definition(
                'N m', f'moment pair about e{k} of strut {i}: +M at the WP end, -M at the rear '
                'end', 'force', terms)
            defs[f'strut{i}_bending_{k}'] = Definition(
                'rad', f'strut {i} bending about e{k}: rotation of the WP end minus the rear end',
                'displacement', terms)
            defs[f'strut{i}_bending_rate_{k}'] = Definition(
                'rad/s', f'rate of strut {i} bending about e{k}', 'velocity', terms)
        terms = _strut_terms(i, 'axial', 1, frames)
        defs[f'strut{i}_axial_force'] = Definition(
            'N', f'axial force pair along e1 of strut {i}: +F on the strut at the BP joint, '
            '-F on the outer cardan ring', 'force', terms)
        defs[f'strut{i}_axial_displacement'] = Definition(
            'm', f'strut {i} axial motion relative to its BP cardan ring', 'displacement', terms)
        defs[f'strut{i}_axial_velocity'] = Definition(
            'm/s', f'strut {i} axial velocity relative to its BP cardan ring', 'velocity', terms)


def _drive_ports(defs: dict[str, Definition], frames: npt.NDArray[np.float64]) -> None:
    for i in range(1, N_STRUTS + 1):
        terms = _strut_terms(i, 'drive', 1, frames)
        defs[f'strut{i}_drive_force'] = Definition(
            'N', f'feed-drive force of strut {i} along e1: +F on the strut (ball screw) at its '
            'BP joint, -F on its gimbal (nut and motor), in parallel with the drive link',
            'force', terms)
        defs[f'strut{i}_drive_displacement'] = Definition(
            'm', f'strut {i} axial motion relative to its gimbal (across the drive link)',
            'displacement', terms)
        defs[f'strut{i}_drive_velocity'] = Definition(
            'm/s', f'strut {i} axial velocity relative to its gimbal', 'velocity', terms)
        defs[f'strut{i}_force'] = Definition(
            'N', f'axial force of strut {i} through a load cell between its nut and gimbal: '
            'the drive force plus the elastic force of the drive link, on the strut along e1 '
            '(> 0 pushes the strut towards its WP joint)', 'load',
            ((drive_link_point(i), frames[i - 1, 0], 'translation', 1.0),),
            ((f'strut{i}_drive_force', 1.0),))


def _chord_ports(defs: dict[str, Definition], frames: npt.NDArray[np.float64],
                 n_span: dict[int, int] | None, chord_position: float) -> None:
    for i in range(1, N_STRUTS + 1):
        for k in (2, 3):
            terms = (_chord_terms(i, k, frames, n_span[i], chord_position)
                     if n_span and i in n_span else ())
            defs[f'strut{i}_chord_force_{k}'] = Definition(
                'N', f'lateral force along e{k} on strut {i} at its chord point, reacted at its '
                'two joints in proportion to the chord interpolation', 'force', terms)
            defs[f'strut{i}_chord_{k}'] = Definition(
                'm', f'strut {i} lateral displacement along e{k} of its chord point relative to '
                'the chord between its joints', 'displacement', terms)
            defs[f'strut{i}_chord_velocity_{k}'] = Definition(
                'm/s', f'rate of strut {i} chord displacement along e{k}', 'velocity', terms)


def definitions(frames: npt.NDArray[np.float64], n_span: dict[int, int] | None = None,
                chord_position: float = CHORD_POSITION) -> dict[str, Definition]:
    """
    All port definitions for the given strut frames (5, 3, 3), keyed by name.

    ``n_span`` gives each strut's number of elements on its active span (chord ports); without
    it the chord ports have no terms (names and metadata only).
    """
    defs: dict[str, Definition] = {}
    _tcp_and_pma(defs)
    _strut_ports(defs, frames)
    unit_vectors = np.eye(3)
    for a, axis in enumerate(AXES):
        pma = (('pma_mount', unit_vectors[a], 'translation', 1.0),)
        defs[f'pma_force_{axis}'] = Definition(
            'N', f'proof-mass actuator force at the PMA mount along global {axis}', 'force', pma)
        defs[f'pma_mount_velocity_{axis}'] = Definition(
            'm/s', f'PMA mount velocity along global {axis}', 'velocity', pma)
    _chord_ports(defs, frames, n_span, chord_position)
    _drive_ports(defs, frames)
    return defs


_NAMES = definitions(np.tile(np.eye(3), (N_STRUTS, 1, 1)))
INPUT_NAMES: tuple[str, ...] = tuple(n for n, d in _NAMES.items() if d.kind == 'force')
OUTPUT_NAMES: tuple[str, ...] = tuple(
    [f'tcp_displacement_{a}' for a in AXES] + [f'tcp_velocity_{a}' for a in AXES]
    + [f'strut{i}_{what}' for i in range(1, N_STRUTS + 1)
       for what in ('bending_2', 'bending_3', 'bending_rate_2', 'bending_rate_3',
                    'axial_displacement', 'axial_velocity')]
    + [f'pma_mount_velocity_{a}' for a in AXES]
    + [f'strut{i}_{what}_{k}' for i in range(1, N_STRUTS + 1)
       for what in ('chord', 'chord_velocity') for k in (2, 3)]
    + [f'strut{i}_{what}' for i in range(1, N_STRUTS + 1)
       for what in ('drive_displacement', 'drive_velocity', 'force')])


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
            table[(f'strut{i}_chord_force_{k}', 'displacement')] = f'strut{i}_chord_{k}'
            table[(f'strut{i}_chord_force_{k}', 'velocity')] = f'strut{i}_chord_velocity_{k}'
        table[(f'strut{i}_axial_force', 'displacement')] = f'strut{i}_axial_displacement'
        table[(f'strut{i}_axial_force', 'velocity')] = f'strut{i}_axial_velocity'
        table[(f'strut{i}_drive_force', 'displacement')] = f'strut{i}_drive_displacement'
        table[(f'strut{i}_drive_force', 'velocity')] = f'strut{i}_drive_velocity'
        table[(f'strut{i}_drive_force', 'load')] = f'strut{i}_force'
    return table


COLLOCATED = _collocated_table()
