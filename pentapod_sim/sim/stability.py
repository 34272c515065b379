"""
Truncation check of sampled closed loops: stability on the plant and on a check model.

The testbed runs plain sampled feedback: the plant is held over a step (zero-order hold) and
every law answers ``u_k`` to the outputs ``y_k = C x_k + D u_{k-1}`` of the same step
(:mod:`pentapod_sim.sim.stepping`). Whether that loop is stable depends on modes the plant
model dropped, so :func:`check_loop` computes the spectral radius of the loop twice: on the
plant and on a *check model* with every FE mode up to a high frequency
(:mod:`pentapod_sim.plant.check_model`). The verdict is

* ``stable``: both loops are asymptotically stable (spectral radius < 1);
* ``unstable``: the loop on the plant is unstable;
* ``stable only thanks to truncation``: the plant's loop is stable, the check model's is not;
  the controller would excite modes the plant model left out;
* ``stable on the plant (no check model)``: a plant without an FE model behind it (modal data,
  synthetic models) can only be checked on itself.

A policy decides what a non-stable verdict does: ``refuse`` raises :class:`UnstableLoopError`
(a :class:`pentapod_sim.errors.ConfigError`), ``warn`` logs a loud warning.

Controllers are discrete state spaces on named ports (:class:`DiscreteController`), so laws
with internal dynamics (filters, actuator models, delays) plug in the same way as static gains:
a law offers either ``discrete_model()`` returning a :class:`DiscreteController` at its sample
time, or ``linear_gain()`` (memoryless ``u = K y``); see :func:`controller_of`.

Units: as the plant ports (N, N m in; m, m/s, rad, rad/s out); sample time dt [s].
"""
from __future__ import annotations

from dataclasses import dataclass
import logging
import threading
import time
from typing import Any, Callable, Sequence

import numpy as np

from pentapod_sim.errors import ConfigError
from pentapod_sim.parameters import sample_time
from pentapod_sim.plant.check_model import (
    check_f_max,
    DEFAULT_CHECK_F_MIN,
    load_or_build_check_model,
)
from pentapod_sim.plant.drives import DrivenPlant, DriveSet, with_drives
from pentapod_sim.plant.model import PlantModel
from pentapod_sim.sim.controllers import (  # noqa: F401 (re-exported)
    controller_of,
    DiscreteController,
    loop_matrix,
)

LOG = logging.getLogger(__name__)

STABLE = 'stable'
UNSTABLE = 'unstable'
TRUNCATION = 'stable only thanks to truncation'
UNCHECKED = 'stable on the plant (no check model)'
#: Wall time [s] after which a long eigenvalue problem reports, and then between reports.
PROGRESS_FIRST, PROGRESS_PERIOD = 1.0, 5.0
#: What a verdict other than ``stable`` does.
POLICIES = ('refuse', 'warn')
DEFAULT_POLICY = 'refuse'


class UnstableLoopError(ConfigError):
    """A sampled loop is unstable on the plant or on the check model (policy ``refuse``)."""


def _eigenvalues(matrix: np.ndarray, progress: Callable[[str], None] | None) -> np.ndarray:
    """``np.linalg.eigvals``; with ``progress``, told the elapsed time past a second."""
    if progress is None:
        return np.linalg.eigvals(matrix)
    out: dict[str, Any] = {}

    def solve() -> None:
        try:
            out['value'] = np.linalg.eigvals(matrix)
        except BaseException as err:        # handed to the caller
            out['error'] = err
    worker = threading.Thread(target=solve, name='loop eigenvalues', daemon=True)
    start = time.monotonic()
    worker.start()
    worker.join(PROGRESS_FIRST)
    while worker.is_alive():
        progress(f'eigenvalues of the sampled loop ({matrix.shape[0]} states): '
                 f'{time.monotonic() - start:.0f} s so far')
        worker.join(PROGRESS_PERIOD)
    if 'error' in out:
        raise out['error']
    return out['value']


