"""
Stability of a sampled loop from frequency responses: the generalised Nyquist criterion.

The truncation check of :mod:`pentapod_sim.sim.stability` needs the controller's state space.
A controller known only by its FRF ``K(e^{j theta})`` (identified from a recorded run,
:mod:`pentapod_sim.analysis.frf.mimo`) is checked here instead: the plant's sampled FRF
``P(z) = C (zI - A)^-1 B + D z^-1`` (zero-order hold; the controller answers ``u_k`` to
``y_k = C x_k + D u_{k-1}``, the lockstep convention of :mod:`pentapod_sim.sim.controllers`)
is exact from its modes, ``L = K P`` (actuators to actuators), and the closed loop's poles are
the zeros of ``F(z) = det(I - L(z))``. With the open loop stable (the modal plant, a stable
controller), the argument principle on the unit circle gives the number of closed-loop poles
outside it: ``-W``, with ``W`` the counter-clockwise winding number of ``F`` around 0; ``F``
being real on the real axis, ``W`` is the change of ``arg F`` from theta = 0 to pi, over pi.

The curve is traced on a grid of theta = omega dt in [0, pi] that is dense around every
plant pole (lightly damped modes turn ``F`` fast there) and refined by bisection wherever
``arg F`` changes by more than :data:`MAX_TURN` between neighbours (a closed-loop pole near the
unit circle away from the open-loop ones). A curve that stays unresolved is reported as such,
not as stable.

Margin: the *return-difference margin* ``min_theta sigma_min(I - L)`` at the actuators (the
smallest perturbation of the loop, relative to identity, that reaches instability; 1 for no
feedback), and the loop with one more sample of delay ``z^-1 L``.

Units: frequencies [Hz], theta [rad], sample time dt [s]; ports as the plant's.
"""
from __future__ import annotations

from dataclasses import dataclass
import math
from typing import Callable, Sequence

import numpy as np
import numpy.typing as npt

from pentapod_sim.plant.model import PlantModel
from pentapod_sim.sim.controllers import DiscreteController

#: Largest change of arg F [rad] between grid neighbours before the interval is bisected.
MAX_TURN = 0.5
#: Uniform grid points on [0, pi] before refinement.
UNIFORM_POINTS = 2049
#: Points around each plant pole, spread over +-POLE_SPAN half-power widths.
POLE_POINTS, POLE_SPAN = 17, 8.0
#: Bisection rounds and the most points a curve may get.
MAX_ROUNDS, MAX_POINTS = 40, 400_000
#: Grid points evaluated at once (bounds the memory of the modal sum).
CHUNK = 2048

#: A controller's FRF: frequencies [Hz] -> (F, n_actuators, n_sensors) complex.
ControllerFrf = Callable[[npt.NDArray[np.float64]], npt.NDArray[np.complex128]]


class SampledPlantFrf:
    """
    The exact sampled FRF of a modal plant between chosen ports, from its modes.

    ``P(theta)`` (F, n_out, n_in) at ``z = e^{j theta}``: per mode the zero-order-hold block
    ``(zI - Phi_i)^-1 Gamma_i`` (:meth:`PlantModel.zoh_blocks`), summed as one matrix product
    over the modes, plus the feed-through acting one step late.
    """

    def __init__(self, plant: PlantModel, inputs: Sequence[str], outputs: Sequence[str],
                 dt: float) -> None:
        sub = plant.select(list(inputs), list(outputs))
        self.dt = float(dt)
        self.phi, gamma = sub.zoh_blocks(dt)
        n_in, n_out = len(inputs), len(outputs)
        # weights of the two modal states: output row x input column, per mode
        self.w0 = np.einsum('om,mi->moi', sub.c_disp, sub.b).reshape(sub.n_modes, -1)
        self.w1 = np.einsum('om,mi->moi', sub.c_vel, sub.b).reshape(sub.n_modes, -1)
        self.gamma = gamma
        self.d = np.asarray(sub.d, dtype=float)
        self.shape = (n_out, n_in)
        lam = np.linalg.eigvals(self.phi) if sub.n_modes else np.zeros((0, 2))
        self.poles = lam.ravel()

    def pole_grid(self) -> npt.NDArray[np.float64]:
        """Angles theta [rad] in [0, pi] around every pole (+-POLE_SPAN half widths)."""
        lam = self.poles[np.abs(self.poles) > 0]
        if not lam.size:
            return np.zeros(0)
        theta = np.abs(np.angle(lam))
        width = np.maximum(-np.log(np.minimum(np.abs(lam), 1.0 - 1e-15)), 1e-9)
        steps = np.linspace(-POLE_SPAN, POLE_SPAN, POLE_POINTS)
        grid = (theta[:, None] + width[:, None] * steps[None, :]).ravel()
        return grid[(grid > 0) & (grid < math.pi)]

    def __call__(self, theta: npt.ArrayLike) -> npt.NDArray[np.complex128]:
        """``P`` at ``z = e^{j theta}`` (F, n_out, n_in)."""
        th = np.atleast_1d(np.asarray(theta, dtype=float))
        out = np.empty((th.size, *self.shape), dtype=complex)
        p00, p01 = self.phi[:, 0, 0], self.phi[:, 0, 1]
        p10, p11 = self.phi[:, 1, 0], self.phi[:, 1, 1]
        g0, g1 = self.gamma[:, 0], self.gamma[:, 1]
        for start in range(0, th.size, CHUNK):
            z = np.exp(1j * th[start:start + CHUNK])[:, None]
            det = (z - p00) * (z - p11) - p01 * p10
            q0 = ((z - p11) * g0 + p01 * g1) / det       # (zI - Phi)^-1 Gamma, per mode
            q1 = (p10 * g0 + (z - p00) * g1) / det
            part = q0 @ self.w0 + q1 @ self.w1
            out[start:start + CHUNK] = part.reshape(-1, *self.shape) + \
                self.d[None] / z[:, :, None]
        return out


