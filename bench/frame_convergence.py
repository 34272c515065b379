"""
Mesh convergence of the plate frame: modes, check model and truncation-check verdicts.

For each shell element size (and the beam frame for reference) at P1 and P2: the modes below
750 Hz, the two frame modes the paper names (first mode with TCP direction x, first with z,
among modes whose strain energy lies mostly in frame + installation), the check model (every
mode below max(5 kHz, 2 x 3 kHz) of config/study.yaml, plant ports, no reduction) and the
truncation check (pentapod_sim.sim.stability.check_loop) of every shipped scenario of
config/study.yaml: the verdict and the spectral radius of the sampled loop on the check model.
Writes the table between the frame-convergence markers of docs/model.md; reduced frames are
cached in out/frames.

Usage: ``python bench/frame_convergence.py [--sizes 0.3,0.2,0.12] [--print-only]``.
"""
from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path
import sys
import time

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))   # run from a checkout
from pentapod_damper.scenario_laws import scenario_laws  # noqa: E402
from pentapod_damper.study.config import load_study_config  # noqa: E402
from pentapod_sim.fe.machine_data import load_machine  # noqa: E402
from pentapod_sim.modes.causes import strain_energy_shares  # noqa: E402
from pentapod_sim.modes.frame_reduction import build_model  # noqa: E402
from pentapod_sim.modes.solver import solve_modes  # noqa: E402
from pentapod_sim.modes.sturm import choose_backend, factorize_shifted  # noqa: E402
from pentapod_sim.plant.build import plant_from_fe, reduce_plant  # noqa: E402
from pentapod_sim.plant.check_model import check_f_max, check_model_from_fe  # noqa: E402
from pentapod_sim.plant.config import load_reduction_config  # noqa: E402
from pentapod_sim.scenario.files import read_scenario  # noqa: E402
from pentapod_sim.sim.stability import check_loop, controller_of  # noqa: E402

F_BAND = 750.0
BEGIN, END = '<!-- frame-convergence:begin -->', '<!-- frame-convergence:end -->'
SHORT = {'stable': 'ok', 'unstable': 'UNSTABLE', 'stable only thanks to truncation': 'TRUNC'}


def machine_for(size: float | None):
    """config/machine.yaml on the beam frame (None) or the plate frame of ``size`` [m]."""
    m = load_machine()
    if size is None:
        return dataclasses.replace(m, frame=dataclasses.replace(m.frame, model='beams'))
    return dataclasses.replace(m, frame=dataclasses.replace(m.frame, model='shells'),
                               shell_frame=dataclasses.replace(m.shell_frame,
                                                               element_size=size))


#: Least share of frame, frame walls and feet in a mode's strain energy for a frame mode.
FRAME_SHARE = 0.4
#: Least share of the TCP's static compliance along an axis (modal dc gain) for a mode to
#: count as a frame mode in that direction.
COMPLIANCE_SHARE = 0.05


def frame_modes(fe, modes) -> tuple[float, float]:
    """
    The paper's two frame modes [Hz], x and z: per axis the lowest frame mode in that direction.

    A frame mode has more than :data:`FRAME_SHARE` of its strain energy in the frame, frame
    walls and feet; it is in direction x (z) if its largest share of the TCP's static
    compliances xx, yy, zz is the one along x (z) and that share is at least
    :data:`COMPLIANCE_SHARE` (share: the modal dc gain ``phi_tcp^2 / omega^2`` over the model's
    static compliance, so it does not depend on how many modes were solved). Taking the lowest
    such mode, not the one with the largest compliance, keeps the pick stable where the
    frame's vertical mode and the platform's vertical mode on the struts lie close together
    and share the TCP's z compliance (the plate frame at 0.12 m: 64.7 and 68.0 Hz at P1, where
    the largest-compliance rule jumped to the feet's bounce mode at 86.5 Hz).
    """
    names = list(fe.stiffness_groups)
    shares = strain_energy_shares(fe.stiffness_groups, modes)
    frame = [g for g, n in enumerate(names) if n in ('frame', 'frame_walls', 'installation')]
    is_frame = shares[:, frame].sum(axis=1) > FRAME_SHARE
    tcp = modes.shapes_at(fe.points['tcp'])[:3]
    gain = tcp ** 2 / modes.omega ** 2
    T = fe.points['tcp'][:3]
    lu = factorize_shifted(fe.K, fe.M, 0.0, choose_backend(fe.n_dof))
    static = np.diag(np.asarray(T @ lu.solve(np.ascontiguousarray(T.T.toarray()))))
    share = gain / static[:, None]
    along = np.argmax(share, axis=0)
    out = []
    for axis in (0, 2):
        hit = np.flatnonzero(is_frame & (along == axis) & (share[axis] >= COMPLIANCE_SHARE))
        out.append(float(modes.frequencies[hit[0]]) if hit.size else np.nan)
    return out[0], out[1]


def pose_modes(size: float | None, position: str, causes: bool = True
               ) -> tuple[dict, object, object]:
    """The model and its modes below 750 Hz at one pose: figures, model, modes.

    ``causes``: count the local frame modes (:func:`analyse_causes`; -1 if not).
    """
    from pentapod_sim.fe.assembly import build_model as build_cached
    from pentapod_sim.modes.causes import analyse_causes
    machine = machine_for(size)
    build_model(machine, position, progress=lambda msg: print(f'  {msg}', flush=True))
    t0 = time.perf_counter()
    fe = build_cached(machine, position)        # the reduced frame read from the cache
    t_build = time.perf_counter() - t0
    modes = solve_modes(fe.K, fe.M, f_max=F_BAND)
    t_modes = time.perf_counter() - t0 - t_build
    fx, fz = frame_modes(fe, modes)
    local = (int(np.count_nonzero(analyse_causes(fe, modes, neuber=False).local_frame))
             if causes else -1)
    return ({'size': size, 'position': position, 'n_dof': fe.n_dof, 'modes': modes.n_modes,
             'local': local, 'fx': fx, 'fz': fz, 'build_s': t_build, 'modes_s': t_modes},
            fe, modes)