def spectral_radius(matrix: np.ndarray, dt: float,
                    progress: Callable[[str], None] | None = None) -> tuple[float, float]:
    """
    Largest |eigenvalue| of a discrete state matrix and the frequency of that eigenvalue.

    ``progress`` (optional) is told the elapsed time of an eigenvalue problem that takes longer
    than a second, every few seconds.

    Returns
    -------
    radius : float
        max |lambda| (>= 1: not asymptotically stable).
    freq_hz : float
        ``|arg lambda| / (2 pi dt)`` of the largest eigenvalue [Hz] (0 to Nyquist).
    """
    if matrix.size == 0:
        return 0.0, 0.0
    # numpy's eigvals, not scipy's: it releases the GIL during LAPACK (scipy's held it for the
    # whole 1.3 s of a 1500 x 1500 matrix here), so a plant node's main thread notices a stop
    # signal while the seconds of a check model's loop are solved (shutdown.unless_requested)
    lam = _eigenvalues(matrix, progress)
    top = lam[np.argmax(np.abs(lam))]
    return float(abs(top)), float(abs(np.angle(top)) / (2 * np.pi * dt))


def plant_radius(plant: PlantModel | DrivenPlant, controllers: Sequence[DiscreteController],
                 dt: float, progress: Callable[[str], None] | None = None
                 ) -> tuple[float, float]:
    """Spectral radius (and its frequency [Hz]) of the sampled loop of a plant."""
    if not controllers and isinstance(plant, DrivenPlant):     # free rotors: radius 1
        return spectral_radius(plant.discrete_matrices(dt)[0], dt, progress)
    if not controllers and isinstance(plant, PlantModel):   # open loop: the 2x2 ZOH blocks
        if plant.n_modes == 0:
            return 0.0, 0.0
        lam = np.linalg.eigvals(plant.zoh_blocks(dt)[0]).ravel()
        top = lam[np.argmax(np.abs(lam))]
        return float(abs(top)), float(abs(np.angle(top)) / (2 * np.pi * dt))
    a, b, c, d = plant.discrete_matrices(dt)
    return spectral_radius(loop_matrix(a, b, c, d, plant.input_names, plant.output_names,
                                       controllers), dt, progress)


@dataclass(frozen=True)
class LoopCheck:
    """
    Result of :func:`check_loop`.

    Attributes
    ----------
    label : str
        What was checked (e.g. scenario and position).
    dt : float
        Sample time [s].
    plant_radius, check_radius : float
        Spectral radius of the sampled loop on the plant and on the check model.
    plant_critical_hz, check_critical_hz : float
        Frequency of the largest eigenvalue [Hz].
    plant_modes, check_modes : int
        Modes of the plant and of the check model.
    check_f_max : float
        Cut-off of the check model's modes [Hz].
    """

    label: str
    dt: float
    plant_radius: float
    check_radius: float
    plant_critical_hz: float
    check_critical_hz: float
    plant_modes: int
    check_modes: int
    check_f_max: float

    @property
    def plant_margin(self) -> float:
        """1 - spectral radius on the plant (> 0: stable)."""
        return 1.0 - self.plant_radius

    @property
    def check_margin(self) -> float:
        """1 - spectral radius on the check model (> 0: stable)."""
        return 1.0 - self.check_radius

    @property
    def verdict(self) -> str:
        """``stable``, ``unstable``, ``stable only thanks to truncation`` or unchecked."""
        if not self.plant_radius < 1.0:
            return UNSTABLE
        if self.check_modes == 0:
            return UNCHECKED
        return STABLE if self.check_radius < 1.0 else TRUNCATION

    def summary(self) -> str:
        """One sentence with both margins and the verdict."""
        if self.check_modes == 0:
            return (f'{self.label}: sampled loop at {1 / self.dt:g} Hz is {self.verdict}; '
                    f'spectral radius {self.plant_radius:.6g} ({self.plant_modes} modes, '
                    f'margin {self.plant_margin:.3g})')
        return (f'{self.label}: sampled loop at {1 / self.dt:g} Hz is {self.verdict}; '
                f'spectral radius {self.plant_radius:.6g} on the plant ({self.plant_modes} '
                f'modes, margin {self.plant_margin:.3g}), {self.check_radius:.6g} on the check '
                f'model ({self.check_modes} modes below {self.check_f_max:g} Hz, margin '
                f'{self.check_margin:.3g}, largest eigenvalue at {self.check_critical_hz:.0f} Hz)')

    def as_row(self) -> dict[str, float | str]:
        """Plain values for tables."""
        return {'sample_rate_hz': 1 / self.dt, 'plant_modes': self.plant_modes,
                'plant_radius': self.plant_radius, 'plant_margin': self.plant_margin,
                'plant_critical_hz': self.plant_critical_hz, 'check_modes': self.check_modes,
                'check_f_max_hz': self.check_f_max, 'check_radius': self.check_radius,
                'check_margin': self.check_margin, 'check_critical_hz': self.check_critical_hz,
                'verdict': self.verdict}


