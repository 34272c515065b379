"""
Settings of a calibration (``calibrate --settings FILE.yaml``; every key has a default).

Validated by :mod:`pentapod_sim.schema` like the other configuration files.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
import os

from pentapod_sim.analysis.calibration.pairing import FREQUENCY_TOLERANCE, MAC_MIN
from pentapod_sim.errors import ConfigError
from pentapod_sim.schema import internal, load, NON_NEGATIVE, POSITIVE, spec

FILLS = ('rayleigh', 'bands')


@dataclass(frozen=True)
class CalibrationSettings:
    """What a calibration identifies, pairs and fills (docs/own_machine.md)."""

    band: tuple[float, ...] | None = spec('Hz', NON_NEGATIVE, default=None, length=2,
                                          description='band analysed (default: the whole '
                                          'measurement)')
    modes_per_band: int = spec('-', POSITIVE, default=8, description='model modes per '
                               'identification sub-band')
    max_order: int = spec('-', POSITIVE, default=30, description='highest pLSCF order per '
                          'sub-band (poles: order x references)')
    refine: bool = spec(default=False, description='refine poles by nonlinear least squares')
    mac_min: float = spec('-', NON_NEGATIVE, default=MAC_MIN, bounds=(0.0, 1.0),
                          description='least MAC of a pair')
    frequency_tolerance: float = spec('-', POSITIVE, default=FREQUENCY_TOLERANCE,
                                      description='largest |f_measured / f_model - 1| of a pair')
    fill: str = spec(default='rayleigh', choices=FILLS, description='damping of unpaired modes')
    fill_edges: tuple[float, ...] = spec('Hz', NON_NEGATIVE, default=(),
                                         description='band edges of fill: bands')
    names: dict[str, str] = spec(default_factory=dict, description='UFF node number -> point '
                                 'name or FE node label')
    quantity: str = spec(default='displacement', choices=('displacement', 'velocity',
                                                          'acceleration'),
                         description='per-force quantity of a CSV measurement')
    source: str = internal()

    def __post_init__(self) -> None:
        if self.band is not None and not self.band[0] < self.band[1]:
            raise ConfigError(f'band = {list(self.band)} Hz: need f_min < f_max')
        if self.fill == 'bands' and len(self.fill_edges) < 2:
            raise ConfigError('fill: bands needs fill_edges (at least two frequencies)')
        for key in self.names:
            if not key.lstrip('-').isdigit():
                raise ConfigError(f'names.{key}: keys are UFF node numbers')

    @property
    def node_names(self) -> dict[int, str]:
        """UFF node number -> name."""
        return {int(k): v for k, v in self.names.items()}


def load_settings(path: str | os.PathLike[str] | None = None) -> CalibrationSettings:
    """The settings of ``path``, or the defaults."""
    if path is None:
        return CalibrationSettings()
    return replace(load(CalibrationSettings, path), source=str(path))
