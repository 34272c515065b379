"""
Damping per mode (analytic part): the modes that dominate the TCP compliances and their ζ.

For a position and a scenario, the closed-loop poles of the sampled lockstep loop (the laws
with their dynamics and delays, as the testbed runs them) and of the continuous loop (the laws'
continuous form: viscous gains, low-passes, no delay) are computed per mode
(:mod:`pentapod_sim.sim.loop_poles`). For each TCP direction a = x, y, z the ``count`` poles
whose term in the sampled-loop FRF ``tcp_displacement_a / tcp_force_a`` peaks highest inside
``band`` are the dominant ones (terms below :data:`NEGLIGIBLE` of the largest are left out);
each gives a row with the open-loop mode paired by MAC, its open-loop frequency and ζ, and
frequency, ζ and MAC in both closed loops. The study merges these rows with the ζ identified
from its recorded runs.

    python -m pentapod_damper.study.damping [--positions P1,P2] [--scenarios a,b] [--count 3]
                                            [--directions xyz] [--band 2,200] [--markdown]

Units: frequencies [Hz], damping ratios [-], peaks [µm/N], decay time constants [s].
"""
from __future__ import annotations

import sys
from typing import Sequence

import numpy as np

from pentapod_damper.scenario_laws import scenario_laws
from pentapod_damper.study.config import load_study_config
from pentapod_damper.study.pipeline import CHECK_CACHE
from pentapod_sim.cli import CommandParser
from pentapod_sim.errors import ConfigError
from pentapod_sim.plant.build import load_or_build_model
from pentapod_sim.plant.model import PlantModel
from pentapod_sim.scenario.files import read_scenario
from pentapod_sim.sim.controllers import controller_of, DiscreteController
from pentapod_sim.sim.loop_poles import closed_loop_poles, continuous_loop_poles, LoopPoles

#: Band in which the dominant modes are sought [Hz] (issue 13: 2-200 Hz).
BAND = (2.0, 200.0)
#: Dominant modes per TCP direction.
COUNT = 3
#: Poles whose term is below this share of the direction's largest are not in the table.
NEGLIGIBLE = 1e-6
#: Scenarios of the table by default (the study's closed loops with linear laws).
SCENARIOS = ('baseline', 'strut_damping_12', 'tcp_damping')


def continuous_controller(law) -> DiscreteController:
    """
    The continuous linear model of a law: ``continuous_model()`` or its memoryless gain.

    Raises
    ------
    ConfigError
        If the law has neither (a filtered or limited PMA).
    """
    model = getattr(law, 'continuous_model', None)
    if callable(model):
        return model()
    gain = law.linear_gain()
    if gain is None:
        raise ConfigError(f'{type(law).__name__} on {law.actuator_ports} has no continuous '
                          'linear model')
    return DiscreteController.static(law.sensor_ports, law.actuator_ports, gain)


def loop_poles(plant: PlantModel, laws: Sequence, dt: float) -> tuple[LoopPoles, LoopPoles]:
    """Poles per mode of the sampled loop at ``dt`` [s] and of the continuous loop."""
    sampled = closed_loop_poles(plant, [controller_of(law) for law in laws], dt)
    continuous = continuous_loop_poles(plant, [continuous_controller(law) for law in laws])
    return sampled, continuous


def _pole(poles: LoopPoles, j: int, tag: str) -> dict:
    if j < 0:
        return {f'{tag}_freq_hz': np.nan, f'{tag}_zeta': np.nan, f'{tag}_mac': np.nan}
    return {f'{tag}_freq_hz': float(poles.freq_hz[j]), f'{tag}_zeta': float(poles.zeta[j]),
            f'{tag}_mac': float(poles.mac[j])}


