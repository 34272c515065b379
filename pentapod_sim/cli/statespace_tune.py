"""
`statespace tune`: the gains of a strut damping law that the machine allows.

For each position and law family (:mod:`pentapod_sim.sim.law_families`) the best design under
the machine's constraints (:mod:`pentapod_sim.sim.tuning`): stable on the design plant with the
law's delay and one more sample, at every stiffness corner (struts, joints, feet +-20 %) and on
the check model; static TCP compliance within ``--static-limit`` of the machine without the law;
actuator force RMS per newton of TCP force below ``--effort-limit``. Prints the optimum and
writes per position and family ``tune_<position>_<family>.csv`` (every design evaluated),
``tradeoff_<position>.png`` (peak reduction against static compliance ratio, the Pareto front
of each family) and ``tune.json`` (the optima). Example::

    statespace tune --position P1 --family lag-bending,iff --sample-rate 5000
"""
from __future__ import annotations

import argparse
import csv
from dataclasses import asdict
import json
import logging
from pathlib import Path
from typing import Any, TYPE_CHECKING

import numpy as np

from pentapod_sim.cli.statespace_options import add_config_and_out, POSITIONS_HELP
from pentapod_sim.errors import ConfigError

if TYPE_CHECKING:       # the numerical modules load with the command that needs them
    from pentapod_sim.sim.tuning import TuneResult, TuneSettings

LOGGER = logging.getLogger('statespace')


def add_tune_parser(sub: Any) -> None:
    """Register the ``tune`` sub-command on the ``statespace`` sub-parsers."""
    from pentapod_sim.sim.law_families import FAMILIES, MACHINES
    from pentapod_sim.sim.tuning import OBJECTIVES
    p = sub.add_parser('tune', help="gains of a strut damping law under the machine's "
                       'constraints, and the trade-off against static compliance')
    p.set_defaults(func=cmd_tune)
    add_config_and_out(p)
    p.add_argument('--position', default=None, help=POSITIONS_HELP)
    p.add_argument('--family', default=','.join(FAMILIES),
                   help=f'comma-separated law families ({", ".join(FAMILIES)})')
    p.add_argument('--sample-rate', type=float, default=5000.0, metavar='HZ',
                   help='sample rate of the law [Hz] (default 5000)')
    p.add_argument('--delay', type=int, default=1, metavar='SAMPLES',
                   help="the law's computational delay [samples] (default 1); stability is "
                        'also required with one more')
    p.add_argument('--direction', choices=('x', 'y', 'z'), default='x',
                   help='TCP direction of the objective (default x)')
    p.add_argument('--objective', choices=OBJECTIVES, default='peak',
                   help='peak: minimise the exact TCP peak; damping: maximise the smallest '
                        'damping ratio of the poles that dominate the TCP')
    p.add_argument('--static-limit', type=float, default=1.1, metavar='RATIO',
                   help="largest static TCP compliance over the machine's without the law "
                        '(default 1.1)')
    p.add_argument('--effort-limit', type=float, default=10.0, metavar='N/N',
                   help='largest actuator force RMS per newton of TCP force (default 10)')
    p.add_argument('--machine', choices=MACHINES, default='locked',
                   help='locked: the FE model (drives infinitely stiff, as the study); drives: '
                        'with the feed drives of config/drives.yaml')
    p.add_argument('--struts', default='1,2,3,4,5', help='struts with the law (default all)')
    p.add_argument('--grid', type=int, default=4, metavar='N',
                   help='grid points of each secondary parameter (default 4)')
    p.add_argument('--gain-points', type=int, default=9, metavar='N',
                   help='grid points of the main gain (default 9)')
    p.add_argument('--refine', type=int, default=30, metavar='N',
                   help='Nelder-Mead iterations after the grid (default 30, 0: none)')
    p.add_argument('--no-check', action='store_true',
                   help='skip the check model (every FE mode below max(5 kHz, 2 x rate))')
    p.add_argument('--no-corners', action='store_true',
                   help='skip the stiffness corners (+-20 %% struts, joints, feet)')


def _settings(args: argparse.Namespace) -> TuneSettings:
    from pentapod_sim.sim.law_models import Dynamics
    from pentapod_sim.sim.tuning import TuneSettings
    try:
        struts = tuple(int(s) for s in args.struts.split(',') if s)
    except ValueError:
        raise ConfigError(f'--struts must be numbers 1..5 separated by commas, got '
                          f'{args.struts!r}') from None
    if args.delay < 0:
        raise ConfigError(f'--delay must be >= 0 samples, got {args.delay}')
    return TuneSettings(sample_rate=args.sample_rate, direction=args.direction,
                        objective=args.objective, static_ratio_limit=args.static_limit,
                        effort_limit=args.effort_limit, machine=args.machine, struts=struts,
                        dynamics=Dynamics(delay_steps=args.delay), grid_points=args.grid,
                        gain_points=args.gain_points, refine_iterations=args.refine)


