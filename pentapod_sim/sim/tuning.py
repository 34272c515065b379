"""
Tuning that respects the machine: the best gains of a law family under a machine's constraints.

A design (a family's parameter values, :mod:`pentapod_sim.sim.law_families`) is judged on the
sampled loop of its machine (locked drives or with the feed drives) at the law's sample rate:

* **objective**: the exact TCP peak in the band (``peak``, minimised) or the smallest damping
  ratio of the closed-loop poles in the band that dominate the TCP FRF (``damping``,
  maximised: a pole whose static contribution ``|r| / |1 - l|``, about its mode's dc gain
  whatever its damping, reaches :data:`DOMINANT_SHARE` of the baseline's largest);
* **constraints**: stable on the design plant with the law's delay and with one more sample
  (the law's: the drives' own delay is the machine's and stays); the static TCP compliance at most
  ``static_ratio_limit`` times the machine's without the law; the RMS of every actuator force
  per newton of TCP force (over the band) at most ``effort_limit``; the same stability and
  static limit on every stiffness corner of the :class:`~pentapod_sim.sim.design_models.
  DesignModel`.

:func:`tune` scans a grid (the main gain densely, the other parameters coarsely), refines the
best feasible design by Nelder-Mead in log-parameters, checks it on the check model with and
without the extra delay (scaling the main gain down until both are stable), and keeps every
evaluation for the trade-off curve (:func:`trade_off`: best peak reduction per static
compliance ratio).

Units: compliance m/N, forces N per N, frequencies Hz, sample rate Hz.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
import logging
from typing import Any, Callable, Sequence

import numpy as np
from scipy.optimize import minimize

from pentapod_sim.errors import ConfigError
from pentapod_sim.sim.controllers import DiscreteController, loop_system
from pentapod_sim.sim.design_models import DesignModel
from pentapod_sim.sim.drives import FeedDrives
from pentapod_sim.sim.law_families import Family, MACHINES
from pentapod_sim.sim.law_models import Dynamics
from pentapod_sim.sim.loop_frf import LinearPlant, PairFrf, SampledLoop, static_gain

LOG = logging.getLogger(__name__)
OBJECTIVES = ('peak', 'damping')
#: A closed-loop pole dominates the TCP FRF if its static contribution reaches this share of
#: the baseline's largest.
DOMINANT_SHARE = 0.05


@dataclass(frozen=True)
class TuneSettings:
    """What a design is judged by (see the module docstring); SI units, Hz."""

    sample_rate: float = 5000.0
    direction: str = 'x'
    objective: str = 'peak'
    static_ratio_limit: float = 1.1
    effort_limit: float = 10.0
    band: tuple[float, float] = (2.0, 400.0)
    machine: str = 'locked'
    struts: tuple[int, ...] = (1, 2, 3, 4, 5)
    dynamics: Dynamics = Dynamics(delay_steps=1)
    extra_delay: int = 1
    grid_points: int = 4
    gain_points: int = 9
    refine_iterations: int = 40

    def __post_init__(self) -> None:
        if self.objective not in OBJECTIVES:
            raise ConfigError(f'objective must be one of {OBJECTIVES}, got {self.objective!r}')
        if self.machine not in MACHINES:
            raise ConfigError(f'machine must be one of {MACHINES}, got {self.machine!r}')
        if self.direction not in ('x', 'y', 'z'):
            raise ConfigError(f'direction must be x, y or z, got {self.direction!r}')
        for name in ('sample_rate', 'static_ratio_limit', 'effort_limit'):
            if not getattr(self, name) > 0:
                raise ConfigError(f'{name} must be > 0, got {getattr(self, name)!r}')

    @property
    def dt(self) -> float:
        """Sample time [s]."""
        return 1.0 / self.sample_rate

    @property
    def pair(self) -> tuple[str, str]:
        """(TCP displacement, TCP force) of the direction."""
        return f'tcp_displacement_{self.direction}', f'tcp_force_{self.direction}'


@dataclass
class Evaluation:
    """One design and what it gives; NaN where not computed (an unstable loop)."""

    values: dict[str, float]
    radius: float = np.nan
    radius_extra: float = np.nan
    corner_radius: float = np.nan
    static_ratio: float = np.nan
    peak: float = np.nan
    peak_hz: float = np.nan
    rms: float = np.nan
    effort_rms: float = np.nan
    min_zeta: float = np.nan
    feasible: bool = False
    reason: str = ''

    def objective(self, kind: str) -> float:
        """Value to minimise (inf when infeasible)."""
        if not self.feasible:
            return np.inf
        return self.peak if kind == 'peak' else -self.min_zeta


@dataclass
class Baseline:
    """The machine without the law: its TCP peak, RMS, static compliance, poles' peak terms."""

    peak: float
    peak_hz: float
    rms: float
    static: float
    largest_term: float
    corner_static: dict[str, float] = field(default_factory=dict)


