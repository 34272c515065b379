"""
`statespace`: modal reduction report, FRF plots, dc-gain charts, damped FRFs, plant files.

All subcommands read config/reduction.yaml (``--config``) and write to ``--out``
(default out/statespace/). Examples::

    statespace report                      # P1, P2: modes kept, static and FRF error
    statespace frf --position P1,P2        # TCP FRF PNG + CSV
    statespace dcgain                      # dc gain per mode with the relevance limit
    statespace closed-loop --damper strut1_bending_moment_2=20000 ...  # + truncation check
    statespace closed-loop --damper tcp_force_x=20000 --poles   # + poles per mode (MAC)
    statespace build --position P1         # out/statespace/plant_P1.npz
    statespace build --modal-data modes.csv --strut-frames frames.yaml
    statespace build --fe-model machine.yaml --config my_reduction.yaml   # imported FE model
    statespace tune --position P1 --family lag-bending,iff   # gains under the machine's limits
    statespace lobes --position P1,P2 --scenario baseline,tcp_damping   # chatter lobes
"""
from __future__ import annotations

import argparse
import copy
import csv
from dataclasses import replace
import json
import logging
from pathlib import Path
import sys
from typing import Any, Iterator, TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from pentapod_sim.cli import (
    add_model_arguments,
    CommandParser,
    configure_logging,
    model_from_args,
    model_label,
    run_command,
)
from pentapod_sim.cli.statespace_lobes import add_lobes_parser
from pentapod_sim.cli.statespace_options import add_config_and_out, POSITIONS_HELP
from pentapod_sim.cli.statespace_tune import add_tune_parser
from pentapod_sim.errors import ConfigError
from pentapod_sim.fe.model import FEModel
from pentapod_sim.parameters import sample_time
from pentapod_sim.plant import frf, frf_plot, reduction
from pentapod_sim.plant.build import (
    config_damping,
    from_modal_data,
    keep_by_relevance,
    plant_from_fe,
    reduce_plant,
)
from pentapod_sim.plant.check_model import DEFAULT_CHECK_F_MIN
from pentapod_sim.plant.config import load_reduction_config, RelevanceRule
from pentapod_sim.plant.model import PlantModel

if TYPE_CHECKING:       # imported by the commands that use them
    from pentapod_sim.sim.controllers import DiscreteController
    from pentapod_sim.sim.stability import LoopCheck

LOGGER = logging.getLogger('statespace')
#: Dampers of the default closed-loop case: bending of every strut, b = 20 kN s/m applied
#: as a moment pair per rad/s (see docs/statespace.md for the unit).
DEFAULT_DAMPERS = [f'strut{i}_bending_moment_{k}=2e4' for i in range(1, 6) for k in (2, 3)]


def _positions(args: argparse.Namespace) -> list[str]:
    if args.fe_model_file:                    # an imported model has the one pose it was made at
        return [model_label(args)]
    return [p for p in (args.position or ','.join(args.cfg.positions)).split(',') if p]


def _plants(args: argparse.Namespace
            ) -> Iterator[tuple[str, PlantModel, npt.NDArray[np.intp]]]:
    """Yield (position, plant with all computed modes, kept indices) per position."""
    for position in _positions(args):
        model_args = copy.copy(args)
        model_args.position = position
        fe = model_from_args(model_args)
        LOGGER.info('%s: FE model built', position)
        plant_all, keep = plant_from_fe(fe, args.cfg, lambda msg: LOGGER.info('%s', msg))
        plant_all.meta['position'] = position
        args.fe_model = fe
        yield position, plant_all, keep


def _pair(args: argparse.Namespace) -> tuple[str, str]:
    """(output, input) from --pair OUT/IN or the config's report_pair (PortError if unknown)."""
    from pentapod_sim.plant.ports import check_names
    if args.pair:
        out, sep, inp = args.pair.partition('/')
        if not sep:
            raise ConfigError(f'--pair must be OUTPUT/INPUT, got {args.pair!r}')
    else:
        out, inp = args.cfg.report_pair
    check_names([out], 'output')
    check_names([inp], 'input')
    return out, inp