def _write_evaluations(result: TuneResult, path: Path) -> Path:
    names = list(result.evaluations[0].values) if result.evaluations else []
    with open(path, 'w', newline='') as stream:
        writer = csv.writer(stream)
        writer.writerow(names + ['feasible', 'reason', 'peak_reduction', 'rms_reduction',
                                 'static_ratio', 'effort_rms_n_per_n', 'min_zeta', 'radius',
                                 'radius_extra_delay', 'worst_corner_radius'])
        for e in result.evaluations:
            writer.writerow([e.values[n] for n in names] + [
                e.feasible, e.reason, result.baseline.peak / e.peak,
                result.baseline.rms / e.rms, e.static_ratio, e.effort_rms, e.min_zeta,
                e.radius, e.radius_extra, e.corner_radius])
    return path


def _plot(curves: dict[str, list[tuple[float, float]]], position: str, limit: float,
          path: Path) -> Path:
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    from pentapod_sim.figures import save_figure
    fig, ax = plt.subplots(figsize=(7, 4.5))
    for name, points in curves.items():
        if points:
            s, r = zip(*points)
            ax.step(s, r, where='post', marker='o', ms=3, label=name)
    ax.axvline(limit, color='k', lw=0.8, ls='--', label=f'static limit x{limit:g}')
    ax.set_xscale('log')
    ax.set_xlabel('static TCP compliance / machine without the law')
    ax.set_ylabel('TCP peak reduction [x]')
    ax.set_title(f'{position}: best peak reduction per static compliance (robustly stable)')
    ax.grid(True, which='both', alpha=0.3)
    ax.legend(fontsize=8)
    return save_figure(fig, path)


def cmd_tune(args: argparse.Namespace) -> int:
    """Tune the law families at the positions; print and write the optima and trade-offs."""
    from pentapod_sim.sim.design_models import load_design_model
    from pentapod_sim.sim.law_families import family
    from pentapod_sim.sim.tuning import Judge, trade_off, tune
    settings = _settings(args)
    families = [family(name) for name in args.family.split(',') if name]
    positions = [p for p in (args.position or ','.join(args.cfg.positions)).split(',') if p]
    args.out.mkdir(parents=True, exist_ok=True)
    summary: list[dict[str, Any]] = []
    for position in positions:
        model = load_design_model(position, settings.sample_rate, check=not args.no_check,
                                  corners=not args.no_corners, reduction_cfg=args.cfg,
                                  progress=lambda msg: LOGGER.info('%s', msg))
        curves = {}
        for fam in families:
            result = tune(Judge(model, fam, settings), lambda msg: LOGGER.info('%s', msg))
            curves[fam.name] = [(s, r) for s, r, _ in trade_off(result)]
            _write_evaluations(result, args.out / f'tune_{position}_{fam.name}.csv')
            best = result.best
            row: dict[str, Any] = {'position': position, 'family': fam.name,
                                   'machine': settings.machine, 'feasible': best is not None}
            if best is None:
                print(f'{position} {fam.name}: no design meets the constraints')
            else:
                row.update(values=best.values, peak_reduction=result.peak_reduction,
                           static_ratio=best.static_ratio, effort_rms_n_per_n=best.effort_rms,
                           min_zeta=best.min_zeta, check_radius=list(result.check_radius),
                           gain_scale=result.gain_scale)
                gains = ', '.join(f'{k} {v:.4g}' for k, v in best.values.items())
                print(f'{position} {fam.name}: {gains}: TCP {settings.direction} peak '
                      f'{result.peak_reduction:.2f}x lower, static compliance x'
                      f'{best.static_ratio:.3f}, actuator force {best.effort_rms:.3g} N/N RMS, '
                      f'check-model radius {result.check_radius[0]:.6f} / '
                      f'{result.check_radius[1]:.6f} (one more sample of delay)')
            summary.append(row)
        png = _plot(curves, position, settings.static_ratio_limit,
                    args.out / f'tradeoff_{position}.png')
        print(f'wrote {png}')
    settings_doc = {k: (str(v) if not isinstance(v, (int, float, str, tuple)) else v)
                    for k, v in asdict(settings).items()}
    path = args.out / 'tune.json'
    path.write_text(json.dumps({'settings': settings_doc, 'optima': summary}, indent=2,
                               default=lambda v: float(v) if isinstance(v, np.floating)
                               else str(v)))
    print(f'wrote {path}')
    return 0
