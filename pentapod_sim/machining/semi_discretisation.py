"""
Milling stability in the time domain: first-order semi-discretisation (Insperger & Stepan).

The modal model ``q'' + 2 Z W q' + W^2 q = b F``, ``r = C_d q + C_v q'`` (TCP x-y displacement,
from a :class:`~pentapod_sim.plant.model.PlantModel`'s TCP ports) is cut with the time-periodic
force ``F(t) = a H(t) (r(t) - r(t - T))``, ``H(t) = K_t sum_j g_j f(phi_j) n(phi_j)^T``
(:mod:`pentapod_sim.machining.milling_cut`). One tooth period T is split into k intervals; on
each, ``H`` is replaced by its exact mean over the interval and the delayed displacement
``r(t - T)`` by the straight line between its two grid values (Insperger & Stepan 2004,
"Updated semi-discretization method for periodic delay-differential equations with discrete
delay", Int. J. Numer. Meth. Engng 61). Each interval is then solved exactly (one block matrix
exponential, Van Loan), which maps the state ``[y_i; r_{i-1} .. r_{i-k}]`` to the next; the
product over a period is the monodromy matrix, and the cut is stable when all its
eigenvalues (Floquet multipliers) lie inside the unit circle.

Unlike the zero-order solution this keeps the time variation of ``H``, so it finds the
period-doubling (flip) lobes of low radial immersion. Its error falls as 1/k^2; k = 40 is the
usual choice. The plant's feed-through D (static correction of dropped modes) is left out:
compare with lobes of the same modal part. Units: SI, speeds in rpm.
"""
from __future__ import annotations

from dataclasses import dataclass
import math

import numpy as np
import numpy.typing as npt
import scipy.linalg as sla

from pentapod_sim.errors import ConfigError
from pentapod_sim.machining.milling_cut import engaged_integral, MillingCut
from pentapod_sim.machining.tcp_frf import TCP_DISPLACEMENTS, TCP_FORCES
from pentapod_sim.plant.model import PlantModel

#: A multiplier is called real (flip or fold) if its angle is within this of 0 or pi [rad].
REAL_ANGLE = 1e-3


@dataclass(frozen=True)
class CriticalDepth:
    """
    The lowest depth at which a cut becomes unstable at one spindle speed.

    Attributes
    ----------
    speed : float
        Spindle speed [rpm].
    depth : float
        Critical axial depth [m]; ``inf`` if stable up to the largest depth tried.
    multiplier : complex
        The critical Floquet multiplier just above the critical depth.
    kind : str
        'hopf' (complex multiplier: chatter off the tooth harmonics), 'flip' (-1: period
        doubling, chatter at odd multiples of half the tooth-passing frequency), 'fold' (+1),
        or 'none'.
    """

    speed: float
    depth: float
    multiplier: complex
    kind: str


@dataclass(frozen=True)
class _TcpModes:
    """TCP part of a modal plant in the cutting frame: A0 (2m, 2m), B (2m, 2), C (2, 2m)."""

    a0: np.ndarray
    b: np.ndarray
    c: np.ndarray


def _tcp_modes(plant: PlantModel, cut: MillingCut) -> _TcpModes:
    tcp = plant.select(list(TCP_FORCES), list(TCP_DISPLACEMENTS))
    a0, b, c, _ = tcp.state_matrices()
    rot = cut.rotation()
    return _TcpModes(a0, b @ rot, rot.T @ c)


def _interval_forces(cut: MillingCut, intervals: int) -> np.ndarray:
    """Mean specific force matrix ``H_i / K_t`` of every interval of a tooth period, (k, 2, 2)."""
    step = cut.tooth_angle / intervals
    start = np.arange(intervals)[:, None] * step + np.arange(cut.teeth)[None, :] * cut.tooth_angle
    return engaged_integral(cut, start, start + step).sum(axis=1) / step


def monodromy(plant: PlantModel, cut: MillingCut, speed_rpm: float, depth: float,
              intervals: int = 40) -> npt.NDArray[np.float64]:
    """
    Monodromy matrix of one tooth period, (2m + 2k, 2m + 2k).

    Parameters
    ----------
    plant : PlantModel
        Modal plant with the TCP x/y force inputs and displacement outputs.
    cut : MillingCut
        Engagement, force law and feed direction.
    speed_rpm : float
        Spindle speed [rpm], > 0.
    depth : float
        Axial depth of cut [m], >= 0.
    intervals : int
        Intervals k per tooth period (>= 2).
    """
    if not (speed_rpm > 0 and depth >= 0 and intervals >= 2):
        raise ConfigError(f'need speed > 0 rpm, depth >= 0 m and >= 2 intervals; got '
                          f'{speed_rpm!r}, {depth!r}, {intervals!r}')
    return _monodromy(_tcp_modes(plant, cut), _interval_forces(cut, intervals),
                      cut.tangential_coefficient * depth, 60.0 / (cut.teeth * speed_rpm))


