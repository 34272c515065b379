"""
What the dampers' actuator/sensor dynamics buy (truncation check) and cost (damping).

For every damping scenario with viscous dampers and every position, the sampled loop at the
study's sample rate is built twice: as the scenario file configures it (the *buildable*
default: gain, low-pass and delay of its damper nodes) and as the *ideal* sampled damper (the
node's default gain, :class:`pentapod_damper.node_parameters.DamperParams`, the paper's or the
best value of the gain sweep, with no dynamics: u_k answers y_k through a zero-order hold).
Each is checked on the plant and on the check model
(:func:`pentapod_sim.sim.stability.check_loop`), and its exact TCP peak reduction is computed
(:class:`pentapod_damper.study.analytic.SampledPairFrf`, searched at the resonances) against the
exact open-loop peak. A scenario whose plant steps the feed drives (its ``drives``) is
modelled with their rotors (:func:`pentapod_sim.scenario.laws.scenario_drives`): plant and
check model with the rotors, the scenario's other laws (the drives' cascade) closed in both
variants as the file sets them; the reference peak stays the locked machine's open loop (so
the reduction includes the drives' own). ``--try order,bandwidth_hz,delay_steps`` replaces
the scenario's dynamics to compare candidates; ``--markdown`` prints the table of
docs/statespace.md ("Default dynamics per damper type"), which test/test_damper_dynamics.py
checks against this code.

    python -m pentapod_damper.study dynamics [--positions P1,P2] [--scenarios a,b]
                                             [--try 1,150,0] [--markdown]

Units: frequencies [Hz], peaks [m/N], gains as the laws'.
"""
from __future__ import annotations

from dataclasses import dataclass
import math
from pathlib import Path
from typing import Any, Sequence

from pentapod_damper.laws import Dynamics, ViscousDamper
from pentapod_damper.node_parameters import DamperParams, DynamicsParams
from pentapod_damper.scenario_laws import scenario_laws
from pentapod_damper.study.analytic import SampledPairFrf
from pentapod_damper.study.config import load_study_config
from pentapod_sim.errors import ConfigError
from pentapod_sim.plant.build import load_or_build_model
from pentapod_sim.plant.check_model import check_f_max, load_or_build_check_model
from pentapod_sim.plant.drives import DriveSet, with_drives
from pentapod_sim.plant.frf_peaks import exact_peak, maximise_near_poles, plant_pair_frf
from pentapod_sim.plant.model import PlantModel
from pentapod_sim.scenario.files import executable_of, read_scenario
from pentapod_sim.scenario.laws import scenario_drives
from pentapod_sim.sim.controllers import controller_of
from pentapod_sim.sim.stability import check_loop

#: Scenarios with viscous damper nodes that the study runs.
SCENARIOS = ('strut_damping_all', 'strut_damping_12', 'strut_chord_damping_all',
             'strut_chord_damping_12', 'axial_damping', 'tcp_damping')


#: Damper node parameters that set its gains and dynamics (from the node's table); the ideal
#: variant drops them, so the node's defaults apply.
_LAW_KEYS = frozenset([p.name for p in DynamicsParams.ros_params()]
                      + [p.name for p in DamperParams.ros_params() if p.name.endswith('_gain')])


@dataclass(frozen=True)
class DamperVariant:
    """
    One scenario's dampers at one position, as shipped (``buildable``) or ``ideal``.

    ``gain`` is the largest gain [N s/m, N m s/rad if ``moment``], then the law's dynamics;
    the spectral radii of the sampled loop on the plant and on the check model, the verdict
    of the truncation check and the exact TCP peak reduction (NaN if the loop is unstable on
    the plant).
    """

    position: str
    scenario: str
    variant: str
    gain: float
    moment: bool
    filter_order: int
    bandwidth_hz: float
    delay_steps: int
    plant_radius: float
    check_radius: float
    verdict: str
    peak_reduction: float


def ideal_laws(scenario: str, dt: float) -> list[ViscousDamper]:
    """The scenario's viscous dampers with the node's default gains and no dynamics."""
    sections = {name: {k: v for k, v in params.items() if k not in _LAW_KEYS}
                if executable_of(name) == 'damper' else params
                for name, params in read_scenario(scenario).sections.items()}
    return [law for law in scenario_laws(sections, dt) if isinstance(law, ViscousDamper)]


def _with(laws: Sequence[ViscousDamper], dyn: Dynamics, dt: float) -> list[ViscousDamper]:
    return [ViscousDamper(law.actuator_ports, [float(g) for g in law.gains], dyn, dt)
            for law in laws]