def damping_rows(plant: PlantModel, laws: Sequence, dt: float,
                 band: tuple[float, float] = BAND, directions: str = 'xyz',
                 count: int = COUNT,
                 poles: tuple[LoopPoles, LoopPoles] | None = None) -> list[dict]:
    """
    Rows of the dominant modes of TCP aa (a in ``directions``) for one set of laws.

    Parameters
    ----------
    plant : PlantModel
        Modal plant with the TCP ports.
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

    Returns
    -------
    list of dict
        ``direction`` (xx, ...), ``rank`` (1 = highest peak), ``mode`` (open-loop mode,
        1-based), ``open_freq_hz``, ``open_zeta``, ``sampled_freq_hz``, ``sampled_zeta``,
        ``sampled_mac``, ``continuous_freq_hz``, ``continuous_zeta``, ``continuous_mac``,
        ``peak_um_per_N`` (the sampled-loop pole's term at its peak) and
        ``decay_time_s`` (1 / (ζ ω) of the sampled-loop pole).
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
            rows.append({'direction': a + a, 'rank': rank, 'mode': i + 1,
                         'open_freq_hz': float(plant.frequencies_hz[i]),
                         'open_zeta': float(plant.zeta[i]), **_pole(sampled, j, 'sampled'),
                         **_pole(continuous, continuous.of_mode(i), 'continuous'),
                         'peak_um_per_N': float(peaks[j] * 1e6), 'decay_time_s': float(decay)})
    return rows


def settling_time(table: Sequence[dict], time_constants: float = 5.0) -> float:
    """``time_constants`` decay time constants of the slowest dominant mode of the rows [s]."""
    return time_constants * max((r['decay_time_s'] for r in table), default=0.0)


def scenario_rows(plant: PlantModel, position: str, scenario: str, dt: float,
                  laws: Sequence | None = None, **options) -> list[dict]:
    """
    :func:`damping_rows` of a scenario's laws, labelled with position and scenario.

    ``laws``: the scenario file's laws at ``dt`` if already built (else read here);
    ``options`` go to :func:`damping_rows`.
    """
    if laws is None:
        laws = scenario_laws(read_scenario(scenario).sections, dt)
    return [{'position': position, 'scenario': scenario, **row}
            for row in damping_rows(plant, laws, dt, **options)]


def rows(positions: Sequence[str], scenarios: Sequence[str], **options) -> list[dict]:
    """Rows for every position and scenario at the study's sample rate (config/study.yaml)."""
    dt = 1.0 / load_study_config().sample_rate
    out = []
    for pos in positions:
        plant, _ = load_or_build_model(position=pos, cache_dir=CHECK_CACHE)
        for scn in scenarios:
            out += scenario_rows(plant, pos, scn, dt, **options)
    return out


def format_table(table: list[dict]) -> str:
    """Plain-text table of :func:`damping_rows` rows."""
    lines = [f'{"pos":4} {"scenario":18} {"dir":3} {"#":>1} {"mode":>4} {"f open":>8} '
             f'{"ζ open":>8} {"f sampled":>9} {"ζ sampled":>9} {"MAC":>5} {"f cont.":>8} '
             f'{"ζ cont.":>8} {"MAC":>5} {"peak um/N":>9} {"tau s":>7}']
    for r in table:
        lines.append(f'{r["position"]:4} {r["scenario"]:18} {r["direction"]:3} {r["rank"]:1d} '
                     f'{r["mode"]:4d} {r["open_freq_hz"]:8.3f} {r["open_zeta"]:8.5f} '
                     f'{r["sampled_freq_hz"]:9.3f} {r["sampled_zeta"]:9.5f} '
                     f'{r["sampled_mac"]:5.3f} {r["continuous_freq_hz"]:8.3f} '
                     f'{r["continuous_zeta"]:8.5f} {r["continuous_mac"]:5.3f} '
                     f'{r["peak_um_per_N"]:9.4f} {r["decay_time_s"]:7.3f}')
    return '\n'.join(lines)


def markdown_table(table: list[dict]) -> str:
    """Markdown table of :func:`damping_rows` rows (docs/statespace.md holds one)."""
    lines = ['| position | scenario | TCP | mode | f open [Hz] | ζ open | f sampled [Hz] | '
             'ζ sampled | MAC | f continuous [Hz] | ζ continuous | MAC | peak [µm/N] |',
             '|---|---|---|---|---|---|---|---|---|---|---|---|---|']
    for r in table:
        lines.append(f'| {r["position"]} | `{r["scenario"]}` | {r["direction"]} | {r["mode"]} '
                     f'| {r["open_freq_hz"]:.2f} | {r["open_zeta"]:.4f} '
                     f'| {r["sampled_freq_hz"]:.2f} | {r["sampled_zeta"]:.4f} '
                     f'| {r["sampled_mac"]:.2f} | {r["continuous_freq_hz"]:.2f} '
                     f'| {r["continuous_zeta"]:.4f} | {r["continuous_mac"]:.2f} '
                     f'| {r["peak_um_per_N"]:.3g} |')
    return '\n'.join(lines)


def main(argv: list[str] | None = None) -> int:
    """Print the table; return 1 with a message on a configuration error."""
    parser = CommandParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--positions', default='P1,P2')
    parser.add_argument('--scenarios', default=','.join(SCENARIOS))
    parser.add_argument('--count', type=int, default=COUNT, help='dominant modes per direction')
    parser.add_argument('--band', default=f'{BAND[0]:g},{BAND[1]:g}', help='LOW,HIGH [Hz]')
    parser.add_argument('--directions', default='xyz', help='TCP directions, e.g. xyz or x')
    parser.add_argument('--markdown', action='store_true', help='print a Markdown table')
    args = parser.parse_args(argv)
    try:
        lo, hi = (float(v) for v in args.band.split(','))
        table = rows(args.positions.split(','), args.scenarios.split(','), band=(lo, hi),
                     count=args.count, directions=args.directions)
    except (ConfigError, ValueError) as err:
        print(f'damping: {err}', file=sys.stderr)
        return 1
    print(markdown_table(table) if args.markdown else format_table(table))
    return 0


if __name__ == '__main__':
    sys.exit(main())