def _flatten(laws: Sequence[Any], dt: float | None) -> list[DiscreteController]:
    out: list[DiscreteController] = []
    for law in laws:
        model = law.discrete(dt) if dt is not None else law.continuous()
        out += model if isinstance(model, list) else [model]
    return out


class Judge:
    """Evaluates designs of one family on one position's models (see module docstring)."""

    def __init__(self, model: DesignModel, family: Family, settings: TuneSettings,
                 target_hz: float | None = None) -> None:
        if family.machine == 'drives' and settings.machine == 'locked':
            settings = replace(settings, machine='drives')
        self.model, self.family, self.settings = model, family, settings
        self._machines: dict[str, LinearPlant] = {}
        self.baseline = self._baseline()
        self.target_hz = self.baseline.peak_hz if target_hz is None else target_hz

    def machine(self, corner: str | None = None, check: bool = False) -> LinearPlant:
        """The plant a loop runs on: nominal, a corner or the check model, with drives or not."""
        key = 'check' if check else (corner or '')
        if key not in self._machines:
            if self.settings.machine == 'drives':
                self._machines[key] = self.model.with_drives(key)
            else:
                modal = (self.model.check if check else
                         self.model.corners[corner] if corner else self.model.plant)
                if modal is None:
                    raise ConfigError(f'{self.model.position}: no check model was built')
                self._machines[key] = modal
        return self._machines[key]

    def context(self, extra: int) -> dict[str, Any]:
        dyn = self.settings.dynamics
        # the extra delay is the law's: the drives are the machine and keep theirs
        return {'dynamics': dyn.with_delay(dyn.delay_steps + extra), 'drives': self.model.drives,
                'stiffness': self.model.stiffness, 'target_hz': getattr(self, 'target_hz', 0),
                'dt': self.settings.dt, 'extra': extra}

    def controllers(self, values: dict[str, float] | None, extra: int = 0,
                    struts: Sequence[int] | None = None) -> list[DiscreteController]:
        """Discrete controllers of a design (None: the baseline), the drives' included."""
        ctx = self.context(extra)
        laws = ([] if values is None else
                self.family.laws(values, struts or self.settings.struts, ctx))
        if self.settings.machine == 'drives' and (values is None
                                                  or self.family.machine != 'drives'):
            laws = [FeedDrives(ctx['drives'])] + laws
        return _flatten(laws, self.settings.dt)

    def _baseline(self) -> Baseline:
        out, inp = self.settings.pair
        loop = SampledLoop(self.machine(), self.controllers(None), self.settings.dt)
        frf = loop.output(out, inp)
        peak = frf.peak(*self.settings.band)
        terms = _dc_terms(frf)
        corner_static = {name: static_gain(self.machine(name), self.controllers(None),
                                           self.settings.dt, out, inp)
                         for name in self.model.corners}
        return Baseline(peak.value, peak.freq_hz, frf.rms(*self.settings.band),
                        loop.static(out, inp), float(terms.max(initial=0.0)), corner_static)

    def radius(self, controllers: list[DiscreteController], corner: str | None = None,
               check: bool = False) -> float:
        """Spectral radius of the sampled loop on a machine."""
        plant = self.machine(corner, check)
        a, b, c, d = plant.discrete_matrices(self.settings.dt)
        loop = loop_system(a, b, c, d, plant.input_names, plant.output_names, controllers)
        return float(np.abs(np.linalg.eigvals(loop.a)).max())

    def evaluate(self, values: dict[str, float], struts: Sequence[int] | None = None,
                 robust: bool = True) -> Evaluation:
        """Objective and constraints of one design (``robust``: the corners and extra delay)."""
        s, ev = self.settings, Evaluation(dict(values))
        out, inp = s.pair
        ctrls = self.controllers(values, 0, struts)
        ev.radius = self.radius(ctrls)
        if not ev.radius < 1.0:
            ev.reason = 'unstable'
            return ev
        try:
            loop = SampledLoop(self.machine(), ctrls, s.dt)
        except ConfigError as err:          # a (nearly) defective loop: no pole-residue form
            ev.reason = str(err)
            return ev
        frf = loop.output(out, inp)
        peak = frf.peak(*s.band)
        ev.peak, ev.peak_hz, ev.rms = peak.value, peak.freq_hz, frf.rms(*s.band)
        ev.static_ratio = loop.static(out, inp) / self.baseline.static
        ev.min_zeta = self._min_zeta(frf)
        actuators = [p for c in ctrls for p in c.actuator_ports]
        ev.effort_rms = max(loop.effort(p, inp).rms(*s.band) for p in dict.fromkeys(actuators))
        if robust:
            ev.radius_extra = self.radius(self.controllers(values, s.extra_delay, struts))
            worst = ([self.radius(ctrls, corner) for corner in self.model.corners]
                     if ev.radius_extra < 1.0 else [np.nan])
            ev.corner_radius = max(worst, default=0.0)       # 0: no corners to check
            for corner in self.model.corners:
                static = static_gain(self.machine(corner), ctrls, s.dt, out, inp)
                ev.static_ratio = max(ev.static_ratio,
                                      static / self.baseline.corner_static[corner])
        ev.feasible, ev.reason = self._verdict(ev, robust)
        return ev

    def _min_zeta(self, frf: PairFrf) -> float:
        """Smallest damping ratio of the poles in the band that dominate the TCP FRF."""
        poles, terms = frf.poles, _dc_terms(frf)
        lo, hi = (2 * np.pi * f for f in self.settings.band)
        inside = (np.abs(poles) >= lo) & (np.abs(poles) <= hi) & (poles.imag > 0)
        dominant = inside & (terms >= DOMINANT_SHARE * self.baseline.largest_term)
        with np.errstate(invalid='ignore', divide='ignore'):
            zeta = -poles.real / np.abs(poles)
        return float(zeta[dominant].min(initial=1.0))

    def _verdict(self, ev: Evaluation, robust: bool) -> tuple[bool, str]:
        s = self.settings
        if robust and not ev.radius_extra < 1.0:
            return False, f'unstable with {s.extra_delay} more sample(s) of delay'
        if robust and not ev.corner_radius < 1.0:
            return False, 'unstable at a stiffness corner'
        if not ev.static_ratio <= s.static_ratio_limit:
            return False, f'static compliance x{ev.static_ratio:.3g}'
        if not ev.effort_rms <= s.effort_limit:
            return False, f'actuator force {ev.effort_rms:.3g} N/N RMS'
        return True, ''

    def check(self, values: dict[str, float], both: bool = True) -> tuple[float, float]:
        """
        Spectral radius on the check model with the law's delay and with one more sample.

        Without ``both`` the first is NaN when the second is already >= 1 (the harder case
        decides, and each costs an eigenvalue problem of thousands of states).
        """
        extra = self.radius(self.controllers(values, self.settings.extra_delay), check=True)
        if not both and not extra < 1.0:
            return float('nan'), extra
        return self.radius(self.controllers(values, 0), check=True), extra