def apply_policy(check: LoopCheck, policy: str = DEFAULT_POLICY) -> LoopCheck:
    """
    Refuse (raise) or warn loudly when ``check`` is not ``stable``; return it otherwise.

    Raises
    ------
    UnstableLoopError
        With policy ``refuse`` and a verdict other than ``stable``.
    """
    if policy not in POLICIES:
        raise ConfigError(f'truncation check policy must be one of {", ".join(POLICIES)}, '
                          f'got {policy!r}')
    if check.verdict in (STABLE, UNCHECKED):
        return check
    advice = ('lower the gains, raise the sample rate or give the law actuator/sensor '
              'dynamics that roll off')
    if policy == 'refuse':
        raise UnstableLoopError(f'{check.summary()}; {advice}')
    LOG.warning('!!! %s -- results of this loop are not trustworthy; %s', check.summary(),
                advice)
    return check


def check_loop(plant: PlantModel, check_plant: PlantModel | None,
               controllers: Sequence[DiscreteController], dt: float,
               policy: str = DEFAULT_POLICY, label: str = 'loop',
               progress: Callable[[str], None] | None = None,
               drives: DriveSet | None = None) -> LoopCheck:
    """
    Spectral radius of the sampled loop on the plant and on the check model; apply a policy.

    Parameters
    ----------
    plant : PlantModel
        The (reduced) plant the loop runs on.
    check_plant : PlantModel or None
        The check model (:mod:`pentapod_sim.plant.check_model`); restricted to the plant's
        ports here. None for a plant without an FE model: checked on itself only.
    controllers : sequence of DiscreteController
        The laws (:func:`controller_of`); empty for the open loop.
    dt : float
        Sample time [s].
    policy : str
        ``refuse`` or ``warn`` (:func:`apply_policy`).
    label : str
        Names the loop in messages.
    progress : callable, optional
        Told the elapsed time of an eigenvalue problem that takes more than a second.
    drives : DriveSet, optional
        The feed drives the plant runs with: plant and check model are both checked with
        their rotors (:class:`pentapod_sim.plant.drives.DrivenPlant`, exact ZOH at ``dt``),
        the controllers may use the motor ports.
    """
    if not np.isfinite(dt) or dt <= 0:
        raise ConfigError(f'sample time dt must be > 0 s, got {dt!r}')
    rho_p, f_p = plant_radius(with_drives(plant, drives), controllers, dt, progress)
    if check_plant is None:
        result = LoopCheck(label, float(dt), rho_p, float('nan'), f_p, float('nan'),
                           plant.n_modes, 0, float('nan'))
        return apply_policy(result, policy)
    check_plant = check_plant.select(plant.input_names, plant.output_names)
    rho_c, f_c = plant_radius(with_drives(check_plant, drives), controllers, dt,
                              progress)
    f_max = float(check_plant.meta.get('check_f_max_hz', check_plant.frequencies_hz.max(
        initial=0.0)))
    result = LoopCheck(label, float(dt), rho_p, rho_c, f_p, f_c, plant.n_modes,
                       check_plant.n_modes, f_max)
    return apply_policy(result, policy)


def startup_check(plant: PlantModel, controllers: Sequence[DiscreteController],
                  sample_rate: float, position: str = '', policy: str = DEFAULT_POLICY,
                  check_f_min: float = DEFAULT_CHECK_F_MIN,
                  cache_dir: str = 'out/models') -> LoopCheck:
    """
    The truncation check a plant node runs before step 0.

    Parameters
    ----------
    plant : PlantModel
        The node's model.
    controllers : sequence of DiscreteController
        Linear models of the laws its force sources run (e.g. sent as
        :meth:`DiscreteController.to_json` text).
    sample_rate : float
        Plant sample rate [Hz].
    position : str
        Position name for the check model; default ``plant.meta['position']``.
    policy, check_f_min, cache_dir
        As :func:`check_loop`, :func:`pentapod_sim.plant.check_model.check_f_max` and
        :func:`pentapod_sim.plant.check_model.load_or_build_check_model`.
    """
    position = position or plant.meta.get('position') or ''
    f_max = check_f_max(sample_rate, check_f_min)
    check_plant, origin = load_or_build_check_model(position, f_max, cache_dir)
    LOG.info('check model %s: %d modes', origin, check_plant.n_modes)
    return check_loop(plant, check_plant, controllers, sample_time(sample_rate), policy,
                      label=f'plant at {position}',
                      progress=lambda msg: LOG.info('truncation check: %s', msg))
