"""
Benchmark of the plate frame (frame.model: shells): Craig-Bampton against the full model.

Same run, same machine, same pose (P1), same solver (spectrum slicing with Sturm counts):

* the frame's reduction (mesh, assembly, constraint modes, fixed-interface modes), once;
* the per-pose model build and modes below ``shell_frame.f_interest`` with the cached frame;
* the baseline: the same pose with the unreduced frame coupled in (every shell DOF), built
  and solved directly.

The note gives DOF, the modes below f_interest of both models and their largest frequency
deviation (the reduction's error at this pose). ``quick`` uses a coarse frame (0.3 m elements,
f_interest 300 Hz); the full run uses config/machine.yaml's mesh and f_interest.
"""
from __future__ import annotations

import dataclasses
import os
from pathlib import Path
import sys
import tempfile
import time

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))   # run from a checkout
from pentapod_sim.fe.assembly import build_model  # noqa: E402
from pentapod_sim.fe.frame_model import frame_fe, unreduced_frame  # noqa: E402
from pentapod_sim.fe.machine_data import load_machine  # noqa: E402
from pentapod_sim.modes.frame_reduction import ensure_reduced_frame  # noqa: E402
from pentapod_sim.modes.solver import solve_modes  # noqa: E402


def shell_machine(quick: bool):
    """config/machine.yaml on the plate frame (coarse if ``quick``)."""
    m = load_machine()
    sh = m.shell_frame
    if quick:
        sh = dataclasses.replace(sh, element_size=0.3, f_interest=300.0)
    return dataclasses.replace(m, frame=dataclasses.replace(m.frame, model='shells'),
                               shell_frame=sh)


def _timed(func, *args, **kwargs):
    t0 = time.perf_counter()
    out = func(*args, **kwargs)
    return out, time.perf_counter() - t0


def run(quick: bool) -> list[dict]:
    """Return benchmark rows (see bench/run_all.py)."""
    machine = shell_machine(quick)
    f_top = machine.shell_frame.f_interest
    load = os.getloadavg()[0]
    with tempfile.TemporaryDirectory() as cache:
        frame, t_reduce = _timed(ensure_reduced_frame, machine, cache, lambda msg: None)

        def per_pose():
            model = build_model(machine, 'P1', frame_cache=cache)
            return model, solve_modes(model.K, model.M, f_max=f_top)

        per_pose()                                  # first call: reads the cache file
        (model, modes), t_pose = _timed(per_pose)

        def direct():
            full = build_model(machine, 'P1', frame_cache=unreduced_frame(frame_fe(machine)))
            return full, solve_modes(full.K, full.M, f_max=f_top)

        (full, full_modes), t_direct = _timed(direct)
    n = min(modes.n_modes, full_modes.n_modes)
    dev = float(np.max(np.abs(modes.frequencies[:n] / full_modes.frequencies[:n] - 1.0)))
    common = (f'P1, {modes.n_modes} (reduced) / {full_modes.n_modes} (full) modes below '
              f'{f_top:g} Hz, largest deviation {100 * dev:.3f} %; load {load:.1f}')
    return [
        {'name': 'plate frame, per-pose model build + modes (cached frame)', 'value': t_pose,
         'unit': 's', 'baseline': 'direct solve of the full model', 'baseline_value': t_direct,
         'ratio': t_direct / t_pose,
         'note': f'{model.n_dof} DOF against {full.n_dof} DOF; {common}'},
        {'name': 'plate frame, Craig-Bampton reduction (once per frame)', 'value': t_reduce,
         'unit': 's', 'baseline': 'direct solve of the full model', 'baseline_value': t_direct,
         'ratio': t_direct / t_reduce,
         'note': f'{frame.meta["n_dof"]} frame DOF -> {frame.n_boundary} interface + '
                 f'{frame.n_modes} fixed-interface modes below {frame.meta["f_cut_hz"]:.0f} '
                 f'Hz (mesh {machine.shell_frame.element_size} m)'},
    ]


if __name__ == '__main__':
    for row in run(quick='--quick' in sys.argv):
        print(row)
