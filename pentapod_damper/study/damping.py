"""
Damping per mode (analytic part): the modes that dominate the TCP compliances and their ζ.

For a position and a scenario, the closed-loop poles of the sampled lockstep loop (the laws
with their dynamics and delays, as the testbed runs them) and of the continuous loop (the laws'
continuous form: viscous gains, low-passes, no delay) are computed per mode
(:mod:`pentapod_sim.sim.loop_poles`). For each TCP direction a = x, y, z the ``count`` poles
whose term in the sampled-loop FRF ``tcp_displacement_a / tcp_force_a`` peaks highest inside
``band`` are the dominant ones (terms below :data:`NEGLIGIBLE` of the largest are left out);
each gives a :class:`ModeDamping` with the open-loop mode paired by MAC, its open-loop
frequency and ζ, and frequency, ζ and MAC in both closed loops. The study merges these with
the ζ identified from its recorded runs.

    python -m pentapod_damper.study damping [--positions P1,P2] [--scenarios a,b] [--count 3]
                                            [--directions xyz] [--band 2,200] [--markdown]

Units: frequencies [Hz], damping ratios [-], peaks [µm/N], decay time constants [s].
"""
from __future__ import annotations

from dataclasses import dataclass
import math
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from pentapod_damper.scenario_laws import scenario_laws
from pentapod_damper.study.config import load_study_config
from pentapod_sim.errors import ConfigError
from pentapod_sim.plant.build import load_or_build_model
from pentapod_sim.plant.drives import DrivenPlant
from pentapod_sim.plant.frf_peaks import PoleResidueFrf
from pentapod_sim.plant.model import PlantModel
from pentapod_sim.scenario.files import read_scenario
from pentapod_sim.scenario.laws import scenario_plant
from pentapod_sim.sim.controllers import controller_blocks, controller_of, DiscreteController
from pentapod_sim.sim.loop_poles import (
    closed_loop_poles,
    continuous_loop_poles,
    continuous_loop_system,
    LoopPoles,
)

#: Band in which the dominant modes are sought [Hz] (issue 13: 2-200 Hz).
BAND = (2.0, 200.0)
#: Dominant modes per TCP direction.
COUNT = 3
#: Poles whose term is below this share of the direction's largest are not in the table.
NEGLIGIBLE = 1e-6
#: Scenarios of the table by default (the study's closed loops with linear laws).
SCENARIOS = ('baseline', 'strut_damping_12', 'tcp_damping')


@dataclass(frozen=True)
class ModeDamping:
    """
    One dominant mode of TCP aa in one loop.

    ``direction`` is aa (xx, ...), ``rank`` 1 for the highest peak, ``mode`` the open-loop mode
    of the reduced plant (1-based) paired by MAC, ``fe_mode`` the same mode's number in the FE
    model (they differ once the reduction left a lower mode out) and ``cause`` the stiffness
    group with the largest share of its strain energy, ``open_*`` its frequency [Hz] and ζ;
    ``sampled_*`` and ``continuous_*`` the pole's frequency, ζ and MAC in the sampled and the
    continuous loop (NaN where the continuous loop has no pole paired with the mode);
    ``peak_um_per_N`` the sampled-loop pole's term at its peak and ``decay_time_s``
    1 / (ζ ω) of that pole.
    """

    position: str
    scenario: str
    direction: str
    rank: int
    mode: int
    fe_mode: int
    cause: str
    open_freq_hz: float
    open_zeta: float
    sampled_freq_hz: float
    sampled_zeta: float
    sampled_mac: float
    continuous_freq_hz: float
    continuous_zeta: float
    continuous_mac: float
    peak_um_per_N: float
    decay_time_s: float


def continuous_controller(law: Any) -> DiscreteController:
    """
    The continuous linear model of a law: ``continuous_model()`` or its memoryless gain.

    Raises
    ------
    ConfigError
        If the law has neither (a filtered or limited PMA).
    """
    model = getattr(law, 'continuous_model', None)
    if callable(model):
        result: DiscreteController = model()
        return result
    gain = law.linear_gain()
    if gain is None:
        raise ConfigError(f'{type(law).__name__} on {law.actuator_ports} has no continuous '
                          'linear model')
    return DiscreteController.static(law.sensor_ports, law.actuator_ports, gain)


