"""
Lobes of a machine with its control laws, and the cutting runs that check them: typed records.

:func:`loop_lobes` takes a plant and the laws of one scenario as the testbed runs them, builds
the sampled loop's TCP FRF (:mod:`pentapod_sim.machining.sampled_tcp`) once and returns, per
milling operation of the machining table, the zero-order stability limit, the lobe envelope on
a speed grid and its summary (minimum stable depth, best pocket): a :class:`LoopLobes`. The
command ``statespace lobes`` and the study's machining section are made of these records.

:func:`check_runs` picks the test of the issue's "done when": a spindle speed where a cutting
node gets a whole number (at least 50) of steps per tooth period and the envelope is lowest,
the predicted limiting depth there, and a run at each factor of it (0.8 and 1.2) whose length
follows from the growth or decay rate of the cut on the sampled loop at that depth, from its
critical Floquet multiplier (:mod:`pentapod_sim.machining.sampled_floquet`; the averaged loop
of :mod:`pentapod_sim.machining.cutting_model` overestimates it where the chatter lies near
half the tooth-passing frequency): :class:`CuttingRun` records with the cutting node's
parameters.

Units: depths [m], speeds [rpm], frequencies [Hz], times [s].
"""
from __future__ import annotations

from dataclasses import dataclass, field
import math
from typing import Any, Sequence

import numpy as np
import numpy.typing as npt

from pentapod_sim.errors import ConfigError
from pentapod_sim.machining.cutting_model import regenerative_controller
from pentapod_sim.machining.cutting_process import CuttingConditions, MIN_STEPS_PER_TOOTH
from pentapod_sim.machining.lobe_plot import LobeSummary, summarise
from pentapod_sim.machining.lobes import LobeEnvelope, milling_limit, StabilityLimit
from pentapod_sim.machining.materials import MachiningTable
from pentapod_sim.machining.sampled_floquet import check_speed, sampled_floquet
from pentapod_sim.machining.sampled_tcp import sampled_tcp_frf, SampledTcpFrf
from pentapod_sim.plant.model import PlantModel
from pentapod_sim.sim.controllers import controller_of, DiscreteController
from pentapod_sim.sim.stability import plant_radius

#: Band [Hz] of the chatter frequencies the lobes consider (the plant's modes of interest).
DEFAULT_BAND = (1.0, 1000.0)
#: e-foldings of the predicted growth a check run above the limit lasts after its settling
#: part. The verdict needs a twofold growth (0.69 e-foldings), but the tool leaving the cut,
#: which the Floquet model leaves out, slows a recorded cut's growth: to 0.29-0.31 of the
#: Floquet rate at P2 with the TCP damper at 3 kHz (833 and 437 rpm), 0.45-0.65 at 5 kHz, so
#: two e-foldings grew 1.8-fold there; three give 2.4-fold at 0.29 (docs/machining.md).
RUN_E_FOLDINGS_GROWTH = 3.0
#: e-foldings of the predicted decay a check run below the limit lasts (the tool leaving the
#: cut speeds the decay: -0.58 against -0.24 1/s on that P2 cut at 0.8x).
RUN_E_FOLDINGS_DECAY = 2.0
#: Fewest tooth periods a check run spans after its settling part (the verdict's growth fit
#: needs 17; a fast rate on a small model would otherwise give too few).
RUN_MIN_TOOTH_PERIODS = 40
#: Speeds of the envelope the check speed is chosen from.
CHECK_SPEEDS = 2000
#: Share of a check run left out as the entry transient (the verdict's default).
RUN_SETTLE_SHARE = 0.25


@dataclass(frozen=True)
class OperationLobes:
    """One operation's lobes on one loop: limit per chatter frequency, envelope, summary."""

    operation: str
    limit: StabilityLimit
    envelope: LobeEnvelope
    summary: LobeSummary

    @property
    def min_depth(self) -> float:
        """Minimum stable depth over all speeds [m]."""
        return self.summary.min_depth


@dataclass(frozen=True)
class LoopLobes:
    """
    The lobes of one scenario (laws) at one position, for every operation asked for.

    Attributes
    ----------
    label, position : str
        Scenario and position.
    loop : SampledTcpFrf
        The sampled loop's TCP FRF (sample time, spectral radius, poles).
    operations : dict of str to OperationLobes
        Per operation of the machining table.
    """

    label: str
    position: str
    loop: SampledTcpFrf
    operations: dict[str, OperationLobes] = field(default_factory=dict)

    def min_depth(self, operation: str) -> float:
        """Minimum stable depth of an operation [m]."""
        return self.operations[operation].min_depth

    def gain_over(self, base: LoopLobes, operation: str) -> float:
        """Stable depth gain: this minimum stable depth over ``base``'s [-]."""
        return self.min_depth(operation) / base.min_depth(operation)


