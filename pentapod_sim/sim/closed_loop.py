"""
Offline closed loop: the plant core plus damper/PMA laws in-process.

:func:`simulate` steps :class:`pentapod_sim.sim.stepping.DiscretePlant` exactly as the lockstep ROS
run does (y_k, then every law and the excitation answer u_k, then x_{k+1}); it is the reference
a ROS run must reproduce, bit for bit (test/test_plant_core.py). A multi-rate plant
(:class:`pentapod_sim.sim.multirate.MultiRatePlant`, N substeps per exchange) steps the same
way at the exchange rate; ``full_rate=True`` also keeps its N outputs per exchange.
:func:`closed_loop_system` forms the closed-loop discrete system of linear laws --
memoryless ones as static gains, laws with actuator/sensor dynamics or delays with their
controller states -- for the analytic checks, with the one construction of
:func:`pentapod_sim.sim.controllers.loop_system`; for a multi-rate plant it is the loop at the
exchange rate.

Units: as the plant ports (N, N m in; m, m/s, rad, rad/s out); time in steps of dt [s].
"""
from __future__ import annotations

from dataclasses import dataclass
import logging
from typing import Callable, Protocol, Sequence

import numpy as np
import numpy.typing as npt

from pentapod_sim.errors import ConfigError, PortError
from pentapod_sim.sim.controllers import (
    controller_of,
    loop_system,
    LoopSystem,
)
from pentapod_sim.sim.stepping import DiscretePlant

LOG = logging.getLogger(__name__)


