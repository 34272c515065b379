"""
Check models: the same FE model's modes up to a high frequency, unreduced, with the plant's ports.

A sampled loop that is stable on the reduced plant may still excite modes the reduction (or the
750 Hz modal cut) dropped. :mod:`pentapod_sim.sim.stability` therefore also closes the loop on a
*check model*: every FE mode below ``f_max`` (default 5 kHz, at least twice the sample rate),
no relevance reduction, the residual flexibility of the modes above ``f_max`` in the
feed-through ``d`` (as :func:`pentapod_sim.plant.build.plant_from_fe` does). Check models are
cached per configuration like the plants of :func:`pentapod_sim.plant.build.load_or_build_model`.
"""
from __future__ import annotations

import dataclasses
import logging
from pathlib import Path
from typing import Callable

import numpy as np
import numpy.typing as npt

from pentapod_sim.errors import ConfigError, ModelFileError
from pentapod_sim.fe.machine_data import load_machine, MachineParams
from pentapod_sim.fe.model import FEModel
from pentapod_sim.modes.frame_reduction import build_model
from pentapod_sim.plant.build import model_cache_key, plant_from_fe
from pentapod_sim.plant.config import load_reduction_config, ReductionConfig
from pentapod_sim.plant.model import PlantModel

LOG = logging.getLogger(__name__)

#: Default lowest cut-off of the check model's modes [Hz].
DEFAULT_CHECK_F_MIN = 5000.0


def check_f_max(sample_rate: float, f_min: float = DEFAULT_CHECK_F_MIN) -> float:
    """
    Cut-off of the check model's modes [Hz]: ``max(f_min, 2 * sample_rate)``.

    Parameters
    ----------
    sample_rate : float
        Sample rate of the loop [Hz], > 0.
    f_min : float
        Lowest cut-off [Hz], > 0 (default 5 kHz).
    """
    for name, value in (('sample_rate', sample_rate), ('check model f_min', f_min)):
        if not np.isfinite(value) or value <= 0:
            raise ConfigError(f'{name} must be > 0 Hz, got {value!r}')
    return float(max(f_min, 2.0 * sample_rate))


def check_model_from_fe(fe: FEModel, reduction_cfg: ReductionConfig, f_max: float,
                        progress: Callable[[str], None] | None = None) -> PlantModel:
    """
    Every mode of ``fe`` below ``f_max`` with the ports of ``reduction_cfg``, no reduction.

    Parameters
    ----------
    fe : FEModel
        The FE model (:func:`pentapod_sim.fe.assembly.build_model`).
    reduction_cfg : ReductionConfig
        As :func:`pentapod_sim.plant.build.load_reduction_config` returns; its ports and
        damping are used, ``modes_f_max`` is replaced by ``f_max``.
    f_max : float
        Cut-off [Hz].
    progress : callable, optional
        Receives one message per stage.
    """
    cfg = dataclasses.replace(reduction_cfg, modes_f_max=float(f_max))
    plant, _ = plant_from_fe(fe, cfg, progress)
    plant.meta.update(check_model=True, check_f_max_hz=float(f_max))
    return plant


def build_check_model(position: str | npt.ArrayLike, f_max: float,
                      machine: MachineParams | None = None,
                      reduction_cfg: ReductionConfig | None = None,
                      progress: Callable[[str], None] | None = None) -> PlantModel:
    """
    Check model of a machine position (name of config/positions.yaml or a 5-vector pose).

    See :func:`check_model_from_fe`; ``machine`` and ``reduction_cfg`` default to the
    package's config files.
    """
    cfg = load_reduction_config() if reduction_cfg is None else reduction_cfg
    machine = load_machine() if machine is None else machine
    model = check_model_from_fe(build_model(machine, position), cfg, f_max, progress)
    model.meta['position'] = position if isinstance(position, str) else None
    return model


def check_cache_file(position: str, f_max: float, cache_dir: str | Path) -> Path:
    """Cache file of a check model: ``check_<position>_<f_max>hz_<config key>.npz``."""
    return Path(cache_dir) / f'check_{position}_{f_max:.0f}hz_{model_cache_key(position)}.npz'


def load_or_build_check_model(position: str, f_max: float,
                              cache_dir: str | Path = 'out/models') -> tuple[PlantModel, str]:
    """
    Load the cached check model of a position, or build and cache it.

    The cache key is the plants' (:func:`pentapod_sim.plant.build.model_cache_key`: machine,
    positions and reduction config, position, package version) plus ``f_max``.

    Returns
    -------
    (PlantModel, str)
        The model and a sentence saying where it came from.
    """
    if not position:
        raise ConfigError('the check model needs a position name (none was given)')
    cached = check_cache_file(position, f_max, cache_dir)
    if cached.exists():
        try:
            return PlantModel.load(cached), f'loaded cached {cached}'
        except ModelFileError as err:
            LOG.warning('rebuilding the check model: %s', err)
    model = build_check_model(position, f_max,
                              progress=lambda msg: LOG.info('check model: %s', msg))
    model.save(cached)
    return model, f'built for {position} (modes below {f_max:g} Hz) and cached in {cached}'
