"""
Modal solver benchmark: spectrum slicing against a plain shift-invert eigsh.

Spectrum slicing (``pentapod_sim.modal.solver.solve_modes``) against a plain
``scipy.sparse.linalg.eigsh(K, k, M, sigma=0)`` on the same pentapod FE model (position P1).

Each case runs in its own Python process so that its peak resident memory (``ru_maxrss``,
model build included) is its own. Usage::

    python bench/bench_modal.py [--quick]
    python bench/bench_modal.py --case ours --element-size 0.002 --n-modes 500   # one case
"""
from __future__ import annotations

import argparse
import json
import os
from pathlib import Path
import resource
import subprocess
import sys
import time

ROOT = Path(__file__).resolve().parents[1]
#: Element length [m] of the paper-scale model (about 792,000 DOF at P1).
PAPER_ELEMENT_SIZE = 0.000375
#: Element length [m] of the largest model the plain baseline is run on (about 150,000 DOF).
BASELINE_ELEMENT_SIZE = 0.002
BASELINE = 'eigsh(K, k, M, sigma=0)'


def _one_case(kind: str, element_size: float | None, n_modes: int) -> dict:
    """Build the model, solve, and return time [s], peak RSS [GB], DOF and top frequency."""
    import numpy as np
    import scipy.sparse.linalg as spla

    from pentapod_sim.fe import assembly, params
    from pentapod_sim.modal.solver import solve_modes

    model = assembly.build_model(params.load_machine(), 'P1', element_size=element_size)
    t0 = time.perf_counter()
    if kind == 'ours':
        f_top = float(solve_modes(model.K, model.M, n_modes=n_modes).frequencies[-1])
    else:
        lam = spla.eigsh(model.K, n_modes, model.M, sigma=0, return_eigenvectors=True)[0]
        f_top = float(np.sqrt(lam.max()) / (2 * np.pi))
    wall = time.perf_counter() - t0
    return {'time_s': wall, 'peak_rss_gb': resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
            / 1e6, 'n_dof': model.n_dof, 'f_top_hz': f_top}


def _case(kind: str, element_size: float | None, n_modes: int) -> dict:
    cmd = [sys.executable, str(Path(__file__).resolve()), '--case', kind,
           '--n-modes', str(n_modes)]
    if element_size is not None:
        cmd += ['--element-size', repr(element_size)]
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    out = subprocess.run(cmd, capture_output=True, text=True, check=True, env=env)
    return json.loads(out.stdout.strip().splitlines()[-1])


def _pair(label: str, ours: dict, base: dict, note: str) -> list[dict]:
    rows = []
    for key, what, unit in (('time_s', 'wall time', 's'), ('peak_rss_gb', 'peak RSS', 'GB')):
        rows.append({'name': f'{label}: {what}', 'value': ours[key], 'unit': unit,
                     'baseline': BASELINE, 'baseline_value': base[key],
                     'ratio': base[key] / ours[key], 'note': note})
    return rows


def run(quick: bool) -> list[dict]:
    """Return the benchmark rows (quick: default mesh and a 30k-DOF mesh, well under 60 s)."""
    rows = []
    n = 500
    ours, base = _case('ours', None, n), _case('plain', None, n)
    rows += _pair(f'{n} modes, default mesh ({ours["n_dof"]} DOF)', ours, base,
                  f'highest mode {ours["f_top_hz"]:.0f} Hz (baseline {base["f_top_hz"]:.0f})')
    if quick:
        ours, base = _case('ours', 0.01, 150), _case('plain', 0.01, 150)
        rows += _pair(f'150 modes, {ours["n_dof"]} DOF', ours, base, 'element size 10 mm')
        return rows
    ours, base = _case('ours', BASELINE_ELEMENT_SIZE, n), _case('plain', BASELINE_ELEMENT_SIZE, n)
    rows += _pair(f'{n} modes, {ours["n_dof"]} DOF', ours, base, 'element size 2 mm')
    paper = _case('ours', PAPER_ELEMENT_SIZE, n)
    # the baseline is not run at paper scale (estimated > 15 min and > 6 GB on a shared 2-core
    # machine); its cost per restart is O(n ncv^2) and its solves O(nnz(LU)) ~ O(n), so it is
    # extrapolated linearly in n from the measured 150k-DOF case (optimistic for the baseline:
    # our own solves grew faster than linearly with n).
    scale = paper['n_dof'] / base['n_dof']
    extrapolated = {'time_s': base['time_s'] * scale, 'peak_rss_gb': base['peak_rss_gb'] * scale}
    rows += _pair(f'{n} modes, paper scale ({paper["n_dof"]} DOF)', paper, extrapolated,
                  f'baseline EXTRAPOLATED x{scale:.2f} from {base["n_dof"]} DOF, not run; '
                  f'highest mode {paper["f_top_hz"]:.0f} Hz')
    return rows


def main(argv: list[str] | None = None) -> int:
    """Print the benchmark rows, or run one case and print it as JSON (``--case``)."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--quick', action='store_true')
    parser.add_argument('--case', choices=('ours', 'plain'))
    parser.add_argument('--element-size', type=float, default=None)
    parser.add_argument('--n-modes', type=int, default=500)
    args = parser.parse_args(argv)
    if args.case:
        print(json.dumps(_one_case(args.case, args.element_size, args.n_modes)))
        return 0
    for r in run(args.quick):
        print(f'{r["name"]:55s} {r["value"]:9.3g} {r["unit"]:3s} baseline '
              f'{r["baseline_value"]:9.3g}  ratio {r["ratio"]:5.2f}x  {r["note"]}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
