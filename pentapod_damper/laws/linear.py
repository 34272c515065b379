"""
Laws with linear dynamics stepped sample by sample.

Integral force feedback, band-pass velocity, lag displacement and positive position feedback
on strut ports (their transfer functions: :mod:`pentapod_sim.sim.law_models`), and the feed
drives' servo cascade with IFF inside (HAC-LAC) or alone (:func:`feed_drives`, its discrete
state space :class:`pentapod_sim.sim.drives.FeedDrives`).

A :class:`SteppedLaw` holds the discrete state space of its law at the plant's sample time and
answers ``u_k`` to ``y_k`` (lockstep convention, docs/architecture.md); ``discrete_model()``
is that same state space for the truncation check and the analytic FRFs,
``continuous_model()`` the law without sampling and delay. Gains may be changed between steps
(:meth:`SteppedLaw.set_gain` scales every channel).

Units: as the ports (N, N m; m, rad, m/s, rad/s); frequencies Hz, gains as stated.
"""
from __future__ import annotations

from dataclasses import replace
from typing import Sequence

import numpy as np
import numpy.typing as npt

from pentapod_damper.laws.viscous import _struts
from pentapod_sim.errors import ConfigError
from pentapod_sim.plant.drives import DriveParams
from pentapod_sim.plant.ports import collocated_output
from pentapod_sim.sim.controllers import DiscreteController
from pentapod_sim.sim.drives import FeedDrives
from pentapod_sim.sim.law_models import (
    band_pass,
    Dynamics,
    iff,
    lag_displacement,
    LinearLaw,
    positive,
    ppf,
)

#: Strut port kinds of the laws: actuator port pattern per kind.
PORT_KINDS = {'bending': 'strut{i}_bending_moment_{k}', 'chord': 'strut{i}_chord_force_{k}'}


