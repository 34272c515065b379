"""The per-step record of a plant run (y_k, u_k), written to an .npz file at the end."""
from __future__ import annotations

import numpy as np

from pentapod_sim.sim.stepping import DiscretePlant, ForceMixer


class Trace:
    """
    Per-step record of y_k and u_k of a plant run (optional: disabled keeps nothing).

    Parameters
    ----------
    n_steps : int
        Steps planned.
    core : DiscretePlant
        The plant (port names and counts).
    enabled : bool
        False: record nothing.
    """

    def __init__(self, n_steps: int, core: DiscretePlant, enabled: bool):
        self.enabled = enabled
        shape = (n_steps if enabled else 0)
        self.y = np.zeros((shape, len(core.output_names)))
        self.u = np.zeros((shape, len(core.input_names)))

    def record(self, k: int, y: np.ndarray, u: np.ndarray) -> None:
        """Store step k."""
        if self.enabled:
            self.y[k], self.u[k] = y, u

    def save(self, path: str, core: DiscretePlant, mixer: ForceMixer, n_planned: int,
             extra: dict) -> None:
        """
        Write the steps run: y, u, dt, port names, reject counts and ``extra``.

        ``steps_run`` is the number of steps actually run (the rows of y and u),
        ``steps_planned`` the configured number; ``extra`` holds e.g. timing figures and
        ``end``, how the run ended ('finished', 'stopped by SIGINT', 'error: ...').
        """
        rejected = [f'{s}/{r}={c}' for (s, r), c in mixer.rejected.items()]
        n = core.k
        np.savez(path, y=self.y[:n], u=self.u[:n], dt=core.dt, x_final=core.x, steps_run=n,
                 steps_planned=n_planned, output_names=np.array(core.output_names),
                 input_names=np.array(core.input_names),
                 rejected=np.array(rejected, dtype=str), **extra)