def _pair_rule(args: argparse.Namespace) -> list[RelevanceRule]:
    """Relevance for the report: the report pair alone at the first rule's limit (or --limit)."""
    out, inp = _pair(args)
    rule = replace(args.cfg.relevance[0], inputs=(inp,), outputs=(out,))
    if args.limit is not None:
        if not args.limit > 0:
            raise ConfigError(f'--limit = {args.limit!r} (unit of the pair): must be > 0')
        rule = replace(rule, abs_limit=args.limit, rel_limit=None, count=None)
    return [rule]


def _direct_check(fe: FEModel, pair_all: PlantModel, f_max: float) -> dict[str, float]:
    """Undamped modal plant (all modes + residual) vs a direct FE harmonic solve."""
    from pentapod_sim.plant.ports import input_matrix, output_matrices, ports
    freq = reduction.between_resonances(pair_all.frequencies_hz, f_max)
    b = input_matrix(ports(fe.points, fe.strut_frames, pair_all.input_names))
    c, _ = output_matrices(ports(fe.points, fe.strut_frames, pair_all.output_names))
    direct = reduction.harmonic_response(fe.K, fe.M, b, c, freq)
    undamped = frf.modal_frf_matrix(pair_all.omega, 0.0, pair_all.b, pair_all.c_disp,
                                    pair_all.c_vel, pair_all.d, freq)
    pointwise = reduction.frf_relative_error_percent(undamped, direct)
    return {'reference_vs_direct_solve_percent_of_peak':
            float(reduction.frf_error_percent(undamped, direct).max()),
            'reference_vs_direct_solve_median_percent': float(np.median(pointwise)),
            'direct_solve_frequencies': int(freq.size)}


def cmd_report(args: argparse.Namespace) -> int:
    """Modes kept, static error with/without correction and FRF error for the report pair."""
    out, inp = _pair(args)
    freq = args.cfg.frequency.grid()
    rows = []
    for position, plant_all, _ in _plants(args):
        pair_all = plant_all.select([inp], [out])
        keep = keep_by_relevance(pair_all, _pair_rule(args))
        reference = frf.modal_frf(pair_all, freq).H
        row: dict[str, Any] = {
            'position': position, 'pair': f'{out}/{inp}', 'n_dof': plant_all.meta['n_dof'],
            'modes_computed': plant_all.n_modes, 'modes_kept': int(keep.size),
            'relevance': dict(_pair_rule(args)[0].criterion, measure=_pair_rule(args)[0].measure),
            'static_compliance_m_per_n': float(pair_all.meta['static_compliance_full'][0][0])}
        for corrected in (False, True):
            red = reduce_plant(pair_all, keep, corrected)
            g_red = red.d[0, 0] + (red.c_disp[0] * red.b[:, 0] / red.omega ** 2).sum()
            tag = 'with' if corrected else 'without'
            row[f'static_error_percent_{tag}_correction'] = float(
                reduction.static_error_percent(g_red, row['static_compliance_m_per_n']))
            h_red = frf.modal_frf(red, freq).H
            row[f'frf_error_percent_{tag}_correction'] = float(
                reduction.frf_error_percent(h_red, reference)[0, 0])
            row[f'frf_median_relative_error_percent_{tag}_correction'] = float(np.median(
                reduction.frf_relative_error_percent(h_red, reference)))
        row.update(_direct_check(args.fe_model, pair_all, freq[-1]))
        rows.append(row)
        print(f'{position}: {out}/{inp}: kept {keep.size} of {plant_all.n_modes} modes '
              f'({row["relevance"]}); static error '
              f'{row["static_error_percent_without_correction"]:+.3f} % without, '
              f'{row["static_error_percent_with_correction"]:+.2e} % with correction; FRF error '
              f'0..{freq[-1]:g} Hz {row["frf_error_percent_without_correction"]:.3f} % / '
              f'{row["frf_error_percent_with_correction"]:.3f} % (max, of peak |H|), median '
              f'{row["frf_median_relative_error_percent_without_correction"]:.3f} % / '
              f'{row["frf_median_relative_error_percent_with_correction"]:.3f} %; '
              f'reference vs direct FE solve {row["direct_solve_frequencies"]} freqs: '
              f'{row["reference_vs_direct_solve_percent_of_peak"]:.1e} % of peak, median '
              f'{row["reference_vs_direct_solve_median_percent"]:.1e} %')
    path = args.out / 'reduction_report.json'
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(rows, indent=2))
    LOGGER.info('wrote %s', path)
    return 0


