"""
Linear discrete controllers on named plant ports, and the sampled loop they close.

A control law with internal dynamics (actuator/sensor low-pass, delays) is a discrete state
space sampled with the plant (:class:`DiscreteController`); a memoryless one is the static gain
``u = K y``. :func:`loop_system` closes the lockstep loop of a discrete plant with any number of
them: the plant is held over a step (zero-order hold) and every controller answers ``u_k`` to
the outputs ``y_k = C x_k + D u_{k-1}`` of the same step. The stepped offline loop
(:func:`pentapod_sim.sim.closed_loop.simulate`), the truncation check
(:mod:`pentapod_sim.sim.stability`) and the analytic FRFs all use this one construction.

Units: as the plant ports (N, N m in; m, m/s, rad, rad/s out).
"""
from __future__ import annotations

from dataclasses import dataclass
import json
from typing import NamedTuple, Protocol, Sequence

import numpy as np
import numpy.typing as npt
import scipy.linalg

from pentapod_sim.errors import ConfigError, PortError


@dataclass(frozen=True)
class DiscreteController:
    """
    Linear discrete controller on named ports, sampled with the plant.

    ``xc_{k+1} = a xc_k + b y_k`` and ``u_k = c xc_k + d y_k``, where ``y_k`` are the values of
    ``sensor_ports`` at step k and ``u_k`` the efforts on ``actuator_ports``.

    Attributes
    ----------
    sensor_ports, actuator_ports : tuple of str
        Plant output and input port names (any sequence of str, kept as a tuple).
    a, b, c, d : ndarray
        (n, n), (n, n_s), (n_a, n), (n_a, n_s); n = 0 for a memoryless law.
    """

    sensor_ports: Sequence[str]
    actuator_ports: Sequence[str]
    a: npt.NDArray[np.float64]
    b: npt.NDArray[np.float64]
    c: npt.NDArray[np.float64]
    d: npt.NDArray[np.float64]

    def __post_init__(self) -> None:
        """Convert to float arrays and check the shapes (ConfigError names the mismatch)."""
        n_s, n_a = len(self.sensor_ports), len(self.actuator_ports)
        n = np.asarray(self.a).shape[0] if np.asarray(self.a).size else 0
        want = {'a': (n, n), 'b': (n, n_s), 'c': (n_a, n), 'd': (n_a, n_s)}
        for name, shape in want.items():
            value = np.asarray(getattr(self, name), dtype=float)
            if value.size == 0 and 0 in shape:      # [] for an empty block
                value = value.reshape(shape)
            if value.shape != shape:
                raise ConfigError(f'controller matrix {name} has shape {value.shape}, expected '
                                  f'{shape} for {n} states, {n_s} sensors, {n_a} actuators')
            if not np.all(np.isfinite(value)):
                raise ConfigError(f'controller matrix {name} is not finite')
            object.__setattr__(self, name, value)
        object.__setattr__(self, 'sensor_ports', tuple(self.sensor_ports))
        object.__setattr__(self, 'actuator_ports', tuple(self.actuator_ports))

    @classmethod
    def static(cls, sensor_ports: Sequence[str], actuator_ports: Sequence[str],
               gain: npt.ArrayLike) -> 'DiscreteController':
        """Memoryless law ``u = K y`` with ``K = gain`` (n_actuators, n_sensors)."""
        gain = np.asarray(gain, dtype=float)
        return cls(tuple(sensor_ports), tuple(actuator_ports), np.zeros((0, 0)),
                   np.zeros((0, len(sensor_ports))), np.zeros((len(actuator_ports), 0)), gain)

    @property
    def n_states(self) -> int:
        """Number of controller states."""
        return self.a.shape[0]

    def to_json(self) -> str:
        """JSON text of the controller (e.g. for a ROS string parameter)."""
        return json.dumps({'sensor_ports': list(self.sensor_ports),
                           'actuator_ports': list(self.actuator_ports),
                           **{k: getattr(self, k).tolist() for k in 'abcd'}})

    @classmethod
    def from_json(cls, text: str) -> 'DiscreteController':
        """Inverse of :meth:`to_json` (ConfigError names what is missing or malformed)."""
        try:
            doc = json.loads(text)
            return cls(doc['sensor_ports'], doc['actuator_ports'],
                       *(np.asarray(doc[k], dtype=float) for k in 'abcd'))
        except (ValueError, KeyError, TypeError) as err:
            raise ConfigError(f'not a controller description: {err}') from None


def with_delay(ctrl: DiscreteController, steps: int = 1) -> DiscreteController:
    """
    ``ctrl`` answering ``steps`` samples late: ``u_k = K(y_{k - steps})``.

    The delay line holds the last ``steps`` sensor vectors as extra states (oldest last).
    """
    if steps < 0:
        raise ConfigError(f'a delay of {steps} samples is negative')
    out = ctrl
    n_s = len(ctrl.sensor_ports)
    for _ in range(steps):
        n = out.n_states
        a = np.block([[out.a, out.b], [np.zeros((n_s, n + n_s))]])
        b = np.vstack([np.zeros((n, n_s)), np.eye(n_s)])
        c = np.hstack([out.c, out.d])
        out = DiscreteController(ctrl.sensor_ports, ctrl.actuator_ports, a, b, c,
                                 np.zeros_like(ctrl.d))
    return out

class PortedLaw(Protocol):
    """What :func:`controller_of` needs of a law besides ``discrete_model``/``linear_gain``."""

    @property
    def sensor_ports(self) -> Sequence[str]:
        """Plant output ports the law reads."""

    @property
    def actuator_ports(self) -> Sequence[str]:
        """Plant input ports the law drives."""