def loop_lobes(plant: PlantModel, laws: Sequence[Any], dt: float, table: MachiningTable,
               operations: Sequence[str], speeds_rpm: npt.ArrayLike, label: str,
               position: str = '', band: tuple[float, float] = DEFAULT_BAND) -> LoopLobes:
    """
    Lobes of ``operations`` on the sampled loop of ``plant`` and ``laws`` (module docstring).

    Parameters
    ----------
    plant : PlantModel
        Continuous plant with the TCP x/y ports and those of the laws.
    laws : sequence
        The scenario's laws sampled with ``dt`` (:func:`pentapod_sim.scenario.laws.
        scenario_loop_laws`); empty for the machine without added damping.
    dt : float
        Sample time [s] of the loop.
    table : MachiningTable
        config/machining.yaml.
    operations : sequence of str
        Operation names of the table.
    speeds_rpm : array_like
        Increasing spindle speeds of the envelope [rpm].
    label, position : str
        Scenario and position (labels of the records and curves).
    band : (float, float)
        Chatter frequencies considered [Hz].

    Raises
    ------
    ConfigError
        If the loop is unstable, a law has no linear model or an operation is unknown.
    """
    loop = sampled_tcp_frf(plant, laws, dt, band[0], band[1], label)
    speeds = np.asarray(speeds_rpm, dtype=float)
    out = {}
    for name in operations:
        limit = milling_limit(loop.frf, table.milling_cut(name), label)
        envelope = limit.envelope(speeds)
        out[name] = OperationLobes(name, limit, envelope, summarise(limit, envelope))
    return LoopLobes(label, position, loop, out)


@dataclass(frozen=True)
class CuttingRun:
    """
    One recorded cutting run that checks a predicted limit.

    Attributes
    ----------
    factor : float
        Depth over the predicted limiting depth at the speed.
    expected : str
        ``'stable'`` below the limit, ``'chatter'`` above.
    params : dict
        Cutting node parameters (operation, spindle_speed [rpm], axial_depth [m]).
    duration : float
        Simulated time [s] of the run.
    settle : float
        Entry transient left out of the verdict [s].
    growth_rate : float
        Growth rate [1/s] of the cut on the sampled loop from its critical Floquet multiplier
        (negative: decay); the run's length follows from it.
    averaged_rate : float
        Growth rate [1/s] of the averaged loop (the cutting node's linear model) at this depth.
    multiplier : complex
        The critical Floquet multiplier (per tooth period).
    kind : str
        'hopf', 'flip' or 'fold'.
    """

    factor: float
    expected: str
    params: dict[str, Any]
    duration: float
    settle: float
    growth_rate: float
    averaged_rate: float = math.nan
    multiplier: complex = complex(math.nan)
    kind: str = ''

    def conditions(self, table: MachiningTable) -> CuttingConditions:
        """The run's cutting conditions (what the cutting node makes of ``params``)."""
        return table.conditions(self.params['operation'], self.params['spindle_speed'],
                                self.params['axial_depth'])


@dataclass(frozen=True)
class CheckPoint:
    """The speed of the check, the predicted limit there and the runs below and above it."""

    operation: str
    speed: float
    depth: float
    chatter_freq: float
    runs: tuple[CuttingRun, ...]

    @property
    def duration(self) -> float:
        """Simulated time of the longest run [s]."""
        return max(run.duration for run in self.runs)


def lobe_bottoms(lobes: OperationLobes, teeth: int, dt: float
                 ) -> list[tuple[float, float, float]]:
    """
    Lobe bottoms a check can run at: (speed [rpm], limiting depth [m], chatter frequency [Hz]).

    The local minima of the envelope, lowest first, between a third of and the highest speed
    whose tooth period spans :data:`pentapod_sim.machining.cutting_process.MIN_STEPS_PER_TOOTH`
    steps of ``dt`` (a factor of three in speed spans whole lobes; the table's speed range may
    lie above it at the sample rate of a run).
    """
    fast = 60.0 / (teeth * MIN_STEPS_PER_TOOTH * dt)
    env = lobes.limit.envelope(np.linspace(fast / 3.0, fast, CHECK_SPEEDS))
    d = env.depth
    inner = np.flatnonzero(np.isfinite(d[1:-1]) & (d[1:-1] <= d[:-2]) & (d[1:-1] < d[2:])) + 1
    if inner.size == 0:
        raise ConfigError(f'{lobes.operation}: no lobe bottom between {fast / 3:.0f} and '
                          f'{fast:.0f} rpm ({MIN_STEPS_PER_TOOTH} steps per tooth period at '
                          f'{1 / dt:g} Hz)')
    inner = inner[np.argsort(d[inner])]
    return [(float(env.speed[i]), float(d[i]), float(env.chatter_freq[i])) for i in inner]


