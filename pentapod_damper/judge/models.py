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
share of the mode's strain energy, as the built plant records it
(:meth:`pentapod_sim.plant.model.PlantModel.fe_mode`), and the mode's dominant translation at
the TCP (the largest of its TCP displacement components in the plant).
"""
from __future__ import annotations

from dataclasses import dataclass
import logging
from pathlib import Path

import numpy as np

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


def mode_labels(plant: PlantModel) -> list[ModeLabel]:
    """Labels of every plant mode (a plant without FE records: its own numbers, no cause)."""
    axes = [a for a in 'xyz' if f'tcp_displacement_{a}' in plant.output_names]
    rows = [plant.output_names.index(f'tcp_displacement_{a}') for a in axes]
    labels = []
    for i, freq in enumerate(plant.frequencies_hz):
        fe_mode, cause = plant.fe_mode(i + 1)
        shape = np.abs(plant.c_disp[rows, i]) if rows else np.zeros(0)
        direction = axes[int(np.argmax(shape))] if shape.size and shape.max() > 0 else '-'
        labels.append(ModeLabel(i + 1, fe_mode, float(freq), cause or '-', direction))
    return labels


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
                             mode_labels(plant))
    plant, origin = load_or_build_model(position=position, cache_dir=cache_dir)
    LOG.info('plant of %s: %s', position, origin)
    path = cache_dir / f'plant_{position}_{model_cache_key(position)}.npz'
    check = None
    if with_check:
        check, origin = load_or_build_check_model(
            position, check_f_max(sample_rate, check_f_min), cache_dir)
        LOG.info('check model of %s: %s', position, origin)
    return PositionModel(position, plant, path, check, mode_labels(plant))
