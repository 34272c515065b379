"""
`calibrate`: modal damping of a model calibrated from measured FRFs, with its report.

Examples::

    calibrate --measured shaker.uff --model machine.yaml --settings calibration.yaml
    calibrate --measured frfs.csv --model P1 --band 20 140 --mac-min 0.85
    calibrate --measured shaker.uff --model P1 --fill bands --fill-edges 0 60 120 400

``--model`` is an imported FE model description (``.yaml``, docs/own_machine.md) or a position
of the own machine (config/positions.yaml). The model's modes below ``modes_f_max`` of the
reduction config (``--config``) are computed, the measured FRFs identified and paired with them,
and ``--out`` (default ``out/calibrate/<model>``) receives ``damping.yaml`` (name it as
``damping_file`` in a reduction config to build the calibrated plant), ``pairing.csv`` (model
f, measured f, MAC, zeta model, zeta measured), ``frf_errors.csv`` (dB at the peaks and RMS per
FRF, before and after), ``overlay.png`` (measured, model before, updated) and, with
``--modes-uff``, ``modes.uff`` (UFF 55 shapes at the measured points) and ``ports.csv``.
"""
from __future__ import annotations

import argparse
import logging
from pathlib import Path
import sys
from typing import TYPE_CHECKING

import numpy as np

from pentapod_sim.cli import CommandParser, configure_logging, model_from_args, run_command
from pentapod_sim.errors import ModalError

if TYPE_CHECKING:       # imported by the functions that use them
    from pentapod_sim.analysis.calibration.settings import CalibrationSettings
    from pentapod_sim.analysis.measured.frf_files import MeasuredFrfs
    from pentapod_sim.fe.model import FEModel

LOGGER = logging.getLogger('calibrate')


def _parser() -> argparse.ArgumentParser:
    parser = CommandParser(prog='calibrate', description=__doc__,
                           formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--measured', required=True,
                        help='measured FRFs: UFF 58 (.uff, .unv) or long-form CSV (.csv)')
    parser.add_argument('--model', required=True,
                        help='FE model description (.yaml) or a position name (e.g. P1)')
    parser.add_argument('--settings', default=None, help='calibration settings YAML')
    parser.add_argument('--config', default=None,
                        help='reduction config (modes_f_max, damping before calibration)')
    parser.add_argument('--band', type=float, nargs=2, default=None, metavar=('F_MIN', 'F_MAX'),
                        help='band to analyse [Hz] (default: settings, else the measurement)')
    parser.add_argument('--mac-min', type=float, default=None, help='least MAC of a pair')
    parser.add_argument('--fill', choices=('rayleigh', 'bands'), default=None,
                        help='damping of the unpaired modes')
    parser.add_argument('--fill-edges', type=float, nargs='+', default=None, metavar='HZ',
                        help='band edges [Hz] of --fill bands')
    parser.add_argument('--modes-uff', action='store_true',
                        help='also write the model modes at the measured points (UFF 55)')
    parser.add_argument('--out', type=Path, default=None, help='output folder')
    parser.add_argument('-v', '--verbose', action='store_true', help='debug log lines')
    return parser


def _settings(args: argparse.Namespace) -> CalibrationSettings:
    from pentapod_sim.analysis.calibration.settings import load_settings
    settings = load_settings(args.settings)
    changes = {k: v for k, v in (('band', tuple(args.band) if args.band else None),
                                 ('mac_min', args.mac_min), ('fill', args.fill),
                                 ('fill_edges', tuple(args.fill_edges or ()) or None))
               if v is not None}
    if not changes:
        return settings
    from pentapod_sim.analysis.calibration.settings import CalibrationSettings
    from pentapod_sim.schema import build
    data = {f: getattr(settings, f) for f in ('band', 'modes_per_band', 'max_order', 'refine',
                                              'mac_min', 'frequency_tolerance', 'fill',
                                              'fill_edges', 'names', 'quantity')}
    data.update(changes)
    data = {k: (list(v) if isinstance(v, tuple) else v) for k, v in data.items()
            if v is not None}
    return build(CalibrationSettings, data, 'command line')


def _model(args: argparse.Namespace) -> tuple[FEModel, str]:
    """(FE model, label) from --model: a description file or a position name."""
    model_args = argparse.Namespace(fe_model_file=None, machine=None, positions=None,
                                    position=args.model, element_size=None, refine=None)
    if args.model.lower().endswith(('.yaml', '.yml')):
        model_args.fe_model_file = args.model
        return model_from_args(model_args), Path(args.model).stem
    return model_from_args(model_args), args.model


def _measured(args: argparse.Namespace, settings: CalibrationSettings) -> MeasuredFrfs:
    from pentapod_sim.analysis.measured.frf_files import read_csv, read_uff58
    if Path(args.measured).suffix.lower() == '.csv':
        return read_csv(args.measured, settings.quantity)
    return read_uff58(args.measured, settings.node_names)


