"""
The regenerative cutting loop as a linear model: what the plant's truncation check can check.

Linearised about the steady cut (every tooth keeps cutting) and averaged over a tooth period,
the dynamic part of the cutting force on the TCP is the zero-order model of Altintas & Budak:

    F_k = a N K_t / (4 pi) R [alpha] R^T (r_k - r(t_k - T)),

``[alpha]`` the directional factors
(:func:`pentapod_sim.machining.milling_cut.directional_factors`), ``R`` the rotation of the
cutting frame into machine x-y and ``r(t_k - T)`` interpolated linearly between the two steps
around one tooth period ago, exactly as
:class:`pentapod_sim.machining.cutting_process.CuttingProcess` does. As a
:class:`pentapod_sim.sim.controllers.DiscreteController` it is a delay line of the TCP
displacement, ``2 (m + 1)`` states for a tooth period of m whole steps, and an exact
representation of the delay (no Pade approximation).

The sampled loop of the plant with this model is stable exactly when the averaged cut is
stable at this depth (the zero-order lobes of the sampled TCP FRF, up to the interpolation of
the delay), so the plant's start-up check says whether the cut would chatter on the plant and
whether modes the plant leaves out would chatter. What it cannot say: the effect of the
time-varying directional matrix (period-doubling lobes of low radial immersion and few teeth:
:mod:`pentapod_sim.machining.semi_discretisation`), the tool leaving the cut (the nonlinearity
that bounds the vibration of an unstable cut: an "unstable" verdict means chatter, not a
vibration growing without bound), the static cutting force (it does not change stability),
edge forces, process damping and the helix.
"""
from __future__ import annotations

import math

import numpy as np

from pentapod_sim.errors import ConfigError
from pentapod_sim.machining.cutting_process import CuttingConditions
from pentapod_sim.machining.milling_cut import directional_factors
from pentapod_sim.machining.tcp_frf import TCP_DISPLACEMENTS, TCP_FORCES
from pentapod_sim.sim.controllers import DiscreteController

#: Longest tooth period [steps] offered as a linear model: the JSON text of the model message
#: grows with the square of the states (2 (m + 1); 250 steps: 502 states, about 1.3 MB).
MAX_MODEL_DELAY_STEPS = 250


def averaged_stiffness(conditions: CuttingConditions) -> np.ndarray:
    """``a N K_t / (4 pi) R [alpha] R^T`` (2, 2) [N/m]: mean force per regenerative chip."""
    cut = conditions.cut
    rot = cut.rotation()
    gain = conditions.axial_depth * cut.teeth * cut.tangential_coefficient / (4.0 * math.pi)
    return gain * rot @ directional_factors(cut) @ rot.T


def regenerative_controller(conditions: CuttingConditions, dt: float) -> DiscreteController:
    """
    The averaged regenerative loop on the TCP ports (module docstring).

    Sensors ``tcp_displacement_{x,y}`` [m], actuators ``tcp_force_{x,y}`` [N]; the state holds
    the displacements of the last m + 1 steps.

    Raises
    ------
    ConfigError
        If the tooth period spans more than :data:`MAX_MODEL_DELAY_STEPS` steps (the message
        would be too large; the reason becomes the source's ``no linear model`` text).
    """
    return delay_controller(averaged_stiffness(conditions), conditions.tooth_period / dt)


def delay_controller(stiffness: np.ndarray, delay: float) -> DiscreteController:
    """
    ``F_k = K (r_k - r(t_k - T))`` on the TCP ports, ``T = delay`` steps (any real >= 0).

    ``K`` (2, 2) [N/m] in machine x-y; ``r(t_k - T)`` interpolated linearly between the two
    steps around it, as the cutting process does. ConfigError beyond
    :data:`MAX_MODEL_DELAY_STEPS` whole steps.
    """
    whole = int(math.floor(delay))
    frac = delay - whole
    if whole > MAX_MODEL_DELAY_STEPS:
        raise ConfigError(f'the tooth period spans {whole} steps; the linear model of the '
                          f'regenerative delay is offered up to {MAX_MODEL_DELAY_STEPS} steps '
                          f'({2 * (MAX_MODEL_DELAY_STEPS + 1)} states)')
    k = np.asarray(stiffness, dtype=float)
    n = 2 * (whole + 1)                 # state block i: r_{k-1-i}, i = 0..m
    a = np.zeros((n, n))
    a[2:, :-2] = np.eye(n - 2)          # shift by one step
    b = np.zeros((n, 2))
    b[:2] = np.eye(2)
    c = np.zeros((2, n))
    # r(t_k - T) = (1 - frac) r_{k-m} + frac r_{k-m-1}: blocks m - 1 and m (r_k itself if m = 0)
    if whole >= 1:
        c[:, 2 * (whole - 1):2 * whole] = -(1.0 - frac) * k
        d = k.copy()
    else:
        d = k * frac
    c[:, 2 * whole:2 * whole + 2] += -frac * k
    return DiscreteController(TCP_DISPLACEMENTS, TCP_FORCES, a, b, c, d)
