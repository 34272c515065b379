"""
Growth rate of a cut on the sampled loop, with the time-varying directional matrix: Floquet.

The averaged loop (:mod:`pentapod_sim.machining.cutting_model`) keeps the tooth-period mean of
the cutting force's directional matrix; its eigenvalues give the zero-order limit, and near it
they also give a growth rate. That rate can be far off: where the chatter frequency lies near
half the tooth-passing frequency, the varying part of the matrix couples the vibration at
``f_c`` with its image at ``f_tooth - f_c``, both inside the same resonance, and the averaged
loop misses the coupling (measured on the machine with the TCP damper at P2: +0.28 1/s
averaged against +0.14 1/s here at 1.2x of the limit, docs/machining.md).

This module linearises the cutting process exactly as the lockstep loop runs it: at step k the
force is ``K_k (r_k - r_{k-m})`` with ``K_k = a K_t R (sum_j g_j f(phi_j) n(phi_j)^T) R^T``, the
teeth at their angles of step k (:class:`~pentapod_sim.machining.cutting_process.
CuttingProcess`), every engaged tooth cutting. With a tooth period of a whole number m of
steps the loop of plant, laws and cut is m-periodic; the product of its m step matrices is the
monodromy matrix, and its eigenvalues (Floquet multipliers) give the growth rate
``ln |mu| / T`` and the kind of the instability (complex: Hopf; -1: flip, period doubling).
It is the discrete-time counterpart of :mod:`pentapod_sim.machining.semi_discretisation` for
the loop with the scenario's laws. What it leaves out: the tool leaving the cut (in down
milling the chip vanishes at the exit angle, so any vibration cuts the engaged arc short and
lowers the growth of a recorded cut a little: 0.078 against 0.107 1/s on the run above).
Units: SI, speeds in rpm, rates in 1/s.
"""
from __future__ import annotations

from dataclasses import dataclass
import math
from typing import Sequence

import numpy as np

from pentapod_sim.errors import ConfigError
from pentapod_sim.machining.cutting_model import delay_controller
from pentapod_sim.machining.cutting_process import CuttingConditions, MIN_STEPS_PER_TOOTH
from pentapod_sim.machining.milling_cut import chip_direction, force_direction
from pentapod_sim.machining.semi_discretisation import multiplier_kind
from pentapod_sim.plant.model import PlantModel
from pentapod_sim.sim.controllers import DiscreteController, loop_matrix

#: A tooth period within this many steps of a whole number counts as whole.
WHOLE_STEPS_TOLERANCE = 1e-6
#: Relative amount a check speed lies below a whole number of steps per tooth period.
OFF_GRID = 1e-9


@dataclass(frozen=True)
class SampledFloquet:
    """
    The critical Floquet multiplier of a cut on the sampled loop.

    Attributes
    ----------
    multiplier : complex
        The multiplier of largest modulus.
    growth_rate : float
        ``ln |multiplier| / T`` [1/s] (negative: the cut's vibration decays).
    kind : str
        'hopf', 'flip' or 'fold' (:func:`pentapod_sim.machining.semi_discretisation.
        multiplier_kind`).
    frequency : float
        Chatter frequency [Hz] in ``[0, f_tooth / 2]`` the multiplier's angle stands for (its
        images lie at ``k f_tooth +- frequency``).
    """

    multiplier: complex
    growth_rate: float
    kind: str
    frequency: float


def whole_step_speed(speed_rpm: float, teeth: int, dt: float) -> float:
    """
    The speed [rpm] nearest to ``speed_rpm`` with a whole number of steps per tooth period.

    At least :data:`~pentapod_sim.machining.cutting_process.MIN_STEPS_PER_TOOTH` steps.
    """
    steps = max(round(60.0 / (teeth * speed_rpm * dt)), MIN_STEPS_PER_TOOTH)
    return 60.0 / (teeth * steps * dt)


def check_speed(speed_rpm: float, teeth: int, dt: float) -> float:
    """
    :func:`whole_step_speed` lowered by :data:`OFF_GRID` (relative): the speed of a check run.

    At a whole number m of steps per tooth period (four teeth: N m steps per revolution) the
    entry and exit angles of a half-immersion cut fall on samples, and the rounding of the
    tooth angle then decides irregularly whether a tooth cuts there: a non-periodic
    disturbance that keeps the once-per-tooth samples of a stable cut from settling (measured:
    a 0.8x cut whose spread decays at -0.66 1/s off the grid decays at -0.06 1/s or even grows
    on it). Lowered by 1e-9 the angle lies just before every such sample, on the same side
    for the whole run (the drift, 1e-9 of the angle turned, stays far below a step), while the
    Floquet analysis sees the same periodic loop.
    """
    return whole_step_speed(speed_rpm, teeth, dt) * (1.0 - OFF_GRID)