def _dc_terms(frf: PairFrf) -> np.ndarray:
    """
    Each pole's static contribution ``|r| / |1 - l|`` to a sampled pair FRF.

    About the modal dc gain ``|c b| / (2 omega^2)`` of its mode whatever its damping, so a
    mode that a law damps still counts as one that dominates the TCP (the peak term
    ``|r| / (1 - |l|)`` would drop it).
    """
    with np.errstate(divide='ignore', invalid='ignore'):
        return np.abs(frf.r) / np.abs(1.0 - frf.lam)


@dataclass
class TuneResult:
    """The optimum of a family at a position and every design evaluated on the way."""

    family: str
    position: str
    settings: TuneSettings
    baseline: Baseline
    best: Evaluation | None
    check_radius: tuple[float, float] = (np.nan, np.nan)
    evaluations: list[Evaluation] = field(default_factory=list)
    gain_scale: float = 1.0

    @property
    def peak_reduction(self) -> float:
        """Baseline peak over the optimum's (NaN without a feasible design)."""
        return self.baseline.peak / self.best.peak if self.best else np.nan


def _log_values(family: Family, x: np.ndarray) -> dict[str, float]:
    out = {}
    for p, v in zip(family.parameters, x):
        value = float(np.exp(v)) if p.log else float(v)
        out[p.name] = float(np.clip(value, p.lower, p.upper))
    return out


