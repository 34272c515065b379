"""
The study's key numbers on the beam frame and the plate frame, side by side.

For each frame (``beams``; ``shells`` at the plate mesh of config/machine.yaml) and position of
config/study.yaml: the model's size and modes, the baseline's exact TCP peak, every scenario's
peak and RMS reduction over the study's band, the struts 1+2 share of the all-struts
improvement and the truncation check of every scenario, computed by the study's own analytic
stage (``pentapod_damper.study.pipeline.scenario_analytic``: the same plant, check model,
exact peak search and check_loop) but without its testbed runs, figures or report. Writes the
table between the frame-study markers of docs/model.md (docs/results.md, the study's own
output on the default frame, stays as it is).

Usage: ``python bench/frame_study.py [--size 0.12] [--print-only]`` (``--size``: the plate
mesh [m], default ``shell_frame.element_size``).
"""
from __future__ import annotations

import argparse
from pathlib import Path
import sys
import time

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))   # run from a checkout
sys.path.insert(0, str(ROOT / 'bench'))
from frame_convergence import F_BAND, frame_modes, machine_for  # noqa: E402

from pentapod_damper.study.analytic import improvement_share, peak_and_rms  # noqa: E402
from pentapod_damper.study.config import load_study_config  # noqa: E402
from pentapod_damper.study.pipeline import scenario_analytic  # noqa: E402
from pentapod_damper.study.records import PositionModel  # noqa: E402
from pentapod_sim.fe.machine_data import load_machine  # noqa: E402
from pentapod_sim.modes.frame_reduction import build_model  # noqa: E402
from pentapod_sim.modes.solver import solve_modes  # noqa: E402
from pentapod_sim.plant.build import build_plant  # noqa: E402
from pentapod_sim.plant.check_model import check_f_max, check_model_from_fe  # noqa: E402
from pentapod_sim.plant.config import load_reduction_config  # noqa: E402
from pentapod_sim.reference import replace_section  # noqa: E402

SECTION = 'frame-study'
SHORT = {'stable': 'stable', 'unstable': 'UNSTABLE',
         'stable only thanks to truncation': 'TRUNC'}


def position_numbers(size: float | None, position: str, study, freq) -> dict:
    """Key numbers of one frame (None: beams) at one position."""
    machine = machine_for(size)
    reduction = load_reduction_config()
    fe = build_model(machine, position, progress=lambda msg: print(f'  {msg}', flush=True))
    modes = solve_modes(fe.K, fe.M, f_max=F_BAND)
    plant = build_plant(position, machine, reduction)
    check = check_model_from_fe(fe, reduction, check_f_max(study.sample_rate,
                                                           study.check_f_min))
    model = PositionModel(position, plant, Path(), plant.content_hash(), check)
    lo, hi = float(study.band[0]), float(study.f_max)
    out = {'dof': fe.n_dof, 'modes': modes.n_modes, 'kept': plant.n_modes,
           'check': check.n_modes, 'frame_xz': frame_modes(fe, modes), 'scn': {}}
    for scenario in study.scenarios:
        ana = scenario_analytic(model, scenario, study, freq)
        out['scn'][scenario] = (ana.peak.value, ana.peak.freq_hz,
                                peak_and_rms(ana.continuous, freq, lo, hi)[1],
                                ana.loop.verdict)
    return out


def table(results: dict, study) -> str:
    """Markdown: one column per (frame, position), one row per key number."""
    cols = list(results)
    lines = ['| | ' + ' | '.join(f'{f} {p}' for f, p in cols) + ' |',
             '|---|' + '---|' * len(cols)]

    def row(label: str, cell) -> None:
        lines.append(f'| {label} | ' + ' | '.join(cell(results[c]) for c in cols) + ' |')

    row('model DOF / modes < 750 Hz / kept / check-model modes',
        lambda r: f'{r["dof"]:,} / {r["modes"]} / {r["kept"]} / {r["check"]}')
    row('frame modes x / z [Hz]', lambda r: '{:.1f} / {:.1f}'.format(*r['frame_xz']))
    row('baseline peak [um/N] at [Hz]', lambda r: '{:.2f} at {:.1f}'.format(
        r['scn']['baseline'][0] * 1e6, r['scn']['baseline'][1]))
    for scenario in study.scenarios[1:]:
        row(f'{scenario}: peak / RMS reduction', lambda r, s=scenario: '{:.2f} / {:.2f}'.format(
            r['scn']['baseline'][0] / r['scn'][s][0], r['scn']['baseline'][2] / r['scn'][s][2]))
    names = ('baseline', 'strut_damping_12', 'strut_damping_all')
    if all(n in study.scenarios for n in names):
        row('struts 1+2 share of the all-struts improvement: peak / RMS',
            lambda r: '{:.2f} / {:.2f}'.format(
                improvement_share(*(r['scn'][n][0] for n in names)),
                improvement_share(*(r['scn'][n][2] for n in names))))
    row(f'truncation check, all {len(study.scenarios)} scenarios',
        lambda r: ', '.join(sorted({SHORT.get(v[3], v[3]) for v in r['scn'].values()})))
    return '\n'.join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0], allow_abbrev=False)
    parser.add_argument('--doc', default=str(ROOT / 'docs' / 'model.md'))
    parser.add_argument('--size', type=float,
                        help='plate mesh [m] (default: shell_frame.element_size)')
    parser.add_argument('--print-only', action='store_true',
                        help='print the table, leave the markdown file alone')
    args = parser.parse_args()
    study = load_study_config()
    freq = np.linspace(*study.freq_grid[:2], int(study.freq_grid[2]))
    size = args.size or load_machine().shell_frame.element_size
    command = 'python bench/frame_study.py' + (f' --size {args.size:g}' if args.size else '')
    t0 = time.perf_counter()
    results = {}
    for frame, s in (('beams', None), (f'shells {size:g} m', size)):
        for position in study.positions:
            print(f'{frame} at {position}', flush=True)
            results[(frame, position)] = position_numbers(s, position, study, freq)
    seconds = time.perf_counter() - t0
    text = (f'Generated by `{command}` (do not edit; {seconds:.0f} s). '
            f'TCP {study.direction}{study.direction}, exact peaks over '
            f"{study.band[0]:g}-{study.f_max:g} Hz, RMS over the same band on the study's grid; "
            "reductions are the baseline's value over the scenario's; the truncation check "
            "is the study's (plant and check model, every scenario).\n\n"
            + table(results, study) + '\n')
    print(text)
    if not args.print_only:
        doc = Path(args.doc)
        doc.write_text(replace_section(doc.read_text(encoding='utf-8'), SECTION, text),
                       encoding='utf-8')


if __name__ == '__main__':
    main()