def step_stiffness(conditions: CuttingConditions, dt: float, steps: int) -> np.ndarray:
    """``K_k`` (steps, 2, 2) [N/m] in machine x-y, k = 0 .. steps - 1 (module docstring)."""
    cut = conditions.cut
    omega = 2.0 * math.pi * conditions.spindle_speed / 60.0
    phi = np.mod(omega * dt * np.arange(steps)[:, None]
                 + cut.tooth_angle * np.arange(cut.teeth)[None, :], 2.0 * math.pi)
    engaged = ((phi >= cut.entry_angle) & (phi <= cut.exit_angle)).astype(float)
    specific = np.einsum('kj,kji,kjl->kil', engaged, force_direction(phi, cut.radial_ratio),
                         chip_direction(phi))
    rot = cut.rotation()
    return conditions.axial_depth * cut.tangential_coefficient * rot @ specific @ rot.T


def sampled_floquet(plant: PlantModel, controllers: Sequence[DiscreteController],
                    conditions: CuttingConditions, dt: float) -> SampledFloquet:
    """
    Critical Floquet multiplier of ``plant`` with ``controllers`` and the cut (module docstring).

    Parameters
    ----------
    plant : PlantModel
        Continuous plant with the TCP x/y ports (and those of the controllers).
    controllers : sequence of DiscreteController
        The scenario's laws (:func:`pentapod_sim.sim.controllers.controller_of`).
    conditions : CuttingConditions
        The cut; its tooth period must be a whole number of steps (:func:`whole_step_speed`).
    dt : float
        Sample time [s].

    Raises
    ------
    ConfigError
        If the tooth period is not a whole number of steps of ``dt``.
    """
    delay = conditions.tooth_period / dt
    steps = int(round(delay))
    if abs(delay - steps) > WHOLE_STEPS_TOLERANCE or steps < 1:
        nearest = whole_step_speed(conditions.spindle_speed, conditions.cut.teeth, dt)
        raise ConfigError(f'the tooth period spans {delay:.6f} steps of {dt:g} s; the Floquet '
                          f'multipliers need a whole number (spindle speed {nearest:.6g} rpm)')
    a, b, c, d = plant.discrete_matrices(dt)

    def loop(stiffness: np.ndarray) -> np.ndarray:
        return loop_matrix(a, b, c, d, plant.input_names, plant.output_names,
                           [*controllers, delay_controller(stiffness, steps)])

    period = _monodromy(loop(np.zeros((2, 2))),
                        [[loop(np.outer(np.eye(2)[i], np.eye(2)[j])) for j in range(2)]
                         for i in range(2)], step_stiffness(conditions, dt, steps))
    mu = np.linalg.eigvals(period)
    top = complex(mu[np.argmax(np.abs(mu))])
    time = steps * dt
    return SampledFloquet(top, math.log(abs(top)) / time, multiplier_kind(top),
                          abs(math.atan2(top.imag, top.real)) / (2.0 * math.pi * time))


def _monodromy(free: np.ndarray, unit: list[list[np.ndarray]],
               stiffness: np.ndarray) -> np.ndarray:
    """
    Product of the step matrices ``A_k = A_0 + U K_k V`` over one period.

    The loop matrix is affine in the cut's stiffness: ``free`` is ``A_0`` (K = 0) and
    ``unit[i][j]`` the loop with ``K = e_i e_j^T``, so ``unit[i][j] - A_0 = U[:, i] V[j]``
    (the force's input columns times the regenerative chip's read-out). The product is taken
    row block by row block: rows of ``A_0`` that copy one state (the delay line's shift) are
    copies, the others a product over the columns they read, which is several times cheaper
    than the dense product of every step.
    """
    if any(m.shape != free.shape for row in unit for m in row):
        raise ConfigError('the loop with the cut changes its state with the stiffness')
    delta = [[unit[i][j] - free for j in range(2)] for i in range(2)]
    top = np.unravel_index(np.argmax(np.abs(delta[0][0])), free.shape)
    u0 = delta[0][0][:, top[1]]                      # a column of the rank-one term
    v0 = delta[0][0][top[0]] / u0[top[0]]
    u = np.column_stack([u0, delta[1][0] @ v0 / (v0 @ v0)])
    v = np.vstack([v0, u0 @ delta[0][1] / (u0 @ u0)])
    if not all(np.allclose(u[:, i, None] * v[j], delta[i][j], rtol=0,
                           atol=1e-9 * max(np.abs(delta[i][j]).max(), 1e-300))
               for i in range(2) for j in range(2)):
        raise ConfigError('the loop is not affine in the cutting stiffness (rank-one terms)')
    nonzero = free != 0
    copy = (nonzero.sum(axis=1) == 1) & np.isclose(free.max(axis=1), 1.0, rtol=0, atol=0)
    copy_from = np.argmax(nonzero, axis=1)[copy]
    rows = np.flatnonzero(~copy)
    cols = np.flatnonzero(nonzero[rows].any(axis=0))
    block = free[np.ix_(rows, cols)]
    n = free.shape[0]
    phi = np.eye(n)
    for k in stiffness:
        new = np.empty_like(phi)
        new[copy] = phi[copy_from]
        new[rows] = block @ phi[cols]
        new += u @ (k @ (v @ phi))
        phi = new
    return phi
