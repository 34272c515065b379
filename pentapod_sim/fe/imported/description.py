"""
The machine description of an imported FE model (a YAML file; docs/own_machine.md).

Every key is a :func:`pentapod_sim.schema.spec` field below, validated like the project's other
configuration files: unknown keys (with the closest known one), missing keys, wrong types and
values out of range are one-line errors naming the file and the key. Relative file names are
relative to the description's folder.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
import os
from pathlib import Path

from pentapod_sim.errors import ConfigError
from pentapod_sim.schema import internal, load, POSITIVE, spec

#: Matrix file formats: what each needs besides mass and stiffness.
FORMATS = ('matrix-market', 'abaqus', 'mapdl-full')
#: Common unit systems as (m, kg) per model unit of length and mass, for the docs and errors.
UNIT_SYSTEMS = {'SI (m, kg, s)': (1.0, 1.0), 'mm, t, s': (1e-3, 1e3),
                'in, lbf s^2/in, s': (0.0254, 175.126835)}


@dataclass(frozen=True)
class PointSpec:
    """A named point: an FE node, or a point rigidly attached to one (e.g. the TCP)."""

    node: int = spec(description='label of the FE node the point is (or is attached to)')
    offset: tuple[float, ...] = spec('model length', length=3, default=(0.0, 0.0, 0.0),
                                     description='point minus node position, global frame')


@dataclass(frozen=True)
class FEDescription:
    """Settings of an FE model description file; see docs/own_machine.md."""

    format: str = spec(choices=FORMATS, description='format of the matrix files')
    length_unit: float = spec('m', POSITIVE, description='metres per model length unit')
    mass_unit: float = spec('kg', POSITIVE, description='kilograms per model mass unit')
    mass: str | None = spec(default=None, description='mass matrix file')
    stiffness: str | dict[str, str] | None = spec(
        default=None, description='stiffness matrix file, or one per element group (summed)')
    matrices: str | None = spec(default=None, description='file holding M and K (mapdl-full)')
    dofs: str | None = spec(default=None, description='DOF map CSV node,component '
                            '(matrix-market)')
    nodes: str | None = spec(default=None, description='node coordinates: .csv (node,x,y,z), '
                             'Abaqus .inp (*NODE) or ANSYS .cdb')
    points: dict[str, PointSpec] = spec(default_factory=dict,
                                        description='named points (tcp, strut ends, joints)')
    strut_frames: tuple[tuple[tuple[float, ...], ...], ...] | None = spec(
        default=None, description='rows e1, e2, e3 of each strut (default: from the joints)')
    pose: tuple[float, ...] | None = spec('m, rad', default=None,
                                          description='TCP pose x, y, z, a, b of the model')
    penalty_diagonal: float = spec('model stiffness', POSITIVE, default=1.0e30,
                                   description='DOFs with a stiffness diagonal at least this '
                                   'large are constrained (dropped)')
    source: str = internal()

    def __post_init__(self) -> None:
        if self.format == 'mapdl-full':
            if self.matrices is None:
                raise ConfigError("format mapdl-full: give 'matrices' (the .full file)")
            if self.mass is not None or self.stiffness is not None:
                raise ConfigError("format mapdl-full: the .full file holds M and K; leave out "
                                  "'mass' and 'stiffness'")
        else:
            missing = [k for k in ('mass', 'stiffness') if getattr(self, k) is None]
            if missing:
                raise ConfigError(f'format {self.format}: missing key(s) {", ".join(missing)}')
            if self.matrices is not None:
                raise ConfigError(f"format {self.format}: 'matrices' is for mapdl-full only")
        if self.format == 'matrix-market' and self.dofs is None:
            raise ConfigError("format matrix-market: give 'dofs' (CSV node,component of every "
                              'matrix row): a Matrix Market file has no DOF labels')
        if self.strut_frames is not None and (
                len(self.strut_frames) != 5
                or any(len(f) != 3 or any(len(e) != 3 for e in f) for f in self.strut_frames)):
            raise ConfigError('strut_frames: expected 5 frames of 3 rows e1, e2, e3 of 3 numbers')
        if self.pose is not None and len(self.pose) != 5:
            raise ConfigError(f'pose: expected x, y, z [m], a, b [rad], got {self.pose!r}')
        if self.points and self.nodes is None:
            raise ConfigError("points need node coordinates: give 'nodes'")

    def path(self, name: str) -> Path:
        """A file named in the description, relative to the description's folder."""
        return Path(self.source).parent / name

    @property
    def stiffness_files(self) -> dict[str, str]:
        """Element group -> stiffness file (one group 'structure' for a single file)."""
        if isinstance(self.stiffness, dict):
            return dict(self.stiffness)
        return {} if self.stiffness is None else {'structure': self.stiffness}


def load_description(path: str | os.PathLike[str]) -> FEDescription:
    """
    Read and validate an FE model description.

    Raises
    ------
    ConfigError
        Naming the file, the key path and the bad value (or the closest known key).
    """
    description = replace(load(FEDescription, path), source=str(path))
    if isinstance(description.stiffness, dict) and not description.stiffness:
        raise ConfigError(f'{path}: stiffness: expected a file or a mapping of groups to files')
    return description