def cmd_frf(args: argparse.Namespace) -> int:
    """FRF of the report pair (kept modes, configured correction) per position: PNG + CSV."""
    out, inp = _pair(args)
    freq, results, marks = args.cfg.frequency.grid(), [], []
    for position, plant_all, keep in _plants(args):
        plant = reduce_plant(plant_all, keep, args.cfg.static_correction)
        results.append(frf.modal_frf(plant.select([inp], [out]), freq, label=position))
        marks.append(plant_all.frequencies_hz)
    stem = f'frf_{out}_{inp}_{"_".join(r.label for r in results)}'
    png = frf_plot.frf_plot(results, out, inp, args.out / f'{stem}.png', mode_freqs=marks,
                       title=f'{out} / {inp} (ticks: modes)')
    csv_path = frf.frf_to_csv(results, [(out, inp)], args.out / f'{stem}.csv')
    print(f'wrote {png} and {csv_path}')
    return 0


def cmd_dcgain(args: argparse.Namespace) -> int:
    """Bar chart of the report pair's dc gain per mode with the relevance limit."""
    out, inp = _pair(args)
    rule = _pair_rule(args)[0]
    for position, plant_all, _ in _plants(args):
        pair_all = plant_all.select([inp], [out])
        keep = keep_by_relevance(pair_all, [rule])
        gains = reduction.modal_dc_gains(pair_all.omega, pair_all.b, pair_all.c_disp)[:, 0, 0]
        png = frf_plot.dc_gain_plot(gains, pair_all.frequencies_hz,
                               args.out / f'dcgain_{out}_{inp}_{position}.png',
                               limit=rule.abs_limit, keep=keep,
                               title=f'{position}: dc gain per mode, {out} / {inp}; '
                                     f'{keep.size} of {gains.size} kept')
        table = args.out / f'dcgain_{out}_{inp}_{position}.csv'
        np.savetxt(table, np.column_stack([np.arange(1, gains.size + 1),
                                           pair_all.frequencies_hz, gains,
                                           np.isin(np.arange(gains.size), keep)]),
                   delimiter=',', header='mode,frequency_hz,dc_gain,kept', comments='',
                   fmt=['%d', '%.6f', '%.6e', '%d'])
        print(f'wrote {png} and {table}')
    return 0


def _dampers(specs: list[str]) -> dict[str, float]:
    dampers = {}
    for spec in specs:
        name, sep, value = spec.partition('=')
        try:
            dampers[name] = float(value)
        except ValueError:
            raise ConfigError(f'--damper must be NAME=GAIN, got {spec!r}') from None
        if not sep:
            raise ConfigError(f'--damper must be NAME=GAIN, got {spec!r}')
    return dampers


def _laws(dampers: dict[str, float]) -> list[DiscreteController]:
    """The dampers as memoryless velocity feedback (the same in discrete and continuous time)."""
    from pentapod_sim.plant.ports import collocated_output
    from pentapod_sim.sim.controllers import DiscreteController
    return [DiscreteController.static([collocated_output(port, 'velocity')], [port], [[-g]])
            for port, g in dampers.items()]


def _sampled_loop_check(args: argparse.Namespace, position: str, plant: PlantModel,
                        laws: list[DiscreteController]) -> LoopCheck:
    """Truncation check of the dampers as sampled feedback (plant vs check model)."""
    from pentapod_sim.plant.check_model import check_f_max, check_model_from_fe
    from pentapod_sim.sim.stability import check_loop
    rate = args.sample_rate or args.cfg.sample_rate
    f_max = check_f_max(rate, args.check_f_min)
    check = check_model_from_fe(args.fe_model, args.cfg, f_max,
                                lambda msg: LOGGER.info('check model: %s', msg))
    result = check_loop(plant, check, laws, sample_time(rate), args.on_unstable,
                        label=position)
    print(result.summary())
    return result