class SteppedLaw:
    """
    A :class:`~pentapod_sim.sim.law_models.LinearLaw` stepped at the sample time ``dt`` [s].

    The law's efforts are scaled by one factor (:meth:`set_gain`, or the damper node setting
    ``gains``): the IFF and band-pass laws are built per unit gain and scaled by theirs, the
    lag and PPF laws carry their stiffness per port and a scale of 1.

    Attributes
    ----------
    law : LinearLaw or FeedDrives
        The law (ports, transfer function, gains, dynamics), or the feed drives' cascade.
    sensor_ports, actuator_ports : list of str
        Plant output and input ports.
    """

    def __init__(self, law: LinearLaw | FeedDrives, dt: float) -> None:
        self.law = law
        self.dt = positive('sample time dt [s]', dt)
        self.sensor_ports = list(law.sensor_ports)
        self.actuator_ports = list(law.actuator_ports)
        self._model = law.discrete(self.dt)
        self._scale = 1.0
        self.reset()

    @property
    def gains(self) -> npt.NDArray[np.float64]:
        """The scale of every channel (the damper node's gain parameter of the law)."""
        return np.full(len(self.actuator_ports), self._scale)

    @gains.setter
    def gains(self, value: npt.ArrayLike) -> None:
        """A new gain parameter (one value for every channel) scales the law from now on."""
        self.set_gain(float(np.mean(np.asarray(value, dtype=float))))

    def reset(self) -> None:
        """Controller states to zero."""
        self._state = np.zeros(self._model.n_states)

    def set_gain(self, scale: float) -> None:
        """Scale every channel's gain by ``scale`` (>= 0) from the next step on."""
        self._scale = positive('gain scale', scale, allow_zero=True)

    def step(self, sensors: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        """Efforts ``u_k`` for the sensor values ``y_k`` of this step."""
        m, y = self._model, np.asarray(sensors, dtype=float)
        u = m.c @ self._state + m.d @ y
        self._state = m.a @ self._state + m.b @ y
        return self._scale * u

    def linear_gain(self) -> None:
        """None: the law has memory (see :meth:`discrete_model`)."""
        return None

    def discrete_model(self) -> DiscreteController:
        """The law's discrete state space on its ports, gains scaled as set."""
        m = self._model
        return DiscreteController(m.sensor_ports, m.actuator_ports, m.a, m.b,
                                  self._scale * m.c, self._scale * m.d)

    def continuous_model(self) -> DiscreteController:
        """The law without sampling and delay (continuous matrices, same container)."""
        m = self.law.continuous()
        return DiscreteController(m.sensor_ports, m.actuator_ports, m.a, m.b,
                                  self._scale * m.c, self._scale * m.d)


def _strut_pairs(kind: str, struts: Sequence[int]) -> list[str]:
    if kind not in PORT_KINDS:
        raise ConfigError(f'strut port kind must be one of {", ".join(PORT_KINDS)}, got '
                          f'{kind!r}')
    return [PORT_KINDS[kind].format(i=i, k=k) for i in _struts(struts) for k in (2, 3)]


def integral_force_feedback(struts: Sequence[int], gain: float, omega_i: float, dt: float,
                            dynamics: Dynamics | None = None) -> SteppedLaw:
    """
    Integral force feedback from the struts' load cells to force actuators at their nuts.

    ``u = -g / (s + omega_i) F`` from each strut's load cell (``strut<i>_force``) to a force
    actuator in series with its drive link (``strut<i>_drive_force``); g [1/s], omega_i
    [rad/s].
    """
    struts = _struts(struts)
    law = SteppedLaw(iff([f'strut{i}_force' for i in struts],
                         [f'strut{i}_drive_force' for i in struts], 1.0, omega_i,
                         dynamics or Dynamics()), dt)
    law.set_gain(gain)          # the law per unit gain, scaled: the gain may change from 0
    return law


def band_pass_velocity(kind: str, struts: Sequence[int], gain: float, highpass_hz: float,
                       lowpass_hz: float, dt: float,
                       dynamics: Dynamics | None = None) -> SteppedLaw:
    """Relative velocity feedback through a band-pass on the strut ports of ``kind``."""
    ports = _strut_pairs(kind, struts)
    law = SteppedLaw(band_pass([collocated_output(p) for p in ports], ports, 1.0, highpass_hz,
                               lowpass_hz, dynamics or Dynamics()), dt)
    law.set_gain(gain)
    return law


def lag_displacement_feedback(kind: str, struts: Sequence[int],
                              stiffness: float | Sequence[float], corner_hz: float, dt: float,
                              dynamics: Dynamics | None = None) -> SteppedLaw:
    """
    Lag displacement feedback ``u = +K w_c / (s + w_c) y`` on the strut ports of ``kind``.

    ``stiffness`` K [N m/rad for bending, N/m for chord] per port or one for all.
    """
    ports = _strut_pairs(kind, struts)
    return SteppedLaw(lag_displacement([collocated_output(p, 'displacement') for p in ports],
                                       ports, stiffness, corner_hz, dynamics or Dynamics()), dt)


def positive_position_feedback(kind: str, struts: Sequence[int], gain: float | Sequence[float],
                               frequency_hz: float, damping: float, dt: float,
                               dynamics: Dynamics | None = None) -> SteppedLaw:
    """Positive position feedback on one mode through the strut ports of ``kind``."""
    ports = _strut_pairs(kind, struts)
    return SteppedLaw(ppf([collocated_output(p, 'displacement') for p in ports], ports, gain,
                          frequency_hz, damping, dynamics or Dynamics()), dt)


class DrivesLaw(SteppedLaw):
    """
    The feed drives' cascade stepped; its gain parameter is the IFF gain g [1/s].

    A new g (the damper node's ``drive_iff_gain`` set while running) rebuilds the cascade's
    discrete state space with it (:meth:`FeedDrives.discrete`, the same dynamics and delay)
    from the next step on; the controller state is kept (same size for every g > 0: the IFF
    filter's and the delay line's states carry on). A g that adds or drops the load cells
    (from or to 0: the drives alone have no IFF channel) is refused: the node's sensors are
    fixed at its start.
    """

    law: FeedDrives

    @property
    def gains(self) -> npt.NDArray[np.float64]:
        """The IFF gain g [1/s] of every channel."""
        return np.full(len(self.actuator_ports), float(self.law.iff_gain))

    @gains.setter
    def gains(self, value: npt.ArrayLike) -> None:
        self.set_iff_gain(float(np.mean(np.asarray(value, dtype=float))))

    def with_iff_gain(self, gain: float) -> tuple[FeedDrives, DiscreteController]:
        """The cascade and its discrete model with IFF gain ``gain`` (ConfigError if refused)."""
        new = replace(self.law, iff_gain=positive('IFF gain g [1/s]', gain, allow_zero=True))
        if new.sensor_ports != self.law.sensor_ports:
            now = 'with' if self.law.iff_gain else 'without'
            raise ConfigError(f'drive_iff_gain {gain!r}: the drives run {now} IFF since the '
                              'start, and a gain to or from 0 would add or drop the load cells '
                              "(the node's sensors are fixed): start the node with "
                              'drive_iff_gain > 0 to change it while running')
        return new, new.discrete(self.dt)

    def set_iff_gain(self, gain: float) -> None:
        """Rebuild the cascade with IFF gain ``gain`` from the next step on (state kept)."""
        self.law, self._model = self.with_iff_gain(gain)


def feed_drives(struts: Sequence[int], params: DriveParams, dt: float, iff_gain: float = 0.0,
                iff_omega: float = 0.0, dynamics: Dynamics | None = None) -> DrivesLaw:
    """
    The feed drives' servo cascade of ``struts``, with IFF inside for ``iff_gain`` > 0 (HAC-LAC).

    Per strut: position P and velocity PI on the motor encoder (``strut<i>_motor_position``
    [m], ``strut<i>_motor_velocity`` [m/s]) with the drives' own delay, and (HAC-LAC)
    ``-g / (s + omega_i)`` of the load cell ``strut<i>_force`` [N] through ``dynamics`` into
    the force command ``strut<i>_motor_force`` [N]; g [1/s], omega_i [rad/s]. Its scale stays
    1 (the cascade's gains are the drives'); its gain parameter is g (:class:`DrivesLaw`).
    Needs a plant with the drives' rotors.
    """
    return DrivesLaw(FeedDrives(params, tuple(_struts(struts)), float(iff_gain),
                                 float(iff_omega), dynamics or Dynamics()), dt)
