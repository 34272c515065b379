"""
Multi-rate plant: N exact ZOH substeps of the plant per exchange with the force sources.

The plant integrates at its internal rate ``sample_rate * substeps`` (sample time
``dt_f = dt / N``), while outputs and forces are exchanged at ``sample_rate`` (``dt``: one
exchange = one /clock tick = one controller step). ``u_k`` is held over the N substeps of
exchange k, so with the fine ZOH matrices ``A_f``, ``B_f`` one exchange is exactly

``x_{k+1} = A_f^N x_k + (sum_{j<N} A_f^j) B_f u_k``,

the ZOH over ``N dt_f = dt``: the exchange-rate state update *is* a single-rate plant at the
exchange rate (same matrices up to rounding), so the offline loop
(:func:`pentapod_sim.sim.closed_loop.simulate`), the sampled-loop construction
(:func:`pentapod_sim.sim.controllers.loop_system`) and the analytic FRFs need no other timing.
What the substeps add are the full-rate outputs inside an exchange, at ``t_k + j dt_f``:

``y_{k,j} = C A_f^j x_k + C (sum_{i<j} A_f^i) B_f u_k + D u_k`` for ``j >= 1``, and
``y_{k,0} = y_k = C x_k + D u_{k-1}``

(the lockstep convention at the fine rate: the feed-through acts on the previous fine input).
They are precomputed as stacked matrices, so all N samples of an exchange are two small
matrix-vector products (:meth:`MultiRatePlant.fine_outputs`), computed only when someone records
or subscribes to them.

Units: SI, as the model's ports; ``dt``, ``fine_dt`` in s.
"""
from __future__ import annotations

import numbers
from typing import TYPE_CHECKING

import control
import numpy as np
import numpy.typing as npt

from pentapod_sim.errors import ConfigError
from pentapod_sim.parameters import sample_time
from pentapod_sim.sim.modal_blocks import modal_blocks
from pentapod_sim.sim.stepping import DEFAULT_MAX_STATE_NORM, DiscretePlant

if TYPE_CHECKING:
    from pentapod_sim.plant.drives import DrivenPlant
    from pentapod_sim.plant.model import PlantModel
    from pentapod_sim.sim.controllers import LoopSystem

#: Largest accepted number of substeps per exchange (the stacked output matrices grow with N).
MAX_SUBSTEPS = 1000


def check_substeps(substeps: object) -> int:
    """Return ``substeps`` as an int in [1, MAX_SUBSTEPS] (ConfigError names a bad value)."""
    if isinstance(substeps, bool) or not isinstance(substeps, numbers.Integral) \
            or not 1 <= int(substeps) <= MAX_SUBSTEPS:
        raise ConfigError(f'substeps must be an integer from 1 to {MAX_SUBSTEPS} (plant '
                          f'substeps per exchange), got {substeps!r}')
    return int(substeps)


def _times_a(a: np.ndarray, blocks: np.ndarray | None, m: np.ndarray,
             transpose: bool = False) -> np.ndarray:
    """``a @ m`` (or ``a.T @ m``), blockwise for a modal A (exact zeros stay zero)."""
    if blocks is None:
        return (a.T if transpose else a) @ m
    half = a.shape[0] // 2
    top, bottom = m[:half], m[half:]
    p = blocks.transpose(1, 0, 2) if transpose else blocks
    col = (slice(None),) + (None,) * (m.ndim - 1)
    return np.concatenate([p[0, 0][col] * top + p[0, 1][col] * bottom,
                           p[1, 0][col] * top + p[1, 1][col] * bottom])