POLE_COLUMNS = ('mode', 'fe_mode', 'cause', 'open_freq_hz', 'open_zeta', 'sampled_freq_hz',
                'sampled_zeta', 'sampled_mac', 'continuous_freq_hz', 'continuous_zeta',
                'continuous_mac')


def _loop_poles(args: argparse.Namespace, position: str, plant: PlantModel,
                laws: list[DiscreteController]) -> Path:
    """Poles per mode (below the FRF band's top) of the sampled and continuous loop: CSV."""
    from pentapod_sim.sim.loop_poles import closed_loop_poles, continuous_loop_poles
    rate = args.sample_rate or args.cfg.sample_rate
    sampled = closed_loop_poles(plant, laws, sample_time(rate))
    cont = continuous_loop_poles(plant, laws)
    rows = []
    for i in map(int, np.flatnonzero(plant.frequencies_hz <= args.cfg.frequency.f_max)):
        row: list[float | str] = [i + 1, *plant.fe_mode(i + 1), plant.frequencies_hz[i],
                                  plant.zeta[i]]
        for poles in (sampled, cont):
            j = poles.of_mode(i)
            row += ([poles.freq_hz[j], poles.zeta[j], poles.mac[j]] if j >= 0
                    else [np.nan] * 3)
        rows.append(row)
    print(f'{position}: poles per mode, sampled loop at {rate:g} Hz and continuous loop '
          f'(frequency [Hz], damping ratio, MAC with the open-loop mode)')
    print(f'{"mode":>4} {"FE":>4} {"cause":12} {"f open":>9} {"ζ open":>8} {"f sampled":>9} '
          f'{"ζ sampled":>10} {"MAC":>5} {"f cont.":>9} {"ζ cont.":>9} {"MAC":>5}')
    for r in rows:
        print(f'{r[0]:4d} {r[1]:4d} {r[2]:12} {r[3]:9.3f} {r[4]:8.5f} {r[5]:9.3f} {r[6]:10.5f} '
              f'{r[7]:5.3f} {r[8]:9.3f} {r[9]:9.5f} {r[10]:5.3f}')
    for name, poles in (('sampled', sampled), ('continuous', cont)):
        ctrl = np.flatnonzero(~poles.structural)
        listed = ', '.join(f'{poles.freq_hz[j]:.4g} Hz ζ {poles.zeta[j]:.3g}' for j in ctrl)
        print(f'{position}: {ctrl.size} controller poles in the {name} loop (not structural)'
              f'{": " + listed if listed else ""}')
    path = args.out / f'loop_poles_{position}.csv'
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, 'w', newline='') as stream:
        writer = csv.writer(stream)
        writer.writerow(POLE_COLUMNS)
        writer.writerows(rows)
    return path


def cmd_closed_loop(args: argparse.Namespace) -> int:
    """Open vs closed-loop FRF of the report pair with added viscous dampers."""
    from pentapod_sim.plant.frf_peaks import exact_peak, plant_pair_frf
    out, inp = _pair(args)
    dampers = _dampers(args.damper or DEFAULT_DAMPERS)
    freq = args.cfg.frequency.grid()
    for position, plant_all, keep in _plants(args):
        plant = reduce_plant(plant_all, keep, args.cfg.static_correction)
        _sampled_loop_check(args, position, plant, _laws(dampers))
        if args.poles:
            print(f'wrote {_loop_poles(args, position, plant, _laws(dampers))}')
        open_ = frf.modal_frf(plant, freq, label=f'{position} open loop')
        closed = frf.closed_loop_frf(plant, dampers, freq, label=f'{position} damped')
        stem = f'closed_loop_{out}_{inp}_{position}'
        png = frf_plot.frf_plot([open_, closed], out, inp, args.out / f'{stem}.png',
                           title=f'{position}: {out} / {inp}, dampers: {len(dampers)}')
        frf.frf_to_csv([open_, closed], [(out, inp)], args.out / f'{stem}.csv')
        band = (float(freq[0]), float(freq[-1]))
        peak_o = exact_peak(plant_pair_frf(plant, out, inp), *band, freq)
        peak_c = exact_peak(plant_pair_frf(plant, out, inp, dampers), *band, freq)
        print(f'{position}: peak |H| {peak_o.value:.3e} at {peak_o.freq_hz:.2f} Hz -> '
              f'{peak_c.value:.3e} at {peak_c.freq_hz:.2f} Hz '
              f'({peak_o.value / peak_c.value:.2f}x lower, exact peaks); wrote {png}')
    return 0