def _monodromy(modes: _TcpModes, forces: np.ndarray, gain: float, period: float) -> np.ndarray:
    n_y, k = modes.a0.shape[0], forces.shape[0]
    dt = period / k
    n = n_y + 2 * k
    phi = np.eye(n)
    big = np.zeros((n_y + 4, n_y + 4))
    big[n_y:n_y + 2, n_y + 2:] = np.eye(2)
    for h in forces:
        bh = gain * (modes.b @ h)                          # (2m, 2): a B H_i
        big[:n_y, :n_y] = (modes.a0 + bh @ modes.c) * dt
        big[:n_y, n_y:n_y + 2] = -bh * dt
        e = sla.expm(big)
        p, e12, e13 = e[:n_y, :n_y], e[:n_y, n_y:n_y + 2], e[:n_y, n_y + 2:]
        y, delayed = phi[:n_y], phi[n_y:].reshape(k, 2, n)
        new_y = p @ y + (e12 - e13) @ delayed[k - 1] + e13 @ delayed[k - 2]
        new_r = np.concatenate([(modes.c @ y)[None], delayed[:k - 1]]).reshape(2 * k, n)
        phi = np.vstack([new_y, new_r])
    return phi


def _largest_multiplier(matrix: np.ndarray) -> complex:
    mu = np.linalg.eigvals(matrix)
    return complex(mu[np.argmax(np.abs(mu))])


def spectral_radius(plant: PlantModel, cut: MillingCut, speed_rpm: float, depth: float,
                    intervals: int = 40) -> float:
    """Largest |Floquet multiplier|: the cut is stable below 1."""
    return abs(_largest_multiplier(monodromy(plant, cut, speed_rpm, depth, intervals)))


def multiplier_kind(mu: complex) -> str:
    """'fold' (+1), 'flip' (-1) or 'hopf' (complex) for a Floquet multiplier."""
    angle = abs(math.atan2(mu.imag, mu.real))
    if angle < REAL_ANGLE:
        return 'fold'
    return 'flip' if math.pi - angle < REAL_ANGLE else 'hopf'


def critical_depth(plant: PlantModel, cut: MillingCut, speed_rpm: float, depth_max: float,
                   intervals: int = 40, steps: int = 40,
                   rel_tol: float = 1e-4) -> CriticalDepth:
    """
    Lowest unstable axial depth at one speed: a scan up to ``depth_max``, then bisection.

    Parameters
    ----------
    plant, cut, speed_rpm, intervals
        As :func:`monodromy`.
    depth_max : float
        Largest depth tried [m]; the scan takes ``steps`` even steps up to it, so an unstable
        band narrower than ``depth_max / steps`` below the first one found can be missed.
    steps : int
        Depths of the scan.
    rel_tol : float
        Relative width of the final bisection bracket.
    """
    if not (depth_max > 0 and steps >= 1 and rel_tol > 0):
        raise ConfigError(f'need depth_max > 0 m, steps >= 1 and rel_tol > 0; got '
                          f'{depth_max!r}, {steps!r}, {rel_tol!r}')
    if not speed_rpm > 0 or intervals < 2:
        raise ConfigError(f'need speed > 0 rpm and >= 2 intervals; got {speed_rpm!r}, '
                          f'{intervals!r}')
    modes, forces = _tcp_modes(plant, cut), _interval_forces(cut, intervals)
    period = 60.0 / (cut.teeth * speed_rpm)

    def multiplier(depth: float) -> complex:
        return _largest_multiplier(_monodromy(modes, forces, cut.tangential_coefficient * depth,
                                              period))

    stable, unstable, mu = 0.0, None, 0j
    for depth in depth_max * np.arange(1, steps + 1) / steps:
        mu = multiplier(depth)
        if abs(mu) >= 1.0:
            unstable = float(depth)
            break
        stable = float(depth)
    if unstable is None:
        return CriticalDepth(float(speed_rpm), math.inf, mu, 'none')
    while unstable - stable > rel_tol * unstable:
        middle = 0.5 * (stable + unstable)
        m = multiplier(middle)
        if abs(m) >= 1.0:
            unstable, mu = middle, m
        else:
            stable = middle
    return CriticalDepth(float(speed_rpm), 0.5 * (stable + unstable), mu, multiplier_kind(mu))