def controller_frf(ctrl: DiscreteController, dt: float) -> ControllerFrf:
    """The FRF ``c (zI - a)^-1 b + d`` of a discrete controller, as a function of f [Hz]."""
    def frf(freq_hz: npt.NDArray[np.float64]) -> npt.NDArray[np.complex128]:
        z = np.exp(2j * np.pi * np.asarray(freq_hz, dtype=float) * dt)
        out = np.broadcast_to(ctrl.d.astype(complex), (z.size, *ctrl.d.shape)).copy()
        if ctrl.n_states:
            eye = np.eye(ctrl.n_states)
            res = np.linalg.solve(z[:, None, None] * eye - ctrl.a, np.broadcast_to(
                ctrl.b, (z.size, *ctrl.b.shape)).astype(complex))
            out += ctrl.c @ res
        return out
    return frf


@dataclass(frozen=True)
class NyquistCheck:
    """
    Result of :func:`nyquist_check`.

    Attributes
    ----------
    label : str
        What was checked.
    resolved : bool
        The grid resolved the curve (its winding number is an integer within tolerance).
    unstable_poles : int
        Closed-loop poles outside the unit circle (``-W``); meaningful only if ``resolved``.
    margin : float
        ``min sigma_min(I - L)`` over the grid [-].
    margin_hz : float
        Frequency of that minimum [Hz].
    extra_delay : int
        Samples of delay added to the loop.
    modes : int
        Modes of the plant the loop was closed on.
    points : int
        Grid points after refinement.
    freq, det, sigma : ndarray
        The grid [Hz], ``det(I - L)`` and ``sigma_min(I - L)`` on it (for figures).
    """

    label: str
    resolved: bool
    unstable_poles: int
    margin: float
    margin_hz: float
    extra_delay: int
    modes: int
    points: int
    freq: npt.NDArray[np.float64]
    det: npt.NDArray[np.complex128]
    sigma: npt.NDArray[np.float64]

    @property
    def verdict(self) -> str:
        """``stable``, ``unstable`` or ``not resolved``."""
        if not self.resolved:
            return 'not resolved'
        return 'stable' if self.unstable_poles == 0 else 'unstable'


def _return_difference(plant: SampledPlantFrf, controller: ControllerFrf, theta: np.ndarray,
                       dt: float, extra_delay: int) -> np.ndarray:
    p = plant(theta)                                             # (F, n_s, n_a)
    k = controller(theta / (2 * np.pi * dt))                     # (F, n_a, n_s)
    loop = k @ p
    if extra_delay:
        loop = loop * np.exp(-1j * extra_delay * theta)[:, None, None]
    return np.eye(loop.shape[1])[None] - loop


def nyquist_check(plant: PlantModel, sensors: Sequence[str], actuators: Sequence[str],
                  controller: ControllerFrf, dt: float, extra_delay: int = 0,
                  label: str = 'loop') -> NyquistCheck:
    """
    Closed-loop stability and margin of ``plant`` with a controller given by its FRF.

    Parameters
    ----------
    plant : PlantModel
        The (reduced or check) modal plant; it must have the ``sensors`` outputs and the
        ``actuators`` inputs.
    sensors, actuators : sequence of str
        The controller's plant output ports (its inputs) and input ports (its outputs).
    controller : callable
        ``K(f)`` (F, n_actuators, n_sensors) for f in [0, Nyquist] Hz.
    dt : float
        Sample time [s].
    extra_delay : int
        Samples of delay added to the loop (0: as run).
    label : str
        Names the loop.
    """
    frf = SampledPlantFrf(plant, actuators, sensors, dt)
    theta = np.unique(np.concatenate([np.linspace(0.0, math.pi, UNIFORM_POINTS),
                                      frf.pole_grid()]))
    diff = _return_difference(frf, controller, theta, dt, extra_delay)
    det = np.linalg.det(diff)
    resolved = True
    for _ in range(MAX_ROUNDS):
        turn = np.abs(np.angle(det[1:] / det[:-1]))
        bad = np.flatnonzero(~(turn <= MAX_TURN))
        if not bad.size:
            break
        if theta.size + bad.size > MAX_POINTS:
            resolved = False
            break
        mid = 0.5 * (theta[bad] + theta[bad + 1])
        new = _return_difference(frf, controller, mid, dt, extra_delay)
        theta = np.concatenate([theta, mid])
        diff = np.concatenate([diff, new])
        det = np.concatenate([det, np.linalg.det(new)])
        order = np.argsort(theta)
        theta, diff, det = theta[order], diff[order], det[order]
    else:
        resolved = False
    phase = np.unwrap(np.angle(det))
    winding = (phase[-1] - phase[0]) / math.pi
    resolved = resolved and bool(np.all(np.isfinite(det))) and abs(winding - round(winding)) < 0.1
    sigma = np.linalg.svd(diff, compute_uv=False)[:, -1]
    best = int(np.argmin(sigma))
    freq = theta / (2 * np.pi * dt)
    return NyquistCheck(label, resolved, int(-round(winding)) if resolved else -1,
                        float(sigma[best]), float(freq[best]), int(extra_delay), plant.n_modes,
                        int(theta.size), freq, det, sigma)