def run(args: argparse.Namespace) -> int:
    """Read, solve, calibrate and write the report; return the exit code."""
    from pentapod_sim.analysis.calibration import report
    from pentapod_sim.analysis.calibration.update import calibrate
    from pentapod_sim.modes.solver import solve_modes
    from pentapod_sim.plant.build import config_damping
    from pentapod_sim.plant.config import load_reduction_config
    from pentapod_sim.plant.damping_file import write_damping_file
    settings = _settings(args)
    cfg = load_reduction_config(args.config)
    measured = _measured(args, settings)
    LOGGER.info('measured: %d responses x %d references, %d lines %.3g-%.4g Hz (%s)',
                len(measured.responses), len(measured.references), measured.freq.size,
                measured.freq.min(), measured.freq.max(), measured.quantity)
    fe, label = _model(args)
    LOGGER.info('model %s: %d DOF; solving modes below %g Hz', label, fe.n_dof, cfg.modes_f_max)
    modes = solve_modes(fe.K, fe.M, f_max=cfg.modes_f_max,
                        progress=lambda found, wanted, msg: LOGGER.info('modes: %s', msg))
    zeta = config_damping(modes.frequencies, cfg)
    cal = calibrate(fe, modes.frequencies, modes.shapes, zeta, measured, settings,
                    progress=lambda msg: LOGGER.info('%s', msg))
    out = args.out if args.out is not None else Path('out') / 'calibrate' / label
    out.mkdir(parents=True, exist_ok=True)
    damping = write_damping_file(
        out / 'damping.yaml', cal.damping,
        f'Modal damping of {label} calibrated on {args.measured} (calibrate).\n'
        "Use it as damping_file in a reduction config (a path relative to that file's folder).")
    rows = report.pairing_rows(cal)
    errors = report.error_rows(cal, measured.responses, measured.references)
    report.write_rows(out / 'pairing.csv', rows, report.PAIR_COLUMNS)
    report.write_rows(out / 'frf_errors.csv', errors, report.ERROR_COLUMNS)
    png = report.overlay_plot(cal, measured.responses, measured.references, out / 'overlay.png',
                              title=f'{label}: measured {Path(args.measured).name} and model')
    print(report.format_pairing(rows))
    counted = [e for e in errors if e['peaks']]
    fill = (f'Rayleigh alpha {cal.damping.rayleigh.alpha:.4g} 1/s, beta '
            f'{cal.damping.rayleigh.beta:.4g} s' if cal.damping.rayleigh is not None
            else f'{len(cal.damping.bands)} bands')
    print(f'\n{len(rows)} of {cal.identified_hz.size} identified modes paired with the '
          f'{modes.n_modes} model modes; unpaired modes: {fill}')
    if counted:
        worst = max(e['peak_db_before'] for e in counted)
        print(f'peaks (paired modes dominating an FRF, {sum(e["peaks"] for e in counted)} in '
              f'{len(counted)} FRFs): largest error {worst:.2f} dB before, '
              f'{max(e["peak_db_after"] for e in counted):.2f} dB after; median RMS '
              f'{np.median([e["rms_db_before"] for e in errors]):.2f} dB before, '
              f'{np.median([e["rms_db_after"] for e in errors]):.2f} dB after')
    written = [damping, out / 'pairing.csv', out / 'frf_errors.csv', png]
    if args.modes_uff:
        from pentapod_sim.analysis.measured.shapes55 import (
            model_shapes,
            write_port_values,
            write_uff55,
        )
        names = list(dict.fromkeys(r.target for r in measured.responses + measured.references
                                   if not r.is_port and r.target in fe.points))
        written.append(write_uff55(out / 'modes.uff', model_shapes(
            fe, modes.frequencies, modes.shapes, names), cal.zeta_after))
        ports = [p for p in list(cfg.inputs) + list(cfg.outputs) if _has_port(fe, p)]
        written.append(write_port_values(out / 'ports.csv', fe, modes.frequencies,
                                         modes.shapes, ports))
    print('written: ' + ', '.join(str(p) for p in written))
    return 0


def _has_port(fe: FEModel, name: str) -> bool:
    from pentapod_sim.errors import PortError
    from pentapod_sim.plant.ports import port
    try:
        return bool(np.all(np.isfinite(port(fe.points, fe.strut_frames, name).vector)))
    except PortError:
        return False


def main(argv: list[str] | None = None) -> int:
    """Entry point of the `calibrate` executable; returns the exit code."""
    args = _parser().parse_args(argv)
    configure_logging(args.verbose)
    return run_command('calibrate', run, args, errors=(ModalError,))


if __name__ == '__main__':
    sys.exit(main())
