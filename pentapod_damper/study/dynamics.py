"""
What the dampers' actuator/sensor dynamics buy (truncation check) and cost (damping).

For every damping scenario with viscous dampers and every position, the sampled loop at the
study's sample rate is built twice: with the laws as the scenario file configures them
(low-pass and delay of its damper nodes) and with the same gains but no dynamics (ideal
sampled feedback with zero-order hold, u_k answers y_k). Each is checked on the plant and on
the check model (:func:`pentapod_sim.sim.stability.check_loop`), and its exact TCP peak
reduction is computed (:class:`pentapod_damper.study.analytic.SampledPairFrf`, searched at the
resonances) against the exact open-loop peak. ``--try order,bandwidth_hz,delay_steps``
replaces the scenario's dynamics to compare candidates.

    python -m pentapod_damper.study.dynamics [--positions P1,P2] [--scenarios a,b]
                                             [--try 1,150,0]

Units: frequencies [Hz], peaks [m/N], gains as the laws'.
"""
from __future__ import annotations

import argparse
import sys

from pentapod_damper.laws import Dynamics, ViscousDamper
from pentapod_damper.scenario_laws import scenario_laws
from pentapod_damper.study.analytic import SampledPairFrf
from pentapod_damper.study.config import load_study_config
from pentapod_damper.study.pipeline import CHECK_CACHE
from pentapod_sim.errors import ConfigError
from pentapod_sim.plant.build import load_or_build_model
from pentapod_sim.plant.check_model import check_f_max, load_or_build_check_model
from pentapod_sim.plant.frf_peaks import exact_peak, maximise_near_poles, plant_pair_frf
from pentapod_sim.scenario.files import read_scenario
from pentapod_sim.sim.stability import check_loop, controller_of

#: Scenarios with viscous damper nodes that the study runs.
SCENARIOS = ('strut_damping_all', 'strut_damping_12', 'strut_chord_damping_all',
             'strut_chord_damping_12', 'axial_damping', 'tcp_damping')


def _without_dynamics(laws: list) -> list:
    return [ViscousDamper(law.actuator_ports, law.gains) for law in laws]


def _with(laws: list, dyn: Dynamics, dt: float) -> list:
    return [ViscousDamper(law.actuator_ports, law.gains, dyn, dt) for law in laws]


def evaluate(plant, check, laws: list, dt: float, direction: str, band: tuple[float, float],
             base_peak: float) -> dict:
    """Check-model margin and exact sampled-loop peak reduction of one set of laws."""
    loop = check_loop(plant, check, [controller_of(law) for law in laws], dt, 'warn')
    row = {'plant_radius': loop.plant_radius, 'check_radius': loop.check_radius,
           'verdict': loop.verdict, 'peak_reduction': float('nan')}
    if loop.plant_radius < 1.0:
        frf = SampledPairFrf(plant, laws, dt, f'tcp_displacement_{direction}',
                             f'tcp_force_{direction}')
        peak = maximise_near_poles(lambda f: abs(frf(f)), frf.poles, *band)
        row['peak_reduction'] = base_peak / peak.value
    return row


def rows(positions, scenarios, candidate: Dynamics | None = None) -> list[dict]:
    """One row per (position, scenario, variant) with radii, verdict and peak reduction."""
    cfg = load_study_config()
    dt = 1.0 / cfg.sample_rate
    band = (float(cfg.band[0]), float(cfg.f_max))
    d = cfg.direction
    out = []
    for pos in positions:
        plant, _ = load_or_build_model(position=pos, cache_dir=CHECK_CACHE)
        check, _ = load_or_build_check_model(pos, check_f_max(cfg.sample_rate, cfg.check_f_min),
                                             CHECK_CACHE)
        base = exact_peak(plant_pair_frf(plant, f'tcp_displacement_{d}', f'tcp_force_{d}'),
                          *band).value
        for scn in scenarios:
            laws = [law for law in scenario_laws(read_scenario(scn).sections, dt)
                    if isinstance(law, ViscousDamper)]
            shipped = laws if candidate is None else _with(laws, candidate, dt)
            for variant, variant_laws in (('with dynamics', shipped),
                                          ('no dynamics', _without_dynamics(laws))):
                dyn = variant_laws[0].dynamics
                row = evaluate(plant, check, variant_laws, dt, d, band, base)
                out.append({'position': pos, 'scenario': scn, 'variant': variant,
                            'filter_order': dyn.order, 'bandwidth_hz': dyn.bandwidth_hz,
                            'delay_steps': dyn.delay_steps, **row})
    return out


def main(argv: list[str] | None = None) -> int:
    """Print the table; return 1 with a message on a configuration error."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--positions', default='P1,P2')
    parser.add_argument('--scenarios', default=','.join(SCENARIOS))
    parser.add_argument('--try', dest='candidate', help='order,bandwidth_hz,delay_steps')
    args = parser.parse_args(argv)
    try:
        candidate = None
        if args.candidate:
            order, bw, delay = args.candidate.split(',')
            candidate = Dynamics(int(order), float(bw), delay_steps=int(delay))
        table = rows(args.positions.split(','), args.scenarios.split(','), candidate)
    except (ConfigError, ValueError) as err:
        print(f'dynamics: {err}', file=sys.stderr)
        return 1
    print(f'{"pos":4} {"scenario":24} {"variant":14} {"ord":>3} {"bw Hz":>7} {"dly":>3} '
          f'{"rho plant":>10} {"rho check":>10} {"peak red.":>9}  verdict')
    for r in table:
        print(f'{r["position"]:4} {r["scenario"]:24} {r["variant"]:14} {r["filter_order"]:3d} '
              f'{r["bandwidth_hz"]:7g} {r["delay_steps"]:3d} {r["plant_radius"]:10.6f} '
              f'{r["check_radius"]:10.6f} {r["peak_reduction"]:9.3f}  {r["verdict"]}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
