"""The per-step record of a plant run (y_k, u_k), written to an .npz file at the end."""
from __future__ import annotations

from typing import Any

import numpy as np

from pentapod_sim.sim.stepping import DiscretePlant, ForceMixer


class Trace:
    """
    Per-step record of y_k and u_k of a plant run (optional: disabled keeps nothing).

    A multi-rate plant (``core.substeps`` N > 1) also keeps its N full-rate outputs per
    exchange (:meth:`pentapod_sim.sim.multirate.MultiRatePlant.fine_outputs`), saved as
    ``y_full`` (row ``k N + j`` at ``t_k + j fine_dt``).

    Parameters
    ----------
    n_steps : int
        Steps (exchanges) planned.
    core : DiscretePlant
        The plant (port names and counts, substeps).
    enabled : bool
        False: record nothing.

    Attributes
    ----------
    full : (n_steps, N, n_out) ndarray or None
        Full-rate outputs per exchange, or None (disabled or N = 1): the plant node fills
        :meth:`fine_rows` through ``fine_outputs`` before it advances.
    """

    def __init__(self, n_steps: int, core: DiscretePlant, enabled: bool):
        self.enabled = enabled
        shape = (n_steps if enabled else 0)
        self.y = np.zeros((shape, len(core.output_names)))
        self.u = np.zeros((shape, len(core.input_names)))
        substeps = getattr(core, 'substeps', 1)
        self.full = (np.zeros((shape, substeps, len(core.output_names)))
                     if enabled and substeps > 1 else None)

    def record(self, k: int, y: np.ndarray, u: np.ndarray) -> None:
        """Store step k."""
        if self.enabled:
            self.y[k], self.u[k] = y, u

    def fine_rows(self, k: int) -> np.ndarray | None:
        """The full-rate rows of exchange k to fill (N, n_out), or None if none are kept."""
        return None if self.full is None else self.full[k]

    def buffers(self) -> list[np.ndarray | None]:
        """The arrays written step by step (a paced run writes every page before step 0)."""
        return [self.y, self.u, self.full]

    def save(self, path: str, core: DiscretePlant, mixer: ForceMixer, n_planned: int,
             extra: dict[str, Any]) -> None:
        """
        Write the steps run: y, u, dt, port names, reject counts and ``extra``.

        ``steps_run`` is the number of steps actually run (the rows of y and u),
        ``steps_planned`` the configured number; ``extra`` holds e.g. timing figures and
        ``end``, how the run ended ('finished', 'stopped by SIGINT', 'error: ...').
        ``substeps`` and ``fine_dt`` [s] are those of the plant; ``y_full`` is saved for N > 1.
        """
        rejected = [f'{s}/{r}={c}' for (s, r), c in mixer.rejected.items()]
        n = core.k
        if self.full is not None:
            extra = dict(extra, y_full=self.full[:n].reshape(-1, self.full.shape[2]))
        np.savez(path, y=self.y[:n], u=self.u[:n], dt=core.dt, x_final=core.x, steps_run=n,
                 steps_planned=n_planned, output_names=np.array(core.output_names),
                 input_names=np.array(core.input_names),
                 rejected=np.array(rejected, dtype=str),
                 substeps=getattr(core, 'substeps', 1),
                 fine_dt=getattr(core, 'fine_dt', core.dt), **extra)