def cmd_build(args: argparse.Namespace) -> int:
    """Build and save plant model files (from the FE model or from external modal data)."""
    if args.modal_data:
        from pentapod_sim.plant.external_modes import load_modal_data
        data = load_modal_data(args.modal_data, args.strut_frames)
        zeta = data.zeta if data.zeta is not None else config_damping(data.frequencies_hz,
                                                                       args.cfg)
        plant = from_modal_data(data.frequencies_hz, data.point_shapes, data.strut_frames,
                                list(args.cfg.inputs), list(args.cfg.outputs), zeta,
                                meta={'source': data.source})
        path = plant.save(args.out / f'plant_{Path(args.modal_data).stem}.npz')
        print(f'wrote {path} ({plant.n_modes} modes, no reduction, no static correction)')
        return 0
    for position, plant_all, keep in _plants(args):
        plant = reduce_plant(plant_all, keep, args.cfg.static_correction)
        path = plant.save(args.out / f'plant_{position}.npz')
        print(f'wrote {path} ({plant.n_modes} of {plant_all.n_modes} modes, '
              f'{len(plant.input_names)} inputs, {len(plant.output_names)} outputs)')
    return 0


def _parser() -> argparse.ArgumentParser:
    parser = CommandParser(prog='statespace', description=__doc__,
                           formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('-v', '--verbose', action='store_true')
    sub = parser.add_subparsers(dest='command', required=True)
    for name, func in (('report', cmd_report), ('frf', cmd_frf), ('dcgain', cmd_dcgain),
                       ('closed-loop', cmd_closed_loop), ('build', cmd_build)):
        p = sub.add_parser(name, help=(func.__doc__ or '').split('\n')[0])
        p.set_defaults(func=func)
        add_model_arguments(p, position='')
        for action in p._actions:     # the shared option takes one name; here a list
            if action.dest == 'position':
                action.help = POSITIONS_HELP
        add_config_and_out(p)
        p.add_argument('--pair', default=None, metavar='OUTPUT/INPUT',
                       help='port pair to report and plot (default: report_pair of the config)')
        p.add_argument('--limit', type=float, default=None,
                       help='absolute relevance limit for the report pair [m/N]')
        if name == 'closed-loop':
            p.add_argument('--damper', action='append', metavar='INPUT=GAIN',
                           help='damper on a collocated input port, gain in N s/m or '
                                'N m s/rad (repeatable; default: bending of all struts, 2e4)')
            p.add_argument('--sample-rate', type=float, default=None, metavar='HZ',
                           help='sample rate [Hz] of the truncation check of the dampers as '
                                'sampled feedback (default: sample_rate of the config)')
            p.add_argument('--check-f-min', type=float, default=DEFAULT_CHECK_F_MIN,
                           metavar='HZ', help='check model: every FE mode below max(this, 2 x '
                           f'sample rate) [Hz] (default {DEFAULT_CHECK_F_MIN:g})')
            p.add_argument('--on-unstable', choices=('warn', 'refuse'), default='warn',
                           help='a sampled loop unstable on the plant or stable only thanks '
                                'to truncation: warn loudly (default) or refuse (error exit)')
            p.add_argument('--poles', action='store_true',
                           help='also print and write (loop_poles_<position>.csv) frequency, '
                                'damping ratio and MAC per mode of the sampled and the '
                                'continuous loop')
        if name == 'build':
            p.add_argument('--modal-data', default=None, help='external modal data .npz/.csv')
            p.add_argument('--strut-frames', default=None, help='YAML with strut_frames')
    add_tune_parser(sub)
    add_lobes_parser(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run the `statespace` command line; returns the exit code."""
    args = _parser().parse_args(argv)
    configure_logging(args.verbose)

    def command(args: argparse.Namespace) -> int:
        args.cfg = load_reduction_config(args.config)
        return args.func(args)
    return run_command('statespace', command, args)


if __name__ == '__main__':
    sys.exit(main())
