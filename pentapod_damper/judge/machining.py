"""
The machining verdict: the minimum stable depth of cut from the measured TCP FRF matrix.

The multisine runs along x and y each give one column of the 2x2 TCP FRF matrix in the
cutting plane (displacement x and y per force along the excited direction). The lines of a
multisine (1 / period apart) do not resolve a lightly damped resonance, and the stable depth
follows the most negative real part of the oriented FRF at it, so the matrix is taken from the
identified modal models of the two runs (:mod:`pentapod_damper.judge.measure`), evaluated on
a grid that is dense across every identified resonance
(:func:`pentapod_sim.machining.tcp_frf.resonance_grid`). The zero-order milling solution of
:mod:`pentapod_sim.machining.lobes` (the one ``analyze lobes`` uses) gives the limiting depth;
its minimum over all spindle speeds is the verdict's figure. The lines themselves give it too
(``analyze lobes`` on the two bags), flagged unresolved where they are too coarse.

The analytic reference is the same computation on the sampled closed loop of the plant with the
controller's published model (the open loop for the baseline).
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

from pentapod_damper.judge.measure import ModelLaw, MultisineRun
from pentapod_damper.study.analytic import SampledPairFrf
from pentapod_sim.cli.analyze_lobes import scenario_frf
from pentapod_sim.machining.lobes import milling_limit, Minimum, StabilityLimit
from pentapod_sim.machining.materials import load_machining
from pentapod_sim.machining.milling_cut import MillingCut
from pentapod_sim.machining.tcp_frf import AXES, resonance_grid, TcpFrf
from pentapod_sim.plant.model import PlantModel
from pentapod_sim.sim.controllers import DiscreteController


@dataclass(frozen=True)
class StableDepth:
    """Minimum stable depth [m] of one controller, identified, on the lines, and analytic."""

    identified: Minimum
    lines: Minimum
    analytic: Minimum | None
    limit: StabilityLimit              # the identified one, for the lobe diagram


def milling_cut(operation: str) -> MillingCut:
    """The operation of config/machining.yaml (ConfigError names an unknown one)."""
    return load_machining().milling_cut(operation)


def identified_matrix(runs: Mapping[str, MultisineRun], band: Sequence[float],
                      label: str) -> TcpFrf:
    """The 2x2 TCP FRF from the identified models of the x and y runs."""
    poles = np.concatenate([runs[a].model.poles for a in AXES])
    grid = resonance_grid(poles, float(band[0]), float(band[1]))
    matrix = np.array([[runs[j].synthesise(grid, i) for j in AXES] for i in AXES])
    return TcpFrf(grid, matrix, label)


def analytic_matrix(plant: PlantModel, models: Sequence[DiscreteController], dt: float,
                    band: Sequence[float], label: str) -> TcpFrf:
    """The 2x2 TCP FRF of the sampled loop with the controllers' models."""
    laws: list[Any] = [ModelLaw(m) for m in models]
    pairs = {(i, j): SampledPairFrf(plant, laws, dt, f'tcp_displacement_{i}',
                                    f'tcp_force_{j}') for i in AXES for j in AXES}
    grid = resonance_grid(pairs[('x', 'x')].poles, float(band[0]), float(band[1]))
    return TcpFrf(grid, np.array([[pairs[(i, j)](grid) for j in AXES] for i in AXES]), label)


def stable_depth(runs: Mapping[str, MultisineRun], bags: Mapping[str, Path], cut: MillingCut,
                 band: Sequence[float], label: str,
                 analytic: TcpFrf | None) -> StableDepth:
    """The minimum stable depth of one controller (module docstring)."""
    limit = milling_limit(identified_matrix(runs, band, label), cut)
    lines_frf: TcpFrf = scenario_frf(f'{bags["x"]},{bags["y"]}')
    lines = milling_limit(lines_frf, cut).minimum()
    return StableDepth(limit.minimum(), lines,
                       None if analytic is None else milling_limit(analytic, cut).minimum(),
                       limit)


def depth_mm(value: Minimum | None) -> float:
    """Depth [mm] of a minimum (NaN for none)."""
    return float('nan') if value is None else 1e3 * value.depth