def modes_table(rows: list[dict]) -> str:
    """Markdown table of :func:`pose_modes` rows."""
    lines = ['| frame | position | model DOF | modes < 750 Hz | local frame modes | '
             'frame x / z mode [Hz] | model build [s] | modes [s] |', '|' + '---|' * 8]
    for r in rows:
        frame = 'beams' if r['size'] is None else f'shells {r["size"]:g} m'
        lines.append(f'| {frame} | {r["position"]} | {r["n_dof"]:,} | {r["modes"]} | '
                     f'{r["local"]} | {r["fx"]:.1f} / {r["fz"]:.1f} | {r["build_s"]:.2f} | '
                     f'{r["modes_s"]:.2f} |')
    return '\n'.join(lines)


def one(size: float | None, position: str, study, cfg) -> dict:
    figures, fe, modes = pose_modes(size, position, causes=False)
    fx, fz, t_build = figures['fx'], figures['fz'], figures['build_s']
    machine = machine_for(size)
    plant_all, keep = plant_from_fe(fe, cfg, progress=lambda msg: None)
    plant = reduce_plant(plant_all, keep, cfg.static_correction)
    f_check = check_f_max(study.sample_rate, study.check_f_min)
    check = check_model_from_fe(fe, cfg, f_check, progress=lambda msg: None)
    dt = 1.0 / study.sample_rate
    verdicts = {}
    for name in study.scenarios:
        laws = scenario_laws(read_scenario(name).sections, dt)
        result = check_loop(plant, check, [controller_of(law) for law in laws], dt,
                            policy='warn', label=f'{name} at {position}')
        verdicts[name] = (result.verdict, result.check_radius)
    frame = None
    if size is not None:
        from pentapod_sim.fe.frame_model import load_reduced_frame
        frame = load_reduced_frame(machine).meta['n_dof']
    return {'size': size, 'position': position, 'n_dof': fe.n_dof, 'frame_dof': frame,
            'modes': modes.n_modes, 'fx': fx, 'fz': fz, 'check_modes': check.n_modes,
            'f_check': f_check, 'kept': plant.n_modes, 'verdicts': verdicts,
            'seconds': t_build}


def table(results: list[dict], scenarios) -> str:
    head = ('| frame | position | frame DOF | model DOF | modes < 750 Hz | '
            'frame x / z mode [Hz] | kept | check-model modes | ' + ' | '.join(scenarios)
            + ' |')
    lines = [head, '|' + '---|' * (8 + len(scenarios))]
    for r in results:
        frame = 'beams' if r['size'] is None else f'shells {r["size"]:g} m'
        cells = [f'{SHORT.get(v, v)} {rho:.4f}' for v, rho in r['verdicts'].values()]
        lines.append(f'| {frame} | {r["position"]} | {r["frame_dof"] or "-"} | {r["n_dof"]} | '
                     f'{r["modes"]} | '
                     f'{r["fx"]:.1f} / {r["fz"]:.1f} | {r["kept"]} | {r["check_modes"]} '
                     f'(< {r["f_check"]:.0f} Hz) | ' + ' | '.join(cells) + ' |')
    return '\n'.join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0], allow_abbrev=False)
    parser.add_argument('--sizes', default='0.3,0.2,0.12',
                        help='shell element sizes [m], comma separated')
    parser.add_argument('--positions', default='P1,P2')
    parser.add_argument('--doc', default=str(ROOT / 'docs' / 'model.md'),
                        help='markdown file with the frame-convergence markers')
    parser.add_argument('--print-only', action='store_true',
                        help='print the table, leave the markdown file alone (a partial run)')
    parser.add_argument('--modes-only', action='store_true',
                        help='only the modes below 750 Hz, local frame modes, frame modes and '
                             'times per pose (no check model; implies --print-only)')
    args = parser.parse_args()
    study, cfg = load_study_config(), load_reduction_config()
    sizes: list[float | None] = [None] + [float(s) for s in args.sizes.split(',')]
    if args.modes_only:
        print(modes_table([pose_modes(size, position)[0] for size in sizes
                           for position in args.positions.split(',')]))
        return
    results = []
    for size in sizes:
        for position in args.positions.split(','):
            print(f'frame {size or "beams"} at {position}', flush=True)
            results.append(one(size, position, study, cfg))
    text = ('Generated by `python bench/frame_convergence.py` (do not edit). Each verdict '
            "cell: the truncation check of the scenario's sampled loop at "
            f'{study.sample_rate:g} Hz (ok = stable on the plant and on the check model, '
            'TRUNC = stable only thanks to truncation, UNSTABLE = unstable on the plant) and '
            'the spectral radius on the check model. The check model of the plate frame '
            'holds every mode of the coupled model below its cut-off, but the frame enters '
            'it through its Craig-Bampton basis: frame modes above shell_frame.mode_multiple '
            'x f_interest are there only statically (constraint modes).\n\n'
            + table(results, list(study.scenarios)) + '\n')
    print(text)
    if args.print_only:
        return
    doc = Path(args.doc)
    head, rest = doc.read_text(encoding='utf-8').split(BEGIN)
    tail = rest.split(END)[1]
    doc.write_text(f'{head}{BEGIN}\n{text}{END}{tail}', encoding='utf-8')


if __name__ == '__main__':
    main()
