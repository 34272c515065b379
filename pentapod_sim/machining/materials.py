"""
Materials, tools and operations of config/machining.yaml, validated by the project's schema.

A material gives its linear edge-force law ``F_t = K_tc a h + K_te a``, ``F_r = K_rc a h +
K_re a`` either directly or as a Kienzle law ``F_t = k_c1.1 a h^(1 - m_c)`` (h in mm)
linearised at a mean chip thickness h_0: the tangent's slope is the cutting coefficient
``K_tc = (1 - m_c) k_c(h_0)`` that the regenerative chip variation sees, its offset the edge
coefficient ``K_te = m_c k_c(h_0) h_0``, with ``k_c(h) = k_c1.1 (h / 1 mm)^-m_c``. An
operation names a material and a tool and sets the radial immersion, up or down milling, the
feed per tooth and the feed direction; :meth:`MachiningTable.milling_cut` and
:meth:`MachiningTable.conditions` turn it into the inputs of the lobes and of the cutting
process. Errors name the file and the key path (:mod:`pentapod_sim.schema`).
"""
from __future__ import annotations

from dataclasses import dataclass, replace
import os
from pathlib import Path

from pentapod_sim.errors import ConfigError
from pentapod_sim.machining.cutting_process import CuttingConditions
from pentapod_sim.machining.milling_cut import MILLING_MODES, MillingCut
from pentapod_sim.paths import config_dir
from pentapod_sim.schema import ANY, check_choice, internal, load, NON_NEGATIVE, POSITIVE, spec

#: Chip thickness at which the Kienzle law's specific force is given [m] (1 mm).
KIENZLE_REFERENCE_CHIP = 1e-3


@dataclass(frozen=True)
class KienzleLaw:
    """Specific cutting force ``k_c(h) = k_c1.1 (h / 1 mm)^-m_c``, linearised at h_0."""

    specific_force: float = spec('N/m^2', POSITIVE,
                                 description='k_c1.1: specific cutting force at h = 1 mm')
    exponent: float = spec('-', NON_NEGATIVE, bounds=(0.0, 1.0), closed=(True, False),
                           description='m_c: how fast k_c rises as the chip thins')
    chip_thickness: float = spec('m', POSITIVE,
                                 description='h_0: mean chip thickness of the linearisation')

    def tangent(self) -> tuple[float, float]:
        """(K_tc [N/m^2], K_te [N/m]): slope and offset of the tangent at h_0."""
        kc = self.specific_force * (self.chip_thickness / KIENZLE_REFERENCE_CHIP) ** (
            -self.exponent)
        return (1.0 - self.exponent) * kc, self.exponent * kc * self.chip_thickness


@dataclass(frozen=True)
class Material:
    """Cutting-force law of a workpiece material (exactly one of tangential or kienzle)."""

    description: str = spec(description='the material and the source of its coefficients')
    radial_ratio: float = spec('-', NON_NEGATIVE, description='K_rc / K_tc')
    tangential: float | None = spec('N/m^2', POSITIVE, default=None,
                                    description='K_tc: tangential cutting coefficient')
    kienzle: KienzleLaw | None = spec(default=None,
                                      description='Kienzle law the coefficients come from')
    edge_tangential: float | None = spec('N/m', NON_NEGATIVE, default=None,
                                         description='K_te (default 0; from kienzle if given)')
    edge_radial: float = spec('N/m', NON_NEGATIVE, default=0.0, description='K_re')

    def __post_init__(self) -> None:
        if (self.tangential is None) == (self.kienzle is None):
            raise ConfigError('give exactly one of tangential and kienzle')
        if self.kienzle is not None and self.edge_tangential is not None:
            raise ConfigError('edge_tangential follows from kienzle; leave it out')

    def coefficients(self) -> tuple[float, float, float, float]:
        """(K_tc, K_rc [N/m^2], K_te, K_re [N/m])."""
        if self.kienzle is not None:
            k_tc, k_te = self.kienzle.tangent()
        else:
            k_tc, k_te = float(self.tangential or 0.0), float(self.edge_tangential or 0.0)
        return k_tc, self.radial_ratio * k_tc, k_te, self.edge_radial


@dataclass(frozen=True)
class Tool:
    """An end mill; the helix is ignored (every tooth engages the whole depth at one angle)."""

    description: str = spec(description='what the tool is')
    teeth: int = spec('-', POSITIVE, description='number of teeth (evenly spaced)')
    diameter: float = spec('m', POSITIVE, description='cutter diameter')


@dataclass(frozen=True)
class Operation:
    """A straight milling cut with one material and one tool."""

    description: str = spec(description='what the operation is')
    material: str = spec(description='key of materials')
    tool: str = spec(description='key of tools')
    radial_immersion: float = spec('-', POSITIVE, bounds=(0.0, 1.0), closed=(False, True),
                                   description='radial depth over diameter a_e / D')
    milling: str = spec(choices=MILLING_MODES, description='up or down milling')
    feed_per_tooth: float = spec('m', POSITIVE, description='feed per tooth f_t')
    feed_angle: float = spec('rad', ANY, default=0.0,
                             description='feed direction from machine x in the x-y plane')


@dataclass(frozen=True)
class MachiningTable:
    """config/machining.yaml."""

    spindle_speeds: tuple[float, ...] = spec('rpm', POSITIVE, length=2,
                                             description='speed range of the lobe diagrams')
    materials: dict[str, Material] = spec(min_length=1, description='workpiece materials')
    tools: dict[str, Tool] = spec(min_length=1, description='end mills')
    operations: dict[str, Operation] = spec(min_length=1, description='milling cuts')
    source: str = internal()

    def __post_init__(self) -> None:
        if not self.spindle_speeds[0] < self.spindle_speeds[1]:
            raise ConfigError(f'spindle_speeds = {list(self.spindle_speeds)} rpm must increase')
        for name, op in self.operations.items():
            check_choice(op.material, list(self.materials), f'operations.{name}.material',
                         'material')
            check_choice(op.tool, list(self.tools), f'operations.{name}.tool', 'tool')

    def operation(self, name: str) -> Operation:
        """The operation ``name`` (ConfigError naming the closest one if unknown)."""
        return self.operations[check_choice(name, list(self.operations),
                                            f'{self.source}: operation', 'operation')]

    def milling_cut(self, name: str) -> MillingCut:
        """Engagement and force law of an operation for the lobes."""
        op = self.operation(name)
        k_tc, k_rc, _, _ = self.materials[op.material].coefficients()
        return MillingCut.from_immersion(self.tools[op.tool].teeth, k_tc, k_rc / k_tc,
                                         op.radial_immersion, op.milling, op.feed_angle)

    def conditions(self, name: str, spindle_speed: float,
                   axial_depth: float) -> CuttingConditions:
        """An operation at a spindle speed [rpm] and axial depth [m], for the time domain."""
        op = self.operation(name)
        _, _, k_te, k_re = self.materials[op.material].coefficients()
        return CuttingConditions(self.milling_cut(name), spindle_speed, axial_depth,
                                 op.feed_per_tooth, k_te, k_re)


def default_path() -> Path:
    """config/machining.yaml of :func:`pentapod_sim.paths.config_dir`."""
    return config_dir() / 'machining.yaml'


def load_machining(path: str | os.PathLike[str] | None = None) -> MachiningTable:
    """
    Read and validate config/machining.yaml (or ``path``).

    Raises
    ------
    ConfigError
        Naming the file, the key path and the bad value (or the closest known key).
    """
    path = Path(path) if path is not None else default_path()
    return replace(load(MachiningTable, path), source=str(path))
