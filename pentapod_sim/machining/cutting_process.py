"""
Regenerative milling in the time domain: the cutting force each plant step answers.

:class:`CuttingProcess` is a force source of the lockstep plant (the :class:`Law` protocol of
:mod:`pentapod_sim.sim.closed_loop`: TCP x/y displacement in, TCP x/y force out, ``u_k``
answering ``y_k``), so the same object runs offline (:func:`simulate_cut`) and inside a node.
Each step it computes, for every tooth j at the immersion angle ``phi_j = 2 pi n t / 60 +
2 pi j / N``, the chip thickness

    h_j = f_t sin(phi_j) + r(t) . n(phi_j) - sigma(t - T),

where ``sigma`` is the surface the previous tooth left at that angle (in the frame moving with
the nominal feed): ``r . n`` where that tooth cut, else the older surface shifted by one feed
(the tool left the cut: h <= 0 gives no force and no new surface, the nonlinearity that bounds
chatter). The delay T = 60 / (N n) is a ring buffer of past surfaces; its non-integer length
in steps is bridged by linear interpolation between the two neighbouring steps. Forces
(linear edge-force law): ``F_t = K_tc a h + K_te a``, ``F_r = K_rc a h + K_re a`` for every
tooth in the cut, ``F = sum F_t (-cos phi, sin phi) + F_r (-sin phi, -cos phi)`` in the
cutting frame (:mod:`pentapod_sim.machining.milling_cut`), rotated into machine x-y. The helix
is ignored: each tooth engages the whole axial depth at one angle. The workpiece is rigid.
"""
from __future__ import annotations

from dataclasses import dataclass
import math
from typing import Sequence

import numpy as np
import numpy.typing as npt

from pentapod_sim.errors import ConfigError, RunError
from pentapod_sim.machining.milling_cut import MillingCut
from pentapod_sim.machining.tcp_frf import TCP_DISPLACEMENTS, TCP_FORCES
from pentapod_sim.plant.model import PlantModel
from pentapod_sim.sim.closed_loop import Law, simulate
from pentapod_sim.sim.stepping import DiscretePlant

_TWO_PI = 2.0 * math.pi
#: Fewest plant steps per tooth period: below it the delay interpolation and the zero-order
#: hold distort the regenerative phase (and so the stability limit) by several percent.
MIN_STEPS_PER_TOOTH = 50


@dataclass(frozen=True)
class CuttingConditions:
    """
    A milling operation in the time domain.

    Attributes
    ----------
    cut : MillingCut
        Teeth, engagement, feed direction, K_tc (``tangential_coefficient``) and K_rc / K_tc.
    spindle_speed : float
        Spindle speed n [rpm].
    axial_depth : float
        Axial depth of cut a [m].
    feed_per_tooth : float
        Feed per tooth f_t [m].
    edge_tangential, edge_radial : float
        Edge coefficients K_te, K_re [N/m] (they shift the mean force, not the stability).
    """

    cut: MillingCut
    spindle_speed: float
    axial_depth: float
    feed_per_tooth: float
    edge_tangential: float = 0.0
    edge_radial: float = 0.0

    def __post_init__(self) -> None:
        for name, unit in (('spindle_speed', 'rpm'), ('axial_depth', 'm'),
                           ('feed_per_tooth', 'm')):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ConfigError(f'{name} = {value!r} {unit} must be > 0')
        for name in ('edge_tangential', 'edge_radial'):
            if not (math.isfinite(getattr(self, name)) and getattr(self, name) >= 0):
                raise ConfigError(f'{name} = {getattr(self, name)!r} N/m must be >= 0')

    @property
    def tooth_period(self) -> float:
        """T = 60 / (N n) [s]."""
        return 60.0 / (self.cut.teeth * self.spindle_speed)