class Law(Protocol):
    """What a control law offers (see :mod:`pentapod_damper.laws`)."""

    sensor_ports: list[str]
    actuator_ports: list[str]

    def step(self, sensors: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        """Efforts for the actuator ports at this step."""

    def reset(self) -> None:
        """Back to the initial state."""


@dataclass
class Response:
    """
    Closed-loop run: y[k] = y_k, u[k] = u_k (total input applied over step k).

    Attributes
    ----------
    y : (n_steps, n_out) ndarray
        Outputs in the units of the output ports.
    u : (n_steps, n_in) ndarray
        Inputs [N or N m].
    dt : float
        Sample time [s].
    output_names, input_names : list of str
        Port names of the columns.
    y_full : (n_steps * N, n_out) ndarray or None
        Full-rate outputs of a multi-rate plant (N substeps per exchange), row ``k N + j`` at
        ``t_k + j dt / N``; None unless asked for.
    """

    y: npt.NDArray[np.float64]
    u: npt.NDArray[np.float64]
    dt: float
    output_names: list[str]
    input_names: list[str]
    y_full: npt.NDArray[np.float64] | None = None

    def output(self, name: str) -> npt.NDArray[np.float64]:
        """Column of an output port."""
        return self.y[:, self.output_names.index(name)]

    def input(self, name: str) -> npt.NDArray[np.float64]:
        """Column of an input port."""
        return self.u[:, self.input_names.index(name)]


def _indices(names: Sequence[str], index: dict[str, int], what: str) -> npt.NDArray[np.intp]:
    """Map port names to plant indices (PortError names a missing port)."""
    try:
        return np.array([index[n] for n in names], dtype=np.intp)
    except KeyError as err:
        raise PortError(f'{what} port {err.args[0]!r} is not in the plant model') from None


def _as_slice(index: npt.NDArray[np.intp]) -> npt.NDArray[np.intp] | slice:
    """A run of consecutive indices as a slice (an in-place add on a view), else the indices."""
    if len(index) and np.array_equal(index, np.arange(index[0], index[0] + len(index))):
        return slice(int(index[0]), int(index[0]) + len(index))
    return index


def excitation_matrix(plant: DiscretePlant, ports: Sequence[str],
                      forces: npt.ArrayLike, n_steps: int) -> npt.NDArray[np.float64]:
    """Scatter excitation forces (n_steps, len(ports)) into a full input array (n_steps, n_in)."""
    forces = np.asarray(forces, dtype=float)
    if forces.shape != (n_steps, len(ports)):
        raise ConfigError(f'excitation forces have shape {forces.shape}, expected '
                          f'({n_steps}, {len(ports)})')
    e = np.zeros((n_steps, len(plant.input_names)))
    e[:, _indices(ports, plant.input_index, 'excitation')] = forces
    return e


def simulate(plant: DiscretePlant, laws: Sequence[Law], excitation: npt.NDArray[np.float64],
             progress: Callable[[int, int], None] | None = None,
             full_rate: bool = False) -> Response:
    """
    Step plant + laws from the plant's current state, as the lockstep ROS run does.

    Parameters
    ----------
    plant : DiscretePlant
        The plant (stepped in place).
    laws : sequence of Law
        Controllers; each answers every step from its sensor outputs.
    excitation : (n_steps, n_in) ndarray
        External forces per step [N, N m] (:func:`excitation_matrix`).
    progress : callable, optional
        Called as ``progress(k, n_steps)`` every 10 % of the run.
    full_rate : bool, optional
        Keep the full-rate outputs of a multi-rate plant (``Response.y_full``).

    Returns
    -------
    Response
    """
    n_in = len(plant.input_names)
    excitation = np.asarray(excitation, dtype=float)
    if excitation.ndim != 2 or excitation.shape[1] != n_in:
        raise ConfigError(f'excitation has shape {excitation.shape}, expected (n_steps, {n_in})')
    n_steps = excitation.shape[0]
    bound = [(_indices(law.sensor_ports, plant.output_index, 'sensor'),
              _as_slice(_indices(law.actuator_ports, plant.input_index, 'actuator')), law.step)
             for law in laws]
    ys = np.empty((n_steps, len(plant.output_names)))
    us = excitation.copy()           # u_k is built in place from e_k
    every = max(1, n_steps // 10)
    outputs, advance = plant.outputs, plant.advance
    fine_outputs = getattr(plant, 'fine_outputs', None) if full_rate else None
    substeps = getattr(plant, 'substeps', 1)
    fine = np.empty((n_steps if fine_outputs else 0, substeps, len(plant.output_names)))
    for k in range(n_steps):
        y = outputs(ys[k])
        u = us[k]
        for sensors, actuators, step in bound:
            u[actuators] += step(y[sensors])
        if fine_outputs is not None:
            fine_outputs(u, y, fine[k])
        advance(u)
        if progress is not None and (k + 1) % every == 0:
            progress(k + 1, n_steps)
    y_full = None
    if full_rate:
        y_full = fine.reshape(-1, ys.shape[1]) if fine_outputs is not None else ys.copy()
    return Response(ys, us, plant.dt, list(plant.output_names), list(plant.input_names),
                    y_full)


def closed_loop_system(plant: DiscretePlant, laws: Sequence[Law]) -> LoopSystem:
    """
    Discrete closed loop of the plant and linear laws, as :func:`simulate` steps it.

    Each law enters through its discrete model
    (:func:`pentapod_sim.sim.controllers.controller_of`): ``discrete_model()`` for laws with
    actuator/sensor dynamics or delays, ``linear_gain()`` for memoryless ones.

    Returns
    -------
    LoopSystem
        ``z_{k+1} = a z_k + b e_k``, ``u_k = c_u z_k + e_k``, ``y_k = c_y z_k`` (e: external
        input), state ``[x; xc; u_{k-1}]``: the plant's, the controllers', and the last input
        only if a law reads an output with feed-through (``augmented``; otherwise
        ``y_k = c_y z_k + D u_{k-1}``).

    Raises
    ------
    ConfigError
        If a law has no linear model (limits, or a filter without a model).
    """
    return loop_system(plant.a, plant.b, plant.c, plant.d, plant.input_names,
                       plant.output_names, [controller_of(law) for law in laws])