def continuous_loop_frf(plant: PlantModel | DrivenPlant, laws: Sequence[Any], output: str,
                        input_: str) -> PoleResidueFrf:
    """
    FRF ``output / input_`` of the continuous loop of the laws' own continuous models.

    The continuous reference of laws with dynamics of their own (IFF, lag displacement, PPF,
    band-pass, a filtered PMA: :func:`continuous_controller`), which have no viscous
    equivalent: the loop with their filters, without sampling and delay.
    """
    controllers = [continuous_controller(law) for law in laws]
    a, b, c_y = continuous_loop_system(plant, controllers)
    i, o = plant.input_names.index(input_), plant.output_names.index(output)
    # the direct term of the loop, y = c_y z + D (I - K D)^-1 e (K: the laws' static gains)
    d = plant.state_matrices()[3]
    gain = controller_blocks(controllers, plant.input_names, plant.output_names)[0]
    direct = (d @ np.linalg.inv(np.eye(len(plant.input_names)) - gain @ d))[o, i]
    return PoleResidueFrf.from_state_space(a, b[:, i], c_y[o], float(direct))


def loop_poles(plant: PlantModel | DrivenPlant, laws: Sequence[Any],
               dt: float) -> tuple[LoopPoles, LoopPoles]:
    """Poles per mode of the sampled loop at ``dt`` [s] and of the continuous loop."""
    sampled = closed_loop_poles(plant, [controller_of(law) for law in laws], dt)
    continuous = continuous_loop_poles(plant, [continuous_controller(law) for law in laws])
    return sampled, continuous


def _pole(poles: LoopPoles, j: int) -> tuple[float, float, float]:
    """Frequency [Hz], ζ and MAC of pole ``j`` (NaN for -1: no pole)."""
    if j < 0:
        return math.nan, math.nan, math.nan
    return float(poles.freq_hz[j]), float(poles.zeta[j]), float(poles.mac[j])


def damping_rows(plant: PlantModel | DrivenPlant, laws: Sequence[Any], dt: float,
                 band: tuple[float, float] = BAND, directions: str = 'xyz',
                 count: int = COUNT, poles: tuple[LoopPoles, LoopPoles] | None = None,
                 position: str = '', scenario: str = '') -> list[ModeDamping]:
    """
    The dominant modes of TCP aa (a in ``directions``) for one set of laws.

    Parameters
    ----------
    plant : PlantModel or DrivenPlant
        Modal plant with the TCP ports (or one with the feed drives' rotors).
    laws : sequence
        Linear laws (:func:`pentapod_damper.scenario_laws.scenario_laws`); empty: open loop.
    dt : float
        Sample time of the sampled loop [s].
    band : (float, float)
        Frequencies [Hz] of the sampled-loop poles considered.
    directions : str
        TCP directions.
    count : int
        Dominant modes per direction.
    poles : (LoopPoles, LoopPoles), optional
        :func:`loop_poles` of the same plant, laws and ``dt``, if already computed.
    position, scenario : str
        Labels of the rows.
    """
    sampled, continuous = loop_poles(plant, laws, dt) if poles is None else poles
    rows = []
    for a in directions:
        out = plant.output_names.index(f'tcp_displacement_{a}')
        inp = plant.input_names.index(f'tcp_force_{a}')
        peaks = sampled.peaks(out, inp)
        f = sampled.freq_hz
        cand = np.flatnonzero(sampled.structural & (sampled.mode >= 0) & (f >= band[0])
                              & (f <= band[1]))
        top = peaks[cand][np.isfinite(peaks[cand])].max(initial=0.0)    # inf: unstable pole
        cand = cand[peaks[cand] > NEGLIGIBLE * top]
        for rank, j in enumerate(cand[np.argsort(-peaks[cand])][:count], 1):
            i = int(sampled.mode[j])
            decay = 1.0 / (sampled.zeta[j] * 2 * np.pi * f[j])
            rows.append(ModeDamping(
                position, scenario, a + a, rank, i + 1, *plant.fe_mode(i + 1),
                float(plant.frequencies_hz[i]),
                float(plant.zeta[i]), *_pole(sampled, int(j)),
                *_pole(continuous, continuous.of_mode(i)), float(peaks[j] * 1e6),
                float(decay)))
    return rows


