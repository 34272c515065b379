"""
Check models: the same FE model's modes up to a high frequency, unreduced, with the plant's ports.

A sampled loop that is stable on the reduced plant may still excite modes the reduction (or the
750 Hz modal cut) dropped. :mod:`pentapod_sim.sim.stability` therefore also closes the loop on a
*check model*: every FE mode below ``f_max`` (default 5 kHz, at least twice the sample rate),
no relevance reduction, the residual flexibility of the modes above ``f_max`` in the
feed-through ``d`` (as :func:`pentapod_sim.plant.build.plant_from_fe` does). Check models are
cached per configuration like the plants of :func:`pentapod_sim.plant.build.load_or_build_model`.

The work before a run's step 0 is bounded (docs/statespace.md, "The plant node checks its loop
at start-up"): a cut-off above :data:`MAX_CHECK_F_MAX` (e.g. ``sample_rate`` 1 MHz asks for the
modes below 2 MHz) or more than :data:`MAX_CHECK_MODES` modes below it (counted by a Sturm
sequence, one sparse factorisation, before any mode is solved) is refused with a one-line
ConfigError naming the value. Building reports progress at most once a second and stops at the
next spectrum slice once ``stop()`` is true (:class:`CheckStopped`).
"""
from __future__ import annotations

import dataclasses
import logging
from pathlib import Path
import time
from typing import Callable

import numpy as np
import numpy.typing as npt

from pentapod_sim.errors import ConfigError, ModelFileError
from pentapod_sim.fe.machine_data import load_machine, MachineParams
from pentapod_sim.fe.model import FEModel
from pentapod_sim.modes.frame_reduction import build_model
from pentapod_sim.modes.slicing import Progress
from pentapod_sim.modes.sturm import sturm_count
from pentapod_sim.plant.build import model_cache_key, plant_from_fe
from pentapod_sim.plant.check_band import check_f_max as check_f_max
from pentapod_sim.plant.check_band import DEFAULT_CHECK_F_MIN as DEFAULT_CHECK_F_MIN
from pentapod_sim.plant.check_band import MAX_CHECK_F_MAX as MAX_CHECK_F_MAX
from pentapod_sim.plant.check_band import RULE
from pentapod_sim.plant.config import load_reduction_config, ReductionConfig
from pentapod_sim.plant.model import PlantModel

LOG = logging.getLogger(__name__)

#: Most modes of a check model: the loop's eigenvalue problem then has about 4000 states
#: (the 1425 modes below 10 kHz of the default mesh take about 3 s to build and 7 s to solve
#: on the 2-core development machine; solving grows with the cube of the states).
MAX_CHECK_MODES = 2000
#: Least wall time [s] between two progress messages of a build.
PROGRESS_PERIOD = 1.0


class CheckStopped(Exception):
    """A stop was requested while a check model was built (nothing is cached)."""


def check_mode_count(fe: FEModel, f_max: float) -> int:
    """
    Modes of ``fe`` below ``f_max`` (Sturm count), refused above :data:`MAX_CHECK_MODES`.

    Raises
    ------
    ConfigError
        One line naming the count and ``f_max``.
    """
    count = sturm_count(fe.K, fe.M, (2.0 * np.pi * f_max) ** 2)
    if count > MAX_CHECK_MODES:
        raise ConfigError(f'truncation check: the FE model has {count} modes below {f_max:g} Hz '
                          f'({RULE}), more than the bound of {MAX_CHECK_MODES} modes of a check '
                          'model (docs/statespace.md); lower the sample rate or check f_min, or '
                          'switch the check off (plant parameter loop_check: off)')
    return count


def _slice_progress(f_max: float, count: int, progress: Callable[[str], None] | None,
                    stop: Callable[[], bool] | None) -> Progress:
    """Progress callback of the mode solver: stop when asked, report once a second."""
    last = [time.monotonic()]

    def report(found: int, wanted: int | None, message: str) -> None:
        if stop is not None and stop():
            raise CheckStopped(f'stopped while solving the check modes below {f_max:g} Hz')
        now = time.monotonic()
        if progress is not None and now - last[0] >= PROGRESS_PERIOD:
            progress(f'{found} of {count} modes below {f_max:g} Hz solved')
            last[0] = now
    return report


def check_model_from_fe(fe: FEModel, reduction_cfg: ReductionConfig, f_max: float,
                        progress: Callable[[str], None] | None = None,
                        stop: Callable[[], bool] | None = None) -> PlantModel:
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
        Receives one message per stage, and the modes solved at most once a second.
    stop : callable, optional
        Polled after each spectrum slice; true raises :class:`CheckStopped`.

    Raises
    ------
    ConfigError
        More than :data:`MAX_CHECK_MODES` modes below ``f_max`` (:func:`check_mode_count`).
    """
    count = check_mode_count(fe, f_max)
    cfg = dataclasses.replace(reduction_cfg, modes_f_max=float(f_max))
    plant, _ = plant_from_fe(fe, cfg, progress,
                             modes_progress=_slice_progress(f_max, count, progress, stop))
    plant.meta.update(check_model=True, check_f_max_hz=float(f_max))
    return plant


def build_check_model(position: str | npt.ArrayLike, f_max: float,
                      machine: MachineParams | None = None,
                      reduction_cfg: ReductionConfig | None = None,
                      progress: Callable[[str], None] | None = None,
                      stop: Callable[[], bool] | None = None) -> PlantModel:
    """
    Check model of a machine position (name of config/positions.yaml or a 5-vector pose).

    See :func:`check_model_from_fe`; ``machine`` and ``reduction_cfg`` default to the
    package's config files.
    """
    cfg = load_reduction_config() if reduction_cfg is None else reduction_cfg
    machine = load_machine() if machine is None else machine
    model = check_model_from_fe(build_model(machine, position), cfg, f_max, progress, stop)
    model.meta['position'] = position if isinstance(position, str) else None
    return model


def check_cache_file(position: str, f_max: float, cache_dir: str | Path) -> Path:
    """Cache file of a check model: ``check_<position>_<f_max>hz_<config key>.npz``."""
    return Path(cache_dir) / f'check_{position}_{f_max:.0f}hz_{model_cache_key(position)}.npz'


def load_or_build_check_model(position: str, f_max: float, cache_dir: str | Path = 'out/models',
                              stop: Callable[[], bool] | None = None
                              ) -> tuple[PlantModel, str]:
    """
    Load the cached check model of a position, or build and cache it.

    The cache key is the plants' (:func:`pentapod_sim.plant.build.model_cache_key`: machine,
    positions and reduction config, position, package version) plus ``f_max``. ``stop`` as
    :func:`check_model_from_fe` (:class:`CheckStopped`: nothing cached).

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
                              progress=lambda msg: LOG.info('check model: %s', msg), stop=stop)
    model.save(cached)
    return model, f'built for {position} (modes below {f_max:g} Hz) and cached in {cached}'
