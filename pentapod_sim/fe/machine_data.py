"""
Machine parameter file (``config/machine.yaml``) and named positions (``config/positions.yaml``).

Every parameter is a field of a frozen dataclass whose metadata holds its unit and its
admissible range (:mod:`pentapod_sim.schema`, the one validation style of all configuration
files); :func:`load_machine` checks the YAML against that schema (missing keys, unknown keys
with the closest known one, wrong types, values out of range) and raises
:class:`pentapod_sim.errors.ConfigError` naming the file, the key path and the bad value.
Quantities in radians may be written in degrees in YAML by appending ``_deg`` to the key.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
import os
from pathlib import Path
import typing

import numpy as np
import numpy.typing as npt

from pentapod_sim.errors import ConfigError
from pentapod_sim.paths import config_dir
from pentapod_sim.schema import ANY, build, internal, NON_NEGATIVE, POSITIVE, read_mapping, spec

__all__ = ['config_dir', 'load_machine', 'load_positions', 'machine_from_dict', 'MachineParams',
           'machine_path', 'Pose', 'positions_path']
_T = typing.TypeVar('_T')


def _f(unit: str, rule: str = POSITIVE, length: int | None = None,
       per_strut: bool = False) -> typing.Any:
    """
    Declare a float (or fixed-length float tuple) field with unit and range rule.

    ``per_strut=True``: a tuple of 5 values (struts 1..5); the YAML may give one number for all.
    """
    return spec(unit, rule, length=5 if per_strut else length, broadcast=per_strut)


@typing.dataclass_transform(frozen_default=True, field_specifiers=(field, spec, _f))
def _schema(cls: type[_T]) -> type[_T]:
    """
    ``dataclass(frozen=True)``, telling a type checker which calls declare fields.

    :func:`_f` and :func:`pentapod_sim.schema.spec` make a ``dataclasses.field`` with a default
    only if given one; a checker that does not know them takes each for a default value.
    """
    return dataclass(frozen=True)(cls)


@_schema
class MeshParams:
    """Beam meshing: target element length [m] and least elements per member [-]."""

    element_size: float = _f('m')
    min_elements_per_member: int = _f('-')


@_schema
class Material:
    """Isotropic linear-elastic material: E [Pa], G [Pa], density [kg/m^3]."""

    youngs_modulus: float = _f('Pa')
    shear_modulus: float = _f('Pa')
    density: float = _f('kg/m^3')


@_schema
class Materials:
    """Named materials of the machine."""

    steel: Material


@_schema
class RhsSection:
    """Rectangular hollow section: outer width (local y) and height (local z), wall [m]."""

    width: float = _f('m')
    height: float = _f('m')
    thickness: float = _f('m')


@_schema
class FrameParams:
    """Machine frame: columns, rings, spokes, BP brackets and the lumped bed."""

    column_radius: float = _f('m')
    column_height: float = _f('m')
    base_ring_z: float = _f('m')
    column: RhsSection
    ring: RhsSection
    spoke: RhsSection
    bp_bracket: RhsSection
    bed_mass: float = _f('kg')
    bed_z: float = _f('m')
    bed_inertia: tuple[float, ...] = _f('kg m^2', length=3)
    model: str = spec(default='beams', choices=('beams', 'shells'),
                      description='frame model: beams (fast) or shells (plate frame)')


@_schema
class ShellFrameParams:
    """
    Plate frame (``frame.model: shells``): mesh, walls, hub, seats and its reduction.

    The frame's boxes take their sizes from the ``frame`` section (columns, rings, spokes);
    this section adds what beams do not have (pentapod_sim.fe.frame_mesh).
    """

    element_size: float = _f('m')
    wall_thickness: float = _f('m')
    walls: tuple[bool, ...] = spec('-', length=5,
                                   description='wall in the bay from column i to the next '
                                               'column counter-clockwise (columns 1..5)')
    hub_width: float = _f('m')
    seat_height: float = _f('m')
    poisson_ratio: float = spec('-', bounds=(0.0, 0.5), closed=(True, False),
                                description='Poisson ratio of the plates')
    f_interest: float = _f('Hz')
    mode_multiple: float = spec('-', bounds=(1.0, 10.0),
                                description='fixed-interface modes up to this multiple of '
                                            'f_interest')
    foot_stiffness: tuple[float, ...] | None = spec(
        'N/m', POSITIVE, length=3, default=None,
        description='x, y, z stiffness of each foot with this frame (default: installation)')
    door_lintel: float = spec('m', NON_NEGATIVE, default=0.0,
                              description='height of the wall above the door in each bay '
                                          'without a wall, down from the top ring (0: open '
                                          'bay)')


@_schema
class InstallationParams:
    """Foundation springs of each of the five feet [N/m]."""

    foot_stiffness_x: float = _f('N/m')
    foot_stiffness_y: float = _f('N/m')
    foot_stiffness_z: float = _f('N/m')


@_schema
class BpJointParams:
    """BP cardan joints: layout, needle-bearing stiffness, gimbal mass and angle limit."""

    radius: float = _f('m')
    angles: tuple[float, ...] = _f('rad', ANY, length=5)
    z: tuple[float, ...] = _f('m', ANY, length=5)
    needle_axial_stiffness: float = _f('N/m')
    needle_cardan1_stiffness: float = _f('N/m')
    needle_cardan2_stiffness: float = _f('N/m')
    torsion_stiffness: float = _f('N m/rad')
    angle_max: float = _f('rad')
    gimbal_mass: float = _f('kg')
    gimbal_inertia: tuple[float, ...] = _f('kg m^2', length=3)


@_schema
class FeedDriveParams:
    """Strut-gimbal link: nut (axial), guide (lateral), bending and torsion stiffness."""

    nut_axial_stiffness: float = _f('N/m')
    guide_lateral_stiffness: float = _f('N/m')
    bending_stiffness: float = _f('N m/rad')
    torsion_stiffness: float = _f('N m/rad')


@_schema
class StrutParams:
    """
    Strut tubes: lengths, stroke limits [m], section, screw mass [kg/m], shear factor [-].

    ``tube_length``, ``stroke_min`` and ``stroke_max`` are tuples for struts 1..5 (the YAML may
    give one number for all struts).
    """

    tube_length: tuple[float, ...] = _f('m', per_strut=True)
    stroke_min: tuple[float, ...] = _f('m', per_strut=True)
    stroke_max: tuple[float, ...] = _f('m', per_strut=True)
    section: RhsSection
    screw_mass_per_length: float = _f('kg/m', NON_NEGATIVE)
    shear_factor: float = _f('-')


@_schema
class WpJointParams:
    """WP cardan joints: ring radius [m], heights above the nose [m], stiffness, limit."""

    radius: float = _f('m')
    height: tuple[float, ...] = _f('m', ANY, length=5)
    axial_stiffness: float = _f('N/m')
    lateral_stiffness: float = _f('N/m')
    torsion_stiffness: float = _f('N m/rad')
    angle_max: float = _f('rad')


@_schema
class PlatformParams:
    """Working platform (spindle housing) as a rigid body."""

    mass: float = _f('kg')
    cog_above_nose: float = _f('m', ANY)
    inertia: tuple[float, ...] = _f('kg m^2', length=3)
    tcp_below_nose: float = _f('m', NON_NEGATIVE)
    pma_mount_above_tcp: float = _f('m', ANY)


@_schema
class Pose:
    """Platform pose: TCP position x, y, z [m] and tilts a (about x), b (about y) [rad]."""

    x: float = _f('m', ANY)
    y: float = _f('m', ANY)
    z: float = _f('m', ANY)
    a: float = _f('rad', ANY)
    b: float = _f('rad', ANY)

    def as_array(self) -> npt.NDArray[np.float64]:
        """Return the pose as the array (x, y, z, a, b) [m, m, m, rad, rad]."""
        return np.array([self.x, self.y, self.z, self.a, self.b])


@_schema
class NamedPose(Pose):
    """A pose of config/positions.yaml with an optional description."""

    description: str = spec(default='', description='what the position is for')


@_schema
class PositionsFile:
    """config/positions.yaml: the named machine positions."""

    positions: dict[str, NamedPose] = spec(min_length=1, description='named machine positions')


@_schema
class MachineParams:
    """All parameters of the pentapod machine model (see config/machine.yaml)."""

    mesh: MeshParams
    materials: Materials
    frame: FrameParams
    installation: InstallationParams
    bp_joints: BpJointParams
    feed_drives: FeedDriveParams
    struts: StrutParams
    wp_joints: WpJointParams
    platform: PlatformParams
    home_pose: Pose
    shell_frame: ShellFrameParams | None = spec(default=None,
                                                description='plate frame (frame.model: shells)')
    source: str = internal()

    def __post_init__(self) -> None:
        _check_consistency(self)


def _check_consistency(m: MachineParams) -> None:
    """Cross-field checks that a single-value rule cannot express."""
    s = m.struts
    for i, (lo, hi, tube) in enumerate(zip(s.stroke_min, s.stroke_max, s.tube_length)):
        if lo >= hi:
            raise ConfigError(f'struts.stroke_min {lo!r} must be < struts.stroke_max {hi!r} '
                              f'(strut {i + 1})')
        if hi >= tube:
            raise ConfigError(f'struts.stroke_max {hi!r} must be < struts.tube_length {tube!r} '
                              f'(strut {i + 1}; the tube must pass through the BP joint)')
    for name in ('column', 'ring', 'spoke', 'bp_bracket'):
        _check_section(getattr(m.frame, name), f'frame.{name}')
    _check_section(s.section, 'struts.section')
    if not 0.0 < m.frame.base_ring_z < m.frame.column_height:
        raise ConfigError(f'frame.base_ring_z {m.frame.base_ring_z!r} must lie between 0 and '
                          f'frame.column_height {m.frame.column_height!r}')
    for i, z in enumerate(m.bp_joints.z):
        if not m.frame.base_ring_z < z < m.frame.column_height:
            raise ConfigError(f'bp_joints.z[{i}] {z!r} must lie between frame.base_ring_z and '
                              f'frame.column_height')
    if m.frame.model == 'shells' and m.shell_frame is None:
        raise ConfigError('frame.model is shells: the shell_frame section is missing')
    if m.bp_joints.radius >= m.frame.column_radius:
        raise ConfigError(f'bp_joints.radius {m.bp_joints.radius!r} must be < '
                          f'frame.column_radius {m.frame.column_radius!r}')


def _check_section(sec: RhsSection, path: str) -> None:
    if 2.0 * sec.thickness >= min(sec.width, sec.height):
        raise ConfigError(f'{path}.thickness {sec.thickness!r} is too large for a '
                          f'{sec.width!r} x {sec.height!r} section')


def machine_path(path: str | os.PathLike[str] | None = None) -> Path:
    """``path``, or machine.yaml of :func:`config_dir` if None."""
    return Path(path) if path is not None else config_dir() / 'machine.yaml'


def positions_path(path: str | os.PathLike[str] | None = None) -> Path:
    """``path``, or positions.yaml of :func:`config_dir` if None."""
    return Path(path) if path is not None else config_dir() / 'positions.yaml'


def machine_from_dict(data: dict[str, typing.Any], source: str = '<dict>') -> MachineParams:
    """
    Validate a parameter mapping (the parsed YAML) and return :class:`MachineParams`.

    Raises
    ------
    ConfigError
        Naming ``source``, the key path and value of the first problem found.
    """
    return replace(build(MachineParams, data, source), source=source)


def load_machine(path: str | os.PathLike[str] | None = None) -> MachineParams:
    """
    Load and validate the machine parameter file.

    Parameters
    ----------
    path : str or path-like, optional
        YAML file; default ``machine.yaml`` in :func:`config_dir`.

    Returns
    -------
    MachineParams
        Frozen, validated parameters in SI units (angles in rad).
    """
    path = machine_path(path)
    return machine_from_dict(read_mapping(path), source=str(path))


def load_positions(path: str | os.PathLike[str] | None = None
                   ) -> dict[str, npt.NDArray[np.float64]]:
    """
    Load the named machine positions.

    Parameters
    ----------
    path : str or path-like, optional
        YAML file with a mapping ``positions: {name: {x, y, z, a|a_deg, b|b_deg}}`` and an
        optional ``description`` per entry. Default ``positions.yaml`` in :func:`config_dir`.

    Returns
    -------
    dict of str to (5,) ndarray
        Pose x, y, z [m], a, b [rad] of the TCP for each name.
    """
    path = positions_path(path)
    doc = build(PositionsFile, read_mapping(path), str(path))
    return {name: entry.as_array() for name, entry in doc.positions.items()}