def settling_time(table: Sequence[ModeDamping], time_constants: float = 5.0) -> float:
    """``time_constants`` decay time constants of the slowest of the modes [s]."""
    return time_constants * max((r.decay_time_s for r in table), default=0.0)


def scenario_rows(plant: PlantModel | DrivenPlant, position: str, scenario: str, dt: float,
                  laws: Sequence[Any] | None = None, **options: Any) -> list[ModeDamping]:
    """
    :func:`damping_rows` of a scenario's laws, labelled with position and scenario.

    ``laws``: the scenario file's laws at ``dt`` if already built (else read here);
    ``options`` go to :func:`damping_rows`.
    """
    if laws is None:
        laws = scenario_laws(read_scenario(scenario).sections, dt)
    return damping_rows(plant, laws, dt, position=position, scenario=scenario, **options)


def rows(positions: Sequence[str], scenarios: Sequence[str], cache_dir: Path,
         **options: Any) -> list[ModeDamping]:
    """
    Rows for every position and scenario at the study's sample rate (config/study.yaml).

    The plants are built once and kept in ``cache_dir``; each scenario's laws are closed on
    the plant as its plant node steps it (with the feed drives' rotors of its ``drives``:
    :func:`pentapod_sim.scenario.laws.scenario_plant`).
    """
    dt = load_study_config().dt
    out = []
    for pos in positions:
        plant, _ = load_or_build_model(position=pos, cache_dir=cache_dir)
        for scn in scenarios:
            out += scenario_rows(scenario_plant(scn, plant), pos, scn, dt, **options)
    return out


def format_table(table: Sequence[ModeDamping]) -> str:
    """Plain-text table of :func:`damping_rows` rows."""
    lines = [f'{"pos":4} {"scenario":18} {"dir":3} {"#":>1} {"mode":>4} {"FE":>4} {"cause":10} '
             f'{"f open":>8} '
             f'{"ζ open":>8} {"f sampled":>9} {"ζ sampled":>9} {"MAC":>5} {"f cont.":>8} '
             f'{"ζ cont.":>8} {"MAC":>5} {"peak um/N":>9} {"tau s":>7}']
    for r in table:
        lines.append(f'{r.position:4} {r.scenario:18} {r.direction:3} {r.rank:1d} '
                     f'{r.mode:4d} {r.fe_mode:4d} {r.cause:10} '
                     f'{r.open_freq_hz:8.3f} {r.open_zeta:8.5f} '
                     f'{r.sampled_freq_hz:9.3f} {r.sampled_zeta:9.5f} '
                     f'{r.sampled_mac:5.3f} {r.continuous_freq_hz:8.3f} '
                     f'{r.continuous_zeta:8.5f} {r.continuous_mac:5.3f} '
                     f'{r.peak_um_per_N:9.4f} {r.decay_time_s:7.3f}')
    return '\n'.join(lines)


def markdown_table(table: Sequence[ModeDamping]) -> str:
    """Markdown table of :func:`damping_rows` rows (docs/statespace.md holds one)."""
    lines = ['| position | scenario | TCP | mode (FE mode, cause) | f open [Hz] | ζ open '
             '| f sampled [Hz] | ζ sampled | MAC | f continuous [Hz] | ζ continuous | MAC '
             '| peak [µm/N] |',
             '|---|---|---|---|---|---|---|---|---|---|---|---|---|']
    for r in table:
        lines.append(f'| {r.position} | `{r.scenario}` | {r.direction} '
                     f'| {r.mode} ({r.fe_mode}, {r.cause or "-"}) '
                     f'| {r.open_freq_hz:.2f} | {r.open_zeta:.4f} '
                     f'| {r.sampled_freq_hz:.2f} | {r.sampled_zeta:.4f} '
                     f'| {r.sampled_mac:.2f} | {r.continuous_freq_hz:.2f} '
                     f'| {r.continuous_zeta:.4f} | {r.continuous_mac:.2f} '
                     f'| {r.peak_um_per_N:.3g} |')
    return '\n'.join(lines)