def exchange_matrices(a_f: np.ndarray, b_f: np.ndarray, c: np.ndarray, d: np.ndarray,
                      substeps: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """
    Exchange-step and full-rate output matrices of N fine ZOH steps with u held.

    Parameters
    ----------
    a_f, b_f, c, d : ndarray
        Fine-rate discrete plant (``x+ = a_f x + b_f u``, ``y = c x + d u_prev``).
    substeps : int
        N, fine steps per exchange.

    Returns
    -------
    a_x : (n, n) ndarray
        ``A_f^N`` (modal 2x2-block layout kept exactly when ``a_f`` has it).
    b_x : (n, n_in) ndarray
        ``sum_{j<N} A_f^j B_f``.
    out_x : ((N-1) n_out, n) ndarray
        Rows of substeps j = 1..N-1: ``C A_f^j``.
    out_u : ((N-1) n_out, n_in) ndarray
        Rows of substeps j = 1..N-1: ``C sum_{i<j} A_f^i B_f + D``.
    """
    substeps = check_substeps(substeps)
    blocks = modal_blocks(a_f)
    a_x = np.eye(a_f.shape[0])
    b_x = np.zeros_like(b_f)              # sum_{i<j} A^i B, j = 0
    c_j = c                               # C A^j, j = 0
    out_x, out_u = [], []
    for j in range(1, substeps + 1):
        a_x = _times_a(a_f, blocks, a_x)
        b_x = _times_a(a_f, blocks, b_x) + b_f
        if j < substeps:
            c_j = _times_a(a_f, blocks, c_j.T, transpose=True).T
            out_x.append(c_j)
            out_u.append(c @ b_x + d)
    n, n_in = a_f.shape[0], b_f.shape[1]
    stack_x = np.vstack(out_x) if out_x else np.zeros((0, n))
    stack_u = np.vstack(out_u) if out_u else np.zeros((0, n_in))
    return a_x, b_x, np.ascontiguousarray(stack_x), np.ascontiguousarray(stack_u)


class MultiRatePlant(DiscretePlant):
    """
    A :class:`DiscretePlant` stepped at the exchange rate with N exact fine substeps inside.

    ``advance``/``outputs`` are those of :class:`DiscretePlant` on the exchange matrices
    (``dt`` = exchange sample time), so every user of the lockstep core runs it unchanged;
    :meth:`fine_outputs` gives the N full-rate outputs of the exchange being applied.

    Parameters
    ----------
    fine : control.StateSpace
        The plant discretised (ZOH) at the internal rate, ``fine.dt = dt / substeps``.
    substeps : int
        N >= 1; N = 1 is the single-rate plant, bit for bit.
    max_state_norm : float, optional
        As :class:`DiscretePlant` (checked once per exchange).

    Attributes
    ----------
    substeps : int
        N.
    fine_dt : float
        Internal sample time ``dt / N`` [s].
    """

    def __init__(self, fine: control.StateSpace, substeps: int = 1,
                 max_state_norm: float = DEFAULT_MAX_STATE_NORM,
                 state_scale: npt.ArrayLike | None = None):
        substeps = check_substeps(substeps)
        fine_plant = DiscretePlant(fine, max_state_norm, state_scale)   # checks dt, the bound
        a_x, b_x, self._out_x, self._out_u = exchange_matrices(
            fine_plant.a, fine_plant.b, fine_plant.c, fine_plant.d, substeps)
        exchange = control.ss(a_x, b_x, fine_plant.c, fine_plant.d, fine_plant.dt * substeps,
                              inputs=fine_plant.input_names, outputs=fine_plant.output_names)
        super().__init__(exchange, max_state_norm, state_scale)
        self.substeps = substeps
        self.fine_dt = fine_plant.dt

    @classmethod
    def from_model(cls, model: PlantModel | DrivenPlant, sample_rate: float, substeps: int = 1,
                   max_state_norm: float = DEFAULT_MAX_STATE_NORM) -> 'MultiRatePlant':
        """
        From a plant model, or the plant with the feed drives' rotors (exact ZOH).

        ``model`` is a :class:`pentapod_sim.plant.model.PlantModel` or a
        :class:`pentapod_sim.plant.drives.DrivenPlant`.

        ``sample_rate`` [Hz] is the exchange rate; the plant integrates at
        ``sample_rate * substeps``. The divergence guard weighs the states by the model's
        ``state_scale()`` if it has one (the drives' rotors as mass-normalised coordinates).
        """
        substeps = check_substeps(substeps)
        if not np.isfinite(sample_rate) or sample_rate <= 0:
            raise ConfigError(f'sample_rate must be > 0 Hz, got {sample_rate!r}')
        scale = getattr(model, 'state_scale', None)
        return cls(model.discretize(sample_time(sample_rate * substeps)), substeps, max_state_norm,
                   None if scale is None else scale())

    def fine_outputs(self, u: npt.NDArray[np.float64], y: npt.NDArray[np.float64],
                     out: npt.NDArray[np.float64] | None = None) -> npt.NDArray[np.float64]:
        """
        Full-rate outputs ``y_{k,j}``, j = 0..N-1, of the exchange k about to apply ``u``.

        Call between :meth:`outputs` (which gave ``y`` = y_k) and :meth:`advance` (u).

        Parameters
        ----------
        u : (n_in,) ndarray
            u_k, held over the exchange.
        y : (n_out,) ndarray
            y_k (becomes row 0, unchanged).
        out : (N, n_out) ndarray, optional
            C-contiguous float64 array to write into.

        Returns
        -------
        (N, n_out) ndarray
            Row j at time ``t_k + j fine_dt``.
        """
        if out is None:
            out = np.empty((self.substeps, len(self.output_names)))
        elif not out.flags.c_contiguous:
            raise ValueError('fine_outputs: out must be C-contiguous (rows are written in place)')
        out[0] = y
        if self.substeps > 1:
            rest = out[1:].reshape(-1)
            np.dot(self._out_x, self._x, out=rest)
            rest += self._out_u @ np.asarray(u, dtype=float)
        return out


def full_rate_loop_outputs(plant: MultiRatePlant, loop: LoopSystem
                           ) -> tuple[np.ndarray, np.ndarray]:
    """
    Full-rate outputs of the sampled loop: substeps j = 1..N-1 of exchange k.

    For a :class:`pentapod_sim.sim.controllers.LoopSystem` ``loop`` of this plant (state
    ``z_k``, external input ``e_k``, ``u_k = c_u z_k + e_k``), the stacked outputs
    ``[y_{k,1}; ...; y_{k,N-1}] = c z_k + d e_k``; ``y_{k,0}`` is the loop's own ``y_k``.

    Returns
    -------
    c : ((N-1) n_out, n_z) ndarray
    d : ((N-1) n_out, n_in) ndarray
    """
    n = plant.n_states
    pick_x = np.zeros((n, loop.a.shape[0]))
    pick_x[:, :n] = np.eye(n)
    return plant._out_x @ pick_x + plant._out_u @ loop.c_u, plant._out_u.copy()
