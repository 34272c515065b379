"""
The plant of each judged position, its check model, and what every plant mode is.

A position of config/positions.yaml gets the reduced plant the plant node runs (built once,
cached like every plant: :func:`pentapod_sim.plant.build.load_or_build_model`) and its check
model (every FE mode below ``max(check_f_min, 2 sample_rate)``,
:func:`pentapod_sim.plant.check_model.load_or_build_check_model`); a model file (``--model-file``,
e.g. a small demo model) runs as a position of its own, with a check model only if one is
given (``--check-model``).

**Mode numbers.** The reduced plant keeps the modes that matter at its ports, so its index of a
mode is not the FE model's (at P1 plant mode 20 is FE mode 21: FE mode 4 is dropped). Every
table of the judge names a mode by both, with its cause: the stiffness group with the largest
share of the mode's strain energy and the mode's dominant direction at the TCP
(:func:`pentapod_sim.modes.causes.analyse_causes`, without the one-elasticity-at-a-time
models), computed once per position configuration and kept next to the cached plants.
"""
from __future__ import annotations

from dataclasses import dataclass
import json
import logging
from pathlib import Path

from pentapod_sim.plant.build import load_or_build_model, model_cache_key
from pentapod_sim.plant.check_model import check_f_max, load_or_build_check_model
from pentapod_sim.plant.model import PlantModel

LOG = logging.getLogger(__name__)


@dataclass(frozen=True)
class ModeLabel:
    """A plant mode by the reduced plant's index, the FE model's number and its cause."""

    plant_mode: int                   # 1-based index in the reduced plant
    fe_mode: int                      # 1-based number among the FE model's modes
    freq_hz: float
    cause: str                        # group with the largest strain-energy share, or '-'
    tcp_direction: str                # dominant TCP component, or '-'

    def text(self) -> str:
        """``FE 21 (plant 20), struts, x``."""
        cause = '' if self.cause == '-' else f', {self.cause}'
        direction = '' if self.tcp_direction == '-' else f', {self.tcp_direction}'
        return f'FE {self.fe_mode} (plant {self.plant_mode}){cause}{direction}'


@dataclass
class PositionModel:
    """
    What the runs at one position need.

    ``check`` is None for a model file without a check model (its loop is then checked on
    the plant alone, and the report says so).
    """

    name: str
    plant: PlantModel
    model_file: Path
    check: PlantModel | None
    labels: list[ModeLabel]

    def label(self, plant_mode: int) -> ModeLabel:
        """Label of a plant mode (0-based index)."""
        return self.labels[plant_mode]


def _causes(position: str, plant: PlantModel, cache_dir: Path) -> tuple[list[str], list[str]]:
    """Cause and TCP direction of every FE mode up to the plant's cut (cached as JSON)."""
    path = cache_dir / f'mode_causes_{position}_{model_cache_key(position)}.json'
    try:
        doc = json.loads(path.read_text())
        return list(doc['cause']), list(doc['tcp_direction'])
    except (OSError, ValueError, KeyError):
        pass
    from pentapod_sim.fe.machine_data import load_machine  # FE code only when needed
    from pentapod_sim.modes.causes import analyse_causes
    from pentapod_sim.modes.frame_reduction import build_model
    from pentapod_sim.modes.solver import solve_modes
    LOG.info('mode causes of %s: FE model and modes below %g Hz', position,
             plant.meta.get('modes_f_max_hz', 750.0))
    fe = build_model(load_machine(), position)
    modes = solve_modes(fe.K, fe.M, f_max=float(plant.meta.get('modes_f_max_hz', 750.0)))
    table = analyse_causes(fe, modes, neuber=False)
    cause, direction = list(table.cause), list(table.tcp_direction)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps({'cause': cause, 'tcp_direction': direction}))
    except OSError as err:
        LOG.warning('mode causes not kept: %s', err)
    return cause, direction


def mode_labels(plant: PlantModel, position: str | None, cache_dir: Path) -> list[ModeLabel]:
    """Labels of every plant mode; a plant without an FE model behind it gets '-' causes."""
    kept = plant.meta.get('kept_modes')
    fe = [int(k) for k in kept] if kept is not None and len(kept) == plant.n_modes else \
        list(range(1, plant.n_modes + 1))
    cause = direction = ['-'] * (max(fe, default=0))
    if position is not None and kept is not None:
        cause, direction = _causes(position, plant, cache_dir)
    return [ModeLabel(i + 1, n, float(f), cause[n - 1] if n <= len(cause) else '-',
                      direction[n - 1] if n <= len(direction) else '-')
            for i, (n, f) in enumerate(zip(fe, plant.frequencies_hz))]


def position_model(position: str, sample_rate: float, check_f_min: float, cache_dir: Path,
                   model_file: str | None = None, check_file: str | None = None,
                   with_check: bool = True) -> PositionModel:
    """
    The plant, check model and mode labels of a position name or of a model file.

    ``with_check`` False skips the check model (no loop check asked for).
    """
    if model_file:
        plant, _ = load_or_build_model(model_file=model_file)
        check = PlantModel.load(check_file) if (check_file and with_check) else None
        name = Path(model_file).stem
        return PositionModel(name, plant, Path(model_file), check,
                             mode_labels(plant, None, cache_dir))
    plant, origin = load_or_build_model(position=position, cache_dir=cache_dir)
    LOG.info('plant of %s: %s', position, origin)
    path = cache_dir / f'plant_{position}_{model_cache_key(position)}.npz'
    check = None
    if with_check:
        check, origin = load_or_build_check_model(
            position, check_f_max(sample_rate, check_f_min), cache_dir)
        LOG.info('check model of %s: %s', position, origin)
    return PositionModel(position, plant, path, check, mode_labels(plant, position, cache_dir))