def controller_of(law: PortedLaw) -> DiscreteController:
    """
    The discrete linear model of a control law.

    A law with internal dynamics returns it from ``discrete_model()``; a memoryless linear law
    from ``linear_gain()`` (with ``sensor_ports`` and ``actuator_ports``).

    Raises
    ------
    ConfigError
        If the law offers neither (e.g. limits or a filter without a linear model).
    """
    model = getattr(law, 'discrete_model', None)
    if callable(model):
        result = model()
        if isinstance(result, DiscreteController):
            return result
    gain = getattr(law, 'linear_gain', lambda: None)()
    if gain is None:
        raise ConfigError(f'{type(law).__name__} on {getattr(law, "actuator_ports", "?")} has '
                          'no linear discrete model (discrete_model() or linear_gain()); the '
                          'stability check cannot close its loop')
    return DiscreteController.static(law.sensor_ports, law.actuator_ports, gain)


def _index(names: Sequence[str], ports: Sequence[str], what: str) -> np.ndarray:
    lookup = {n: i for i, n in enumerate(names)}
    try:
        return np.array([lookup[p] for p in ports], dtype=np.intp)
    except KeyError as err:
        raise PortError(f'{what} port {err.args[0]!r} is not in the plant model') from None


class ControllerBlocks(NamedTuple):
    """
    Controllers stacked on a plant's ports: ``xc' = a xc + b y``, ``u = c xc + gain y``.

    ``gain`` (n_in, n_out), ``a`` (n_c, n_c), ``b`` (n_c, n_out), ``c`` (n_in, n_c), with the
    states of the controllers one after the other and their efforts summed per input port.
    """

    gain: np.ndarray
    a: np.ndarray
    b: np.ndarray
    c: np.ndarray


def controller_blocks(controllers: Sequence[DiscreteController], input_names: Sequence[str],
                      output_names: Sequence[str]) -> ControllerBlocks:
    """Stack ``controllers`` on the ports ``input_names`` / ``output_names`` (PortError)."""
    n_in, n_out = len(input_names), len(output_names)
    n_c = sum(k.n_states for k in controllers)
    gain, c_full = np.zeros((n_in, n_out)), np.zeros((n_in, n_c))
    b_full, a_c = np.zeros((n_c, n_out)), np.zeros((n_c, n_c))
    start = 0
    for ctrl in controllers:
        rows = _index(input_names, ctrl.actuator_ports, 'actuator')
        cols = _index(output_names, ctrl.sensor_ports, 'sensor')
        span = slice(start, start + ctrl.n_states)
        gain[np.ix_(rows, cols)] += ctrl.d
        c_full[rows, span] += ctrl.c
        b_full[span, cols] += ctrl.b
        a_c[span, span] = ctrl.a
        start += ctrl.n_states
    return ControllerBlocks(gain, a_c, b_full, c_full)


class LoopSystem(NamedTuple):
    """
    Closed sampled loop ``z_{k+1} = a z_k + b e_k``, ``u_k = c_u z_k + e_k``, ``y_k = c_y z_k``.

    ``e`` is the external input on the plant's input ports. The state is ``[x; xc; u_{k-1}]``
    (plant, controllers, last input); ``u_{k-1}`` is left out (``augmented`` False) when no
    controller reads an output with feed-through, and then ``y_k = c_y z_k + D u_{k-1}``.
    """

    a: np.ndarray
    b: np.ndarray
    c_y: np.ndarray
    c_u: np.ndarray
    augmented: bool


def loop_system(a: np.ndarray, b: np.ndarray, c: np.ndarray, d: np.ndarray,
                input_names: Sequence[str], output_names: Sequence[str],
                controllers: Sequence[DiscreteController]) -> LoopSystem:
    """
    The sampled loop of a discrete plant (lockstep convention) and controllers.

    The plant is ``x_{k+1} = a x_k + b u_k``, ``y_k = c x_k + d u_{k-1}``; the controllers'
    efforts add up on the input ports, together with the external input ``e_k``.
    """
    n_in, n_out = len(input_names), len(output_names)
    gain, a_c, b_full, c_full = controller_blocks(controllers, input_names, output_names)
    n_c = a_c.shape[0]
    kc = gain @ c
    kd, bd = gain @ d, b_full @ d
    if not (np.any(kd) or np.any(bd)):
        return LoopSystem(np.block([[a + b @ kc, b @ c_full], [b_full @ c, a_c]]),
                          np.vstack([b, np.zeros((n_c, n_in))]),
                          np.hstack([c, np.zeros((n_out, n_c))]), np.hstack([kc, c_full]),
                          False)
    c_u = np.hstack([kc, c_full, kd])
    a_cl = np.block([[a + b @ kc, b @ c_full, b @ kd], [b_full @ c, a_c, bd], [c_u]])
    b_cl = np.vstack([b, np.zeros((n_c, n_in)), np.eye(n_in)])
    c_y = np.hstack([c, np.zeros((n_out, n_c)), d])
    return LoopSystem(a_cl, b_cl, c_y, c_u, True)


def loop_matrix(a: np.ndarray, b: np.ndarray, c: np.ndarray, d: np.ndarray,
                input_names: Sequence[str], output_names: Sequence[str],
                controllers: Sequence[DiscreteController]) -> np.ndarray:
    """State matrix of :func:`loop_system`."""
    return loop_system(a, b, c, d, input_names, output_names, controllers).a


def parallel(controllers: Sequence[DiscreteController]) -> DiscreteController:
    """The laws side by side (one node's laws): one controller, ports and states concatenated."""
    return DiscreteController(
        [p for k in controllers for p in k.sensor_ports],
        [p for k in controllers for p in k.actuator_ports],
        *(scipy.linalg.block_diag(*(getattr(k, m) for k in controllers)) for m in 'abcd'))
