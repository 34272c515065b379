"""
White-noise disturbance on chosen plant input ports: independent excitation of every port.

Identifying a controller in the loop (its FRF from the plant outputs it reads to the efforts it
answers) needs as many independent excitations as the controller reads sensors
(:mod:`pentapod_sim.analysis.frf.mimo`). :class:`PortNoise` gives one: a zero-mean Gaussian
force (or moment) of RMS ``rms`` on each of its ports, independent between ports and white up
to the Nyquist frequency, held over each step like every force of the lockstep plant. The
value of step k is fixed by ``seed`` and k alone (blocks of :data:`BLOCK` steps, each drawn
from its own seeded generator), so a node that answers the steps in any order, again after a
re-sent step, or the offline loop (:func:`pentapod_sim.sim.closed_loop.simulate`, through
:meth:`PortNoise.step`) applies the same forces.

Units: N on force ports, N m on moment ports (the ports' own units).
"""
from __future__ import annotations

from typing import Sequence

import numpy as np
import numpy.typing as npt

from pentapod_sim.errors import ConfigError

#: Steps drawn at once from one generator (seeded with ``(seed, block)``).
BLOCK = 4096


class PortNoise:
    """
    Seeded white noise on ``ports`` (a force source with no sensors).

    Parameters
    ----------
    ports : sequence of str
        Plant input ports, each driven by its own independent noise.
    rms : float
        RMS of each port's signal [N or N m], >= 0.
    seed : int
        Random seed (>= 0).
    """

    def __init__(self, ports: Sequence[str], rms: float, seed: int = 0) -> None:
        if not ports:
            raise ConfigError('the disturbance needs at least one input port (ports)')
        if len(set(ports)) != len(ports):
            raise ConfigError(f'the disturbance ports repeat a port: {list(ports)}')
        if not (np.isfinite(rms) and rms >= 0):
            raise ConfigError(f'disturbance RMS = {rms!r}: must be a finite number >= 0')
        self.sensor_ports: list[str] = []
        self.actuator_ports = list(ports)
        self.rms = float(rms)
        self.seed = int(seed)
        self._block = -1
        self._values = np.zeros((0, len(ports)))
        self._k = 0

    def force(self, k: int) -> npt.NDArray[np.float64]:
        """Efforts of step ``k`` (>= 0) on the ports [N or N m]."""
        if k < 0:
            raise ConfigError(f'step {k} < 0 has no disturbance value')
        block, row = divmod(int(k), BLOCK)
        if block != self._block:
            rng = np.random.default_rng([self.seed, block])
            self._values = self.rms * rng.standard_normal((BLOCK, len(self.actuator_ports)))
            self._block = block
        return self._values[row].copy()

    def step(self, sensors: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        """The next step's efforts (offline closed loop: steps 0, 1, 2, ...)."""
        value = self.force(self._k)
        self._k += 1
        return value

    def reset(self) -> None:
        """Back to step 0."""
        self._k = 0