def _averaged_rate(plant: PlantModel, controllers: list[DiscreteController], dt: float,
                   cond: CuttingConditions) -> float:
    """Growth rate [1/s] of the averaged loop (the cutting node's linear model)."""
    radius, _ = plant_radius(plant, [*controllers, regenerative_controller(cond, dt)], dt)
    return math.log(radius) / dt


def run_e_foldings(rate: float) -> float:
    """e-foldings of ``rate`` [1/s] a check run lasts after its settling part."""
    return RUN_E_FOLDINGS_GROWTH if rate > 0 else RUN_E_FOLDINGS_DECAY


def _duration(rate: float, durations: tuple[float, float], tooth_period: float) -> float:
    active = max(run_e_foldings(rate) / max(abs(rate), 1e-9),
                 RUN_MIN_TOOTH_PERIODS * tooth_period)
    return min(max(active / (1.0 - RUN_SETTLE_SHARE), durations[0]), durations[1])


def _point(plant: PlantModel, controllers: list[DiscreteController], dt: float,
           table: MachiningTable, operation: str, speed: float, depth: float, freq: float,
           factors: Sequence[float], averaged: Sequence[float],
           durations: tuple[float, float]) -> CheckPoint:
    """The runs at ``factors`` of ``depth``, each as long as its Floquet rate asks."""
    runs = []
    for factor, averaged_rate in zip(factors, averaged):
        cond = table.conditions(operation, speed, factor * depth)
        floquet = sampled_floquet(plant, controllers, cond, dt)
        duration = _duration(floquet.growth_rate, durations, cond.tooth_period)
        runs.append(CuttingRun(
            factor, 'stable' if factor < 1.0 else 'chatter',
            {'operation': operation, 'spindle_speed': speed, 'axial_depth': factor * depth},
            duration, RUN_SETTLE_SHARE * duration, floquet.growth_rate, averaged_rate,
            floquet.multiplier, floquet.kind))
    return CheckPoint(operation, speed, depth, freq, tuple(runs))


def check_runs(plant: PlantModel, laws: Sequence[Any], dt: float, table: MachiningTable,
               lobes: OperationLobes, factors: Sequence[float] = (0.8, 1.2),
               speed: float | None = None, durations: tuple[float, float] = (0.5, 120.0),
               candidates: int = 8, floquet_candidates: int = 3) -> CheckPoint:
    """
    Cutting runs below and above the predicted limit at one speed (module docstring).

    Every speed is moved to the nearest whole number of steps per tooth period, less 1e-9
    (:func:`pentapod_sim.machining.sampled_floquet.check_speed`; the depth is the limit's
    envelope there), so that the loop with the cut is periodic and its Floquet
    multipliers (:func:`pentapod_sim.machining.sampled_floquet.sampled_floquet`) give each
    run's growth or decay rate with the time-varying directional matrix; a run lasts
    :func:`run_e_foldings` e-foldings of it after the settling share, within ``durations`` (min,
    max) [s]. The speed is chosen among the ``candidates`` lowest lobe bottoms
    (:func:`lobe_bottoms`): the ``floquet_candidates`` whose runs the averaged loop predicts
    shortest get their Floquet rates (about a second each on the machine's loop), and of those
    whose rates have the sign the zero-order limit predicts (decay below, growth above) the
    one with the shortest runs is taken; if none has, the next candidates are tried until one
    has. ``speed`` [rpm] fixes the speed instead.

    Raises
    ------
    ConfigError
        If at no candidate speed the Floquet rates agree with the zero-order prediction (the
        zero-order limit is off by more than the factors there).
    """
    teeth = table.tools[table.operation(lobes.operation).tool].teeth
    controllers = [controller_of(law) for law in laws]
    wanted = [float(speed)] if speed is not None else [
        at for at, _, _ in lobe_bottoms(lobes, teeth, dt)[:candidates]]
    points = []
    for at in dict.fromkeys(check_speed(s, teeth, dt) for s in wanted):
        env = lobes.limit.envelope([at])
        depth, freq = float(env.depth[0]), float(env.chatter_freq[0])
        rates = [_averaged_rate(plant, controllers, dt,
                                table.conditions(lobes.operation, at, f * depth))
                 for f in factors]
        period = 60.0 / (teeth * at)
        points.append((max(_duration(r, durations, period) for r in rates), at, depth, freq,
                       rates))
    best: CheckPoint | None = None
    for tried, (_, at, depth, freq, rates) in enumerate(sorted(points, key=lambda p: p[:2])):
        if tried >= floquet_candidates and best is not None:
            break
        point = _point(plant, controllers, dt, table, lobes.operation, at, depth, freq,
                       factors, rates, durations)
        agrees = all((run.growth_rate > 0) == (run.expected == 'chatter') for run in point.runs)
        if agrees and (best is None or point.duration < best.duration):
            best = point
    if best is None:
        raise ConfigError(f'{lobes.operation}: at none of the speeds tried do the Floquet '
                          f'rates of the cut agree with the zero-order limit at {factors} of it')
    return best
