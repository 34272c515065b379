"""
Periodic steady state of a sampled loop under a periodic input: where to start a run.

A stable linear loop ``z_{k+1} = A z_k + B e_k`` driven by an input of period N samples has one
periodic solution, ``z_0 = A^N z_0 + z_N(rest)``, with ``z_N(rest)`` the state after one period
from rest: ``z_0 = (I - A^N)^-1 z_N(rest)``. A run started there holds no transient, so a
0.1 %-damped mode needs no settling time (decades of its decay time) before its lines can be
read: every period of the run is already the periodic response. The loop is
:func:`pentapod_sim.sim.controllers.loop_system` (plant in the lockstep convention and the
laws' linear models); the plant's part of ``z_0`` is in the basis the plant steps in
(:class:`pentapod_sim.sim.stepping.DiscretePlant`), with the plant input of the step before
step 0, ``u_{-1}``, which feeds through ``D`` into ``y_0``.

Units: SI, as the plant's ports (input N or N m, state as the plant's modal states).
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np
import numpy.typing as npt

from pentapod_sim.errors import ConfigError
from pentapod_sim.sim.controllers import DiscreteController, loop_system, LoopSystem
from pentapod_sim.sim.stepping import DiscretePlant

#: Keys of an initial-state file (.npz): the plant state x_0 and the input of step -1.
STATE_KEY, INPUT_KEY = 'x', 'u_previous'


@dataclass(frozen=True)
class PeriodicState:
    """
    The periodic steady state at step 0.

    Attributes
    ----------
    loop_state : (n_z,) ndarray
        State of the whole loop ``[x; xc; (u_{k-1})]`` (:class:`LoopSystem`).
    plant_state : (n_x,) ndarray
        The plant's part ``x_0`` (its stepping basis).
    u_previous : (n_in,) ndarray
        Total plant input of step -1 (external plus the laws'), i.e. of the period's last step.
    closure : float
        ``|z_N - z_0| / |z_0|`` after one period stepped from ``z_0``: rounding, unless the
        loop is nearly undamped over a period (then ``I - A^N`` is nearly singular).
    """

    loop_state: npt.NDArray[np.float64]
    plant_state: npt.NDArray[np.float64]
    u_previous: npt.NDArray[np.float64]
    closure: float


def _step_period(loop: LoopSystem, z0: npt.NDArray[np.float64],
                 excitation: npt.NDArray[np.float64]) -> tuple[np.ndarray, np.ndarray]:
    """State after one period from ``z0`` and the total input of its last step."""
    z = np.array(z0, dtype=float)
    a, b = loop.a, loop.b
    forced = excitation @ b.T            # B e_k of every step, one product
    for k in range(len(excitation) - 1):
        z = a @ z + forced[k]
    u_last = loop.c_u @ z + excitation[-1]
    return a @ z + forced[-1], u_last


def periodic_state(loop: LoopSystem, n_plant: int,
                   excitation: npt.ArrayLike) -> PeriodicState:
    """
    Periodic steady state of ``loop`` under ``excitation``, one period (N, n_in) on its input.

    Raises
    ------
    ConfigError
        If the loop is not asymptotically stable (no periodic state to converge to), or the
        excitation's width differs from the loop's inputs.
    """
    e = np.atleast_2d(np.asarray(excitation, dtype=float))
    if e.shape[1] != loop.b.shape[1] or e.shape[0] < 1:
        raise ConfigError(f'excitation has shape {e.shape}, expected (N >= 1, '
                          f'{loop.b.shape[1]}) for the loop inputs')
    radius = float(np.max(np.abs(np.linalg.eigvals(loop.a)))) if loop.a.size else 0.0
    if radius >= 1.0:
        raise ConfigError(f'the loop is not asymptotically stable (spectral radius {radius:.9g})'
                          ': it has no periodic steady state')
    z_rest, _ = _step_period(loop, np.zeros(loop.a.shape[0]), e)
    a_n = np.linalg.matrix_power(loop.a, len(e))
    z0 = np.linalg.solve(np.eye(loop.a.shape[0]) - a_n, z_rest)
    z_end, u_last = _step_period(loop, z0, e)
    scale = float(np.linalg.norm(z0)) or 1.0
    return PeriodicState(z0, z0[:n_plant].copy(), u_last,
                         float(np.linalg.norm(z_end - z0)) / scale)


def start_with_laws_at_rest(loop: LoopSystem, n_plant: int,
                            state: PeriodicState) -> PeriodicState:
    """
    A plant start for laws whose nodes start at rest, from the loop's periodic ``state``.

    The laws' states start at zero, not at their periodic values: the difference is a
    transient, and through the plant it rings in every lightly damped mode for as long as
    those modes ring (0.1 % damping: seconds). The plant's state is shifted by ``delta`` so
    that the whole start error ``[delta; -xc; 0]`` has no component along the ``n_plant``
    slowest eigenvectors of the loop: what is left decays at the rates of the fastest modes
    (the laws' own filters), and the run is periodic after a few of their time constants.
    ``u_previous`` stays the periodic one (the plant sets it). The returned ``plant_state`` is
    ``x + delta``; ``loop_state`` is the loop's periodic state as given.
    """
    n_laws = loop.a.shape[0] - n_plant - (loop.b.shape[1] if loop.augmented else 0)
    if n_laws == 0:
        return state
    lam, vec = np.linalg.eig(loop.a)
    slow = np.argsort(-np.abs(lam), kind='stable')[:n_plant]
    rows = np.linalg.solve(vec, np.eye(vec.shape[0]))[slow]          # left eigenvectors
    coupling = rows[:, :n_plant]
    wanted = rows[:, n_plant:n_plant + n_laws] @ state.loop_state[n_plant:n_plant + n_laws]
    # real delta with coupling delta = wanted (conjugate pairs: the real and imaginary parts)
    delta = np.linalg.lstsq(np.vstack([coupling.real, coupling.imag]),
                            np.r_[wanted.real, wanted.imag], rcond=None)[0]
    return PeriodicState(state.loop_state, state.plant_state + delta, state.u_previous,
                         state.closure)


def plant_periodic_state(plant: DiscretePlant, controllers: Sequence[DiscreteController],
                         excitation: npt.ArrayLike) -> PeriodicState:
    """
    :func:`periodic_state` of ``plant`` closed with ``controllers`` (lockstep loop).

    ``excitation``: one period (N, n_in) of the external force on the plant's input ports, in
    the order of ``plant.input_names``; step k of the run applies row ``k mod N``.
    """
    loop = loop_system(plant.a, plant.b, plant.c, plant.d, plant.input_names,
                       plant.output_names, controllers)
    return periodic_state(loop, plant.n_states, excitation)


def save_initial_state(path: str | Path, state: PeriodicState) -> Path:
    """Write the plant's part of ``state`` as an initial-state file (.npz) and return its path."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, 'wb') as f:
        np.savez(f, x=state.plant_state, u_previous=state.u_previous)   # the keys above
    return path


def load_initial_state(path: str | Path, n_states: int,
                       n_inputs: int) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """
    The plant state x_0 and input u_{-1} of an initial-state file (ConfigError in one line).

    ``u_previous`` may be left out (zero).
    """
    try:
        with np.load(path, allow_pickle=False) as doc:
            if STATE_KEY not in doc:
                raise ConfigError(f'initial state file {path} holds no array {STATE_KEY!r} '
                                  f'(it has {sorted(doc.files)})')
            x0 = np.asarray(doc[STATE_KEY], dtype=float)
            u = (np.asarray(doc[INPUT_KEY], dtype=float) if INPUT_KEY in doc
                 else np.zeros(n_inputs))
    except (OSError, ValueError, EOFError) as err:
        raise ConfigError(f'initial state file {path} is not readable as .npz: {err}') from None
    if x0.shape != (n_states,) or u.shape != (n_inputs,):
        raise ConfigError(f'initial state file {path} has {STATE_KEY} {x0.shape} and '
                          f'{INPUT_KEY} {u.shape}; the plant needs ({n_states},) and '
                          f'({n_inputs},)')
    if not (np.all(np.isfinite(x0)) and np.all(np.isfinite(u))):
        raise ConfigError(f'initial state file {path} holds values that are not finite')
    return x0, u