def evaluate(plant: PlantModel, check: PlantModel, laws: Sequence[Any], dt: float,
             direction: str, band: tuple[float, float],
             base_peak: float, drives: DriveSet | None = None) -> tuple[float, float, str, float]:
    """
    Spectral radii (plant, check model), verdict and exact peak reduction of some laws.

    ``drives``: the feed drives the plant steps (plant and check model with their rotors).
    """
    loop = check_loop(plant, check, [controller_of(law) for law in laws], dt, 'warn',
                      drives=drives)
    reduction = math.nan
    if loop.plant_radius < 1.0:
        frf = SampledPairFrf(with_drives(plant, drives), laws, dt, f'tcp_displacement_{direction}',
                             f'tcp_force_{direction}')
        peak = maximise_near_poles(lambda f: abs(frf(f)), frf.poles, *band)
        reduction = base_peak / peak.value
    return loop.plant_radius, loop.check_radius, loop.verdict, reduction


def rows(positions: Sequence[str], scenarios: Sequence[str], cache_dir: Path,
         candidate: Dynamics | None = None) -> list[DamperVariant]:
    """One row per (position, scenario, variant); plants and check models kept in cache_dir."""
    cfg = load_study_config()
    dt = cfg.dt
    band = (float(cfg.band[0]), float(cfg.f_max))
    d = cfg.direction
    parts = {}
    for scn in scenarios:           # checked before any model is built
        every = scenario_laws(read_scenario(scn).sections, dt)
        laws = [law for law in every if isinstance(law, ViscousDamper)]
        if not laws:
            raise ConfigError(f'scenario {scn!r} has no viscous dampers: the dynamics table '
                              'compares their dynamics')
        parts[scn] = (scenario_drives(scn), laws,
                      [law for law in every if not isinstance(law, ViscousDamper)])
    out = []
    for pos in positions:
        plant, _ = load_or_build_model(position=pos, cache_dir=cache_dir)
        check, _ = load_or_build_check_model(pos, check_f_max(cfg.sample_rate, cfg.check_f_min),
                                             cache_dir)
        base = exact_peak(plant_pair_frf(plant, f'tcp_displacement_{d}', f'tcp_force_{d}'),
                          *band).value
        for scn in scenarios:
            drives, laws, others = parts[scn]
            shipped = laws if candidate is None else _with(laws, candidate, dt)
            for variant, variant_laws in (('buildable', shipped),
                                          ('ideal', ideal_laws(scn, dt))):
                dyn = variant_laws[0].dynamics
                out.append(DamperVariant(
                    pos, scn, variant, float(max(abs(g) for law in variant_laws
                                                 for g in law.gains)),
                    any('moment' in port for law in variant_laws
                        for port in law.actuator_ports),
                    dyn.order, dyn.bandwidth_hz, dyn.delay_steps,
                    *evaluate(plant, check, variant_laws + others, dt, d, band, base,
                              drives)))
    return out


def _unit(scenario_rows: Sequence[DamperVariant]) -> str:
    return 'N m s/rad' if scenario_rows[0].moment else 'N s/m'


def _law(r: DamperVariant) -> str:
    dyn = (f'order-{r.filter_order} low-pass {r.bandwidth_hz:g} Hz'
           if r.filter_order else 'no low-pass')
    delay = f', delay {r.delay_steps} step(s)' if r.delay_steps else ''
    return f'{r.gain:g}, {dyn}{delay}'


def markdown_table(table: Sequence[DamperVariant]) -> str:
    """Per scenario and variant: the law, check radius and peak reduction per position."""
    positions = list(dict.fromkeys(r.position for r in table))
    lines = ['| scenario | variant | gain [unit], dynamics | check-model radius '
             + ' / '.join(positions) + ' | TCP peak reduction ' + ' / '.join(positions)
             + ' | verdict ' + ' / '.join(positions) + ' |', '|---' * 6 + '|']
    for scn in dict.fromkeys(r.scenario for r in table):
        for variant in ('buildable', 'ideal'):
            sel = [r for r in table if r.scenario == scn and r.variant == variant]
            lines.append(
                f'| `{scn}` | {variant} | {_law(sel[0])} [{_unit(sel)}] | '
                + ' / '.join(f'{r.check_radius:.6f}' for r in sel) + ' | '
                + ' / '.join(f'{r.peak_reduction:.3f}' for r in sel) + ' | '
                + ' / '.join(r.verdict for r in sel) + ' |')
    return '\n'.join(lines)


def format_table(table: Sequence[DamperVariant]) -> str:
    """Plain-text table of :func:`rows`."""
    lines = [f'{"pos":4} {"scenario":24} {"variant":14} {"ord":>3} {"bw Hz":>7} {"dly":>3} '
             f'{"rho plant":>10} {"rho check":>10} {"peak red.":>9}  verdict']
    for r in table:
        lines.append(f'{r.position:4} {r.scenario:24} {r.variant:14} {r.filter_order:3d} '
                     f'{r.bandwidth_hz:7g} {r.delay_steps:3d} {r.plant_radius:10.6f} '
                     f'{r.check_radius:10.6f} {r.peak_reduction:9.3f}  {r.verdict}')
    return '\n'.join(lines)
