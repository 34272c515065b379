"""
The ideal proof-mass actuator on the working platform (paper section 4.4), free of ROS.

The proof mass m_a is accelerated by ``g v`` (v: the measured mount velocity, optionally
through a second-order Butterworth high-pass against drift), which puts the damping
``b = m_a g`` on the mount above the high-pass. Without stroke or force limits the law is
linear: :meth:`ProofMassActuator.discrete_model` is its state space (the high-pass biquad the
law steps), so the truncation check and the analytic FRFs include the high-pass.

Units: forces N, velocities m/s, masses kg, gains 1/s, lengths m.
"""
from __future__ import annotations

from typing import Sequence

import numpy as np
import numpy.typing as npt
import scipy.signal

from pentapod_damper.laws.viscous import _axes
from pentapod_sim.errors import ConfigError
from pentapod_sim.sim.controllers import DiscreteController
from pentapod_sim.sim.law_models import positive as _positive


class ProofMassActuator:
    """
    Ideal inertial actuator on ``pma_mount``: the proof mass is accelerated by ``g v``.

    The actuator pushes the proof mass m_a with ``F_a = m_a g v_f`` (v_f: measured mount
    velocity, optionally high-passed) and the structure with the reaction ``-F_a``, which is a
    viscous damper of ``b = m_a g`` for frequencies above the high-pass. The proof mass is
    integrated exactly for a force held over the step; the mount moves with the sampled
    velocity over the step.

    Parameters
    ----------
    directions : sequence of str
        Axes (x, y, z) with one actuator each.
    mass : float
        Proof mass m_a [kg], > 0.
    gain : float
        g [1/s], >= 0 (damping b = m_a g [N s/m]).
    dt : float
        Sample time [s].
    highpass_hz : float
        Corner of a 2nd-order Butterworth high-pass on the velocity [Hz]; 0 = none.
    stroke_limit : float
        Max |stroke| [m] (proof mass relative to the mount); 0 = unlimited.
    force_limit : float
        Max |F_a| commanded [N]; 0 = unlimited. At the stroke limit an ideal end stop adds
        the force that holds the proof mass at the limit (it may exceed ``force_limit``).
    """

    def __init__(self, directions: Sequence[str], mass: float, gain: float, dt: float,
                 highpass_hz: float = 0.0, stroke_limit: float = 0.0, force_limit: float = 0.0):
        axes = _axes(directions)
        self.actuator_ports = [f'pma_force_{a}' for a in axes]
        self.sensor_ports = [f'pma_mount_velocity_{a}' for a in axes]
        self.mass = _positive('proof mass m_a [kg]', mass)
        self.gain = _positive('gain g [1/s]', gain, allow_zero=True)
        self.dt = _positive('sample time dt [s]', dt)
        self.highpass_hz = _positive('highpass_hz', highpass_hz, allow_zero=True)
        if self.highpass_hz >= 0.5 / self.dt:
            raise ConfigError(f'highpass_hz {self.highpass_hz} must be below Nyquist '
                              f'{0.5 / self.dt} Hz')
        self.stroke_limit = _positive('stroke_limit [m]', stroke_limit, allow_zero=True)
        self.force_limit = _positive('force_limit [N]', force_limit, allow_zero=True)
        self.sos = (scipy.signal.butter(2, self.highpass_hz, 'highpass', fs=1 / self.dt,
                                        output='sos')[0] if self.highpass_hz > 0 else None)
        self.reset()

    def reset(self) -> None:
        """Proof mass at rest in the middle of its stroke; filter at rest."""
        n = len(self.actuator_ports)
        self.stroke = np.zeros(n)          # proof-mass displacement relative to the mount [m]
        self.mass_velocity = np.zeros(n)   # absolute proof-mass velocity [m/s]
        self.force = np.zeros(n)           # F_a on the proof mass over the last step [N]
        self._hp_state = np.zeros((n, 2))
        self.limit_hits = {'stroke': 0, 'force': 0}

    def _highpass(self, v: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        """One sample of the biquad (transposed direct form II, scipy's sosfilt recursion).

        Written out because a sosfilt call per sample costs ~20 us of overhead.
        """
        b0, b1, b2, _, a1, a2 = self.sos
        z = self._hp_state
        out = b0 * v + z[:, 0]
        z[:, 0] = b1 * v - a1 * out + z[:, 1]
        z[:, 1] = b2 * v - a2 * out
        return out

    def step(self, sensors: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        """
        Advance the proof mass over one step and return the force on the structure [N].

        Parameters
        ----------
        sensors : (n,) ndarray
            Mount velocity v_k [m/s] per axis.
        """
        v = np.asarray(sensors, dtype=float)
        v_f = self._highpass(v) if self.sos is not None else v
        force = self.mass * self.gain * v_f
        if self.force_limit > 0:
            clipped = np.clip(force, -self.force_limit, self.force_limit)
            self.limit_hits['force'] += int(np.count_nonzero(clipped != force))
            force = clipped
        half_dt2_m = 0.5 * self.dt ** 2 / self.mass
        free = self.stroke + self.dt * (self.mass_velocity - v)
        if self.stroke_limit > 0:
            target = np.clip(free + half_dt2_m * force, -self.stroke_limit, self.stroke_limit)
            limited = (target - free) / half_dt2_m
            hit = np.abs(limited - force) > 1e-12 * (1 + np.abs(force))
            self.limit_hits['stroke'] += int(np.count_nonzero(hit))
            force = np.where(hit, limited, force)
        self.stroke = free + half_dt2_m * force
        self.mass_velocity = self.mass_velocity + self.dt / self.mass * force
        self.force = force
        return -force

    def linear_gain(self) -> npt.NDArray[np.float64] | None:
        """``-m_a g I`` when there is no filter or limit, else None (the law has memory)."""
        if self.sos is not None or self.stroke_limit > 0 or self.force_limit > 0:
            return None
        return -self.mass * self.gain * np.eye(len(self.actuator_ports))

    def discrete_model(self) -> DiscreteController | None:
        """
        The law's state space with its high-pass (None with limits: it is not linear).

        The biquad of :meth:`_highpass` as ``z_k+1 = A z_k + B v_k``, ``v_f = C z_k + D v_k``
        (transposed direct form II), per axis; the force on the mount is ``-m_a g v_f``.
        """
        if self.stroke_limit > 0 or self.force_limit > 0:
            return None
        n = len(self.actuator_ports)
        if self.sos is None:
            return DiscreteController.static(self.sensor_ports, self.actuator_ports,
                                             -self.mass * self.gain * np.eye(n))
        b0, b1, b2, _, a1, a2 = self.sos
        a = np.array([[-a1, 1.0], [-a2, 0.0]])
        b = np.array([[b1 - a1 * b0], [b2 - a2 * b0]])
        c = np.array([[1.0, 0.0]])
        eye, g = np.eye(n), -self.mass * self.gain
        return DiscreteController(self.sensor_ports, self.actuator_ports, np.kron(eye, a),
                                  np.kron(eye, b), g * np.kron(eye, c), g * b0 * eye)