def _to_x(family: Family, values: dict[str, float]) -> np.ndarray:
    return np.array([np.log(values[p.name]) if p.log else values[p.name]
                     for p in family.parameters])


def tune(judge: Judge, progress: Callable[[str], None] | None = None) -> TuneResult:
    """Grid scan, Nelder-Mead refinement and check-model verification (module docstring)."""
    say = progress or (lambda msg: LOG.info('%s', msg))
    s, fam = judge.settings, judge.family
    grids = [p.grid(s.gain_points if k == 0 else s.grid_points)
             for k, p in enumerate(fam.parameters)]
    evaluations: list[Evaluation] = []
    for combo in np.array(np.meshgrid(*grids, indexing='ij')).reshape(len(grids), -1).T:
        evaluations.append(judge.evaluate(dict(zip([p.name for p in fam.parameters], combo))))
    say(f'{judge.model.position} {fam.name}: {len(evaluations)} grid designs, '
        f'{sum(e.feasible for e in evaluations)} feasible')
    feasible = [e for e in evaluations if e.feasible]
    best = min(feasible, key=lambda e: e.objective(s.objective), default=None)
    if best is not None and s.refine_iterations:
        def cost(x: np.ndarray) -> float:
            ev = judge.evaluate(_log_values(fam, x))
            evaluations.append(ev)
            return ev.objective(s.objective)
        minimize(cost, _to_x(fam, best.values), method='Nelder-Mead',
                 options={'maxiter': s.refine_iterations, 'xatol': 1e-3, 'fatol': 0.0})
        best = min((e for e in evaluations if e.feasible),
                   key=lambda e: e.objective(s.objective))
    result = TuneResult(fam.name, judge.model.position, s, judge.baseline, best,
                        evaluations=evaluations)
    if best is not None and judge.model.check is not None:
        _verify(judge, result, say)
    return result


def _verify(judge: Judge, result: TuneResult, say: Callable[[str], None]) -> None:
    """Scale the main gain down until the check model is stable with and without extra delay."""
    main = judge.family.parameters[0]
    if result.best is None:
        return
    values = dict(result.best.values)
    for attempt in range(10):
        radii = judge.check(values, both=False)
        say(f'{judge.model.position} {judge.family.name}: check model radius {radii[0]:.6f} / '
            f'{radii[1]:.6f} (extra delay) at {main.name} = {values[main.name]:.4g}')
        if radii[0] < 1.0 and radii[1] < 1.0:
            break
        values[main.name] *= 0.7
        result.gain_scale *= 0.7
    result.check_radius = radii
    if result.gain_scale != 1.0:
        result.best = judge.evaluate(values)


def trade_off(result: TuneResult) -> list[tuple[float, float, dict[str, float]]]:
    """
    (static compliance ratio, peak reduction, values) of the designs on the Pareto front.

    Every design that is stable (also with the extra delay and at the corners) and within the
    actuator force limit counts, whatever its static compliance.
    """
    limit = result.settings.effort_limit
    points = sorted(((e.static_ratio, result.baseline.peak / e.peak, e.values)
                     for e in result.evaluations
                     if e.radius < 1 and e.radius_extra < 1 and not e.corner_radius >= 1
                     and e.effort_rms <= limit and np.isfinite(e.static_ratio)),
                    key=lambda p: (p[0], -p[1]))
    front: list[tuple[float, float, dict[str, float]]] = []
    for point in points:
        if not front or point[1] > front[-1][1]:
            front.append(point)
    return front