class CuttingProcess:
    """
    Cutting force of a milling operation, answering the TCP displacement step by step.

    Parameters
    ----------
    conditions : CuttingConditions
        The operation.
    dt : float
        Plant sample time [s]; the tooth period must span >= :data:`MIN_STEPS_PER_TOOTH`.
    record_steps : int
        Keep chip thickness, engagement and force of the first ``record_steps`` steps.

    Attributes
    ----------
    angles, chip, in_cut, tooth_force : (N,) ndarray
        Immersion angle [rad, in 0..2 pi], chip thickness [m], whether each tooth cuts and
        its tangential force ``F_t`` [N] (0 out of the cut), at the last step.
    force : (2,) ndarray
        Force on the TCP in machine x-y [N] at the last step.
    """

    sensor_ports = list(TCP_DISPLACEMENTS)
    actuator_ports = list(TCP_FORCES)

    def __init__(self, conditions: CuttingConditions, dt: float, record_steps: int = 0):
        if not (math.isfinite(dt) and dt > 0):
            raise ConfigError(f'sample time dt = {dt!r} s must be > 0')
        delay = conditions.tooth_period / dt
        if delay < MIN_STEPS_PER_TOOTH * (1 - 1e-9):
            rate = MIN_STEPS_PER_TOOTH / conditions.tooth_period
            raise ConfigError(f'the tooth period {conditions.tooth_period:.4g} s spans only '
                              f'{delay:.1f} plant steps of {dt:g} s; cutting needs >= '
                              f'{MIN_STEPS_PER_TOOTH}: a sample rate of at least {rate:.0f} Hz')
        self.conditions, self.dt = conditions, float(dt)
        cut = conditions.cut
        self._whole, self._frac = int(math.floor(delay)), delay - math.floor(delay)
        self._ring = [[0.0] * cut.teeth for _ in range(self._whole + 2)]
        self._rotation = cut.rotation()
        self._omega = 2 * math.pi * conditions.spindle_speed / 60.0
        self._pitch = [j * cut.tooth_angle for j in range(cut.teeth)]
        self._previous = [(j + 1) % cut.teeth for j in range(cut.teeth)]  # j follows j + 1
        self.record_steps = int(record_steps)
        self.recorded_chip = np.zeros((self.record_steps, cut.teeth))
        self.recorded_in_cut = np.zeros((self.record_steps, cut.teeth), dtype=bool)
        self.recorded_engaged = np.zeros((self.record_steps, cut.teeth), dtype=bool)
        self.recorded_force = np.zeros((self.record_steps, 2))
        self.reset()

    def reset(self) -> None:
        """Back to step 0 with a straight surface left by the previous tooth."""
        self.k = 0
        for row in self._ring:
            row[:] = [0.0] * len(row)
        teeth = self.conditions.cut.teeth
        self.angles = np.mod(np.array(self._pitch), _TWO_PI)
        self.chip, self.in_cut = np.zeros(teeth), np.zeros(teeth, dtype=bool)
        self.tooth_force, self.force = np.zeros(teeth), np.zeros(2)

    def step(self, sensors: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        """Force (x, y) [N] answering the TCP displacement (x, y) [m] of the next step."""
        return self.answer(self.k, sensors)

    def answer(self, k: int, displacement: npt.ArrayLike) -> npt.NDArray[np.float64]:
        """
        Force on the TCP [N] (machine x, y) at step ``k`` from its displacement [m].

        Steps must come in order (0, 1, 2, ...): the ring buffer holds the surfaces of the
        last tooth period. RunError names a step out of order.
        """
        if k != self.k:
            raise RunError(f'cutting process: step {k} answered, expected step {self.k} '
                           '(steps must come in order)')
        cond, cut = self.conditions, self.conditions.cut
        # plain floats per tooth: numpy's per-call cost dominates arrays of 2-6 teeth
        (c_f, s_f), (m_s, m_c) = self._rotation[:, 0], self._rotation[:, 1]
        x, y = (float(v) for v in np.asarray(displacement, dtype=float)[:2])
        r_feed, r_normal = c_f * x + s_f * y, m_s * x + m_c * y      # cutting frame
        ring, size = self._ring, len(self._ring)
        older, newer = ring[(k - self._whole - 1) % size], ring[(k - self._whole) % size]
        row = ring[k % size]
        theta = self._omega * k * self.dt
        feed, depth, frac = cond.feed_per_tooth, cond.axial_depth, self._frac
        k_tc, k_rc = cut.tangential_coefficient, cut.radial_ratio * cut.tangential_coefficient
        f_x = f_y = 0.0
        teeth = cut.teeth
        angles, chips, tangential = [0.0] * teeth, [0.0] * teeth, [0.0] * teeth
        cuts, engaged = [False] * teeth, [False] * teeth
        for j in range(teeth):
            phi = (theta + self._pitch[j]) % _TWO_PI
            sin, cos = math.sin(phi), math.cos(phi)
            before = self._previous[j]
            surface = (1.0 - frac) * newer[before] + frac * older[before]    # sigma(t - T)
            normal = r_feed * sin + r_normal * cos
            chip = feed * sin + normal - surface
            inside = cut.entry_angle <= phi <= cut.exit_angle
            cutting = inside and chip > 0.0
            row[j] = normal if cutting or not inside else surface - feed * sin
            if cutting:
                f_t = depth * (k_tc * chip + cond.edge_tangential)
                f_r = depth * (k_rc * chip + cond.edge_radial)
                f_x -= f_t * cos + f_r * sin
                f_y += f_t * sin - f_r * cos
                tangential[j] = f_t
            angles[j], chips[j], cuts[j], engaged[j] = phi, chip, cutting, inside
        self.angles, self.chip, self.in_cut = (np.array(angles), np.array(chips),
                                               np.array(cuts))
        self.tooth_force = np.array(tangential)
        self.force = np.array([c_f * f_x + m_s * f_y, s_f * f_x + m_c * f_y])
        if k < self.record_steps:
            self.recorded_chip[k], self.recorded_in_cut[k] = chips, cuts
            self.recorded_engaged[k], self.recorded_force[k] = engaged, self.force
        self.k += 1
        return self.force


@dataclass(frozen=True)
class CutRun:
    """
    An offline cutting run.

    Attributes
    ----------
    time : (n,) ndarray
        t_k [s].
    displacement, force : (n, 2) ndarray
        TCP displacement [m] and cutting force on the TCP [N], machine x-y.
    chip : (n, N) ndarray
        Chip thickness per tooth [m] (negative: that tooth is out of the cut).
    in_cut, engaged : (n, N) bool ndarray
        Tooth cutting (engaged with h > 0), tooth within the engaged angles.
    """

    time: np.ndarray
    displacement: np.ndarray
    force: np.ndarray
    chip: np.ndarray
    in_cut: np.ndarray
    engaged: np.ndarray


def simulate_cut(plant: PlantModel, conditions: CuttingConditions, dt: float, duration: float,
                 laws: Sequence[Law] = ()) -> CutRun:
    """
    Step a plant with the cutting process (and optional control laws) from rest.

    The plant is discretised with zero-order hold and stepped by
    :func:`pentapod_sim.sim.closed_loop.simulate`, exactly as the lockstep testbed steps it.

    Parameters
    ----------
    plant : PlantModel
        Continuous plant with the TCP x/y ports (and those of the laws).
    conditions : CuttingConditions
        The operation.
    dt : float
        Sample time [s].
    duration : float
        Simulated time [s].
    laws : sequence of Law
        Further force sources, e.g. dampers (:mod:`pentapod_damper.laws`).
    """
    n_steps = int(round(duration / dt))
    if n_steps < 1:
        raise ConfigError(f'duration {duration!r} s is shorter than one step of {dt!r} s')
    process = CuttingProcess(conditions, dt, record_steps=n_steps)
    discrete = DiscretePlant(plant.discretize(dt))
    response = simulate(discrete, [process, *laws],
                        np.zeros((n_steps, len(discrete.input_names))))
    disp = np.column_stack([response.output(name) for name in TCP_DISPLACEMENTS])
    return CutRun(np.arange(n_steps) * dt, disp, process.recorded_force, process.recorded_chip,
                  process.recorded_in_cut, process.recorded_engaged)
