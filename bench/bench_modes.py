"""
Modal solver benchmark: spectrum slicing against a plain shift-invert eigsh, ARPACK vs PRIMME.

Spectrum slicing (``pentapod_sim.modes.solver.solve_modes``, default window solver) against a
plain ``scipy.sparse.linalg.eigsh(K, k, M, sigma=0)`` on the same pentapod FE model (position
P1); in the full run also windows side by side against one at a time, and the window solver
PRIMME (``method='primme'``, if the optional package is installed, within 3x ARPACK's time)
against ARPACK (``method='arpack'``) at about 148k and 789k DOF; without primme, or when it
fails or runs out of time, its rows say so instead of giving a figure.

Each case runs in its own Python process so that its peak resident memory (``ru_maxrss``,
model build included) is its own. Usage::

    python bench/bench_modes.py [--quick]
    python bench/bench_modes.py --case ours --element-size 0.002 --n-modes 500   # one case
    python bench/bench_modes.py --case primme --element-size 0.002               # PRIMME
    python bench/bench_modes.py --case block --element-size 0.002                # block Lanczos
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

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
#: Element length [m] of the paper-scale model (about 792,000 DOF at P1).
PAPER_ELEMENT_SIZE = 0.000375
#: Element length [m] of the largest model the plain baseline is run on (about 150,000 DOF).
BASELINE_ELEMENT_SIZE = 0.002
BASELINE = 'eigsh(K, k, M, sigma=0)'
#: PRIMME's time limit per case, relative to ARPACK's wall time on the same model.
PRIMME_TIME_LIMIT = 3.0
#: Window solver of each case kind (``plain`` is the baseline without slicing).
METHOD = {'ours': None, 'arpack': 'arpack', 'primme': 'primme', 'block': 'block'}


def _one_case(kind: str, element_size: float | None, n_modes: int,
              workers: int | None = None) -> dict:
    """
    Build the model, solve, and return time [s], peak RSS [GB], DOF and top frequency.

    Peak RSS is this process's, and the largest window process's when windows were solved
    side by side.
    """
    extra = {}
    import numpy as np
    import scipy.sparse.linalg as spla

    from pentapod_sim.fe import assembly, machine_data
    from pentapod_sim.modes.solver import solve_modes

    model = assembly.build_model(machine_data.load_machine(), 'P1', element_size=element_size)
    t0, cpu0 = time.perf_counter(), time.process_time()
    if kind in METHOD:
        method = {} if METHOD[kind] is None else {'method': METHOD[kind]}
        res = solve_modes(model.K, model.M, n_modes=n_modes, workers=workers, **method)
        f_top = float(res.frequencies[-1])
        extra = {k: res.stats[k] for k in ('method', 'windows', 'factorisations', 'retries',
                                           'windows_unused', 'window_processes',
                                           'factorisation_time_s', 'eigensolver_time_s',
                                           'max_residual', 'max_orthogonality_error')}
        extra['frequencies_hz'] = res.frequencies.tolist()
    else:
        lam = spla.eigsh(model.K, n_modes, model.M, sigma=0, return_eigenvectors=True)[0]
        f_top = float(np.sqrt(lam.max()) / (2 * np.pi))
    wall, cpu = time.perf_counter() - t0, time.process_time() - cpu0
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6
    child = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1e6
    return {'time_s': wall, 'cpu_s': cpu, 'peak_rss_gb': rss, 'window_process_rss_gb': child,
            'n_dof': model.n_dof, 'f_top_hz': f_top, **extra}


def _case(kind: str, element_size: float | None, n_modes: int,
          workers: int | None = None, timeout: float | None = None) -> dict:
    cmd = [sys.executable, str(Path(__file__).resolve()), '--case', kind,
           '--n-modes', str(n_modes)]
    if workers is not None:
        cmd += ['--workers', str(workers)]
    if element_size is not None:
        cmd += ['--element-size', repr(element_size)]
    path = os.pathsep.join(p for p in (str(ROOT), os.environ.get('PYTHONPATH', '')) if p)
    out = subprocess.run(cmd, capture_output=True, text=True, check=True, timeout=timeout,
                         env=dict(os.environ, PYTHONPATH=path))
    return json.loads(out.stdout.strip().splitlines()[-1])


#: The figures of a case a row can compare: key, what it is, unit.
WALL_TIME = ('time_s', 'wall time', 's')
PEAK_RSS = ('peak_rss_gb', 'peak RSS', 'GB')


def _pair(label: str, ours: dict, base: dict, note: str, baseline: str = BASELINE,
          figures: tuple = (WALL_TIME, PEAK_RSS)) -> list[dict]:
    rows = []
    for key, what, unit in figures:
        rows.append({'name': f'{label}: {what}', 'value': ours[key], 'unit': unit,
                     'baseline': baseline, 'baseline_value': base[key],
                     'ratio': base[key] / ours[key], 'note': note})
    return rows


def _processes(case: dict) -> str:
    """How the windows of a case were solved, and the memory of its window processes."""
    text = (f'{case["windows"]} windows ({case["windows_unused"]} solved ahead and unused, '
            f'{case["retries"]} solved again) in {case["window_processes"]} window process(es)')
    if case['window_processes'] > 1:
        text += f', peak RSS of the largest {case["window_process_rss_gb"]:.1f} GB'
    return text


def _have_primme() -> bool:
    try:
        import primme  # noqa: F401
    except ImportError:
        return False
    return True


def _primme_missing(n: int, n_dof: int, arpack: dict, why: str) -> dict:
    """A PRIMME row without a figure, saying why."""
    return {'name': f'{n} modes, {n_dof} DOF, window solver PRIMME: wall time',
            'value': float('nan'), 'unit': 's',
            'baseline': "window solver ARPACK (solve_modes method='arpack')",
            'baseline_value': arpack['time_s'], 'ratio': float('nan'), 'note': why}


def _primme_rows(arpack: dict, element_size: float, n: int, what: str) -> tuple[list, str]:
    """
    PRIMME's rows on the model ARPACK solved, and '' or why it gave no figure.

    PRIMME gets :data:`PRIMME_TIME_LIMIT` times ARPACK's wall time plus a minute for the
    model build; it stalled on this model before (docs/modes.md).
    """
    limit = PRIMME_TIME_LIMIT * arpack['time_s'] + 60.0
    try:
        primme = _case('primme', element_size, n, timeout=limit)
    except subprocess.TimeoutExpired:
        why = (f"PRIMME did not finish within {limit:.0f} s ({PRIMME_TIME_LIMIT:g}x ARPACK's "
               'time plus a minute) and was stopped')
    except subprocess.CalledProcessError as err:
        why = 'PRIMME failed: ' + ''.join((err.stderr or '').strip().splitlines()[-1:])
    else:
        return _solver_rows(arpack, primme, what), ''
    return [_primme_missing(n, arpack['n_dof'], arpack, f'{what}; {why}')], why


def _solver_rows(arpack: dict, primme: dict, what: str) -> list[dict]:
    """PRIMME against ARPACK as the window solver, same model; frequencies compared."""
    f_a, f_p = (np.array(c['frequencies_hz']) for c in (arpack, primme))
    dev = float(np.max(np.abs(f_p - f_a) / f_a)) if f_a.shape == f_p.shape else float('nan')
    note = (f'{what}; windows/factorisations ARPACK {arpack["windows"]}/'
            f'{arpack["factorisations"]}, PRIMME {primme["windows"]}/'
            f'{primme["factorisations"]}; eigensolver time ARPACK '
            f'{arpack["eigensolver_time_s"]:.0f} s, PRIMME {primme["eigensolver_time_s"]:.0f} s; '
            f'max relative frequency difference {dev:.1e}; max residual PRIMME '
            f'{primme["max_residual"]:.1e}')
    return _pair(f'500 modes, {primme["n_dof"]} DOF, window solver PRIMME', primme, arpack,
                 note, baseline="window solver ARPACK (solve_modes method='arpack')")


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
    ours = _case('arpack', BASELINE_ELEMENT_SIZE, n)
    base = _case('plain', BASELINE_ELEMENT_SIZE, n)
    rows += _pair(f'{n} modes, {ours["n_dof"]} DOF', ours, base,
                  f'element size 2 mm; {_processes(ours)}')
    one = _case('arpack', BASELINE_ELEMENT_SIZE, n, workers=1)
    rows += _pair(f'{n} modes, {ours["n_dof"]} DOF, windows side by side', ours, one,
                  f'{_processes(ours)}; one at a time: {one["windows"]} windows, '
                  f'{one["retries"]} retries', baseline='one window at a time (workers=1)',
                  figures=(WALL_TIME,))
    primme_why = '' if _have_primme() else \
        'not measured: the optional package primme is not installed (pip install primme)'
    if primme_why:
        rows.append(_primme_missing(n, ours['n_dof'], ours, primme_why))
    else:
        more, primme_why = _primme_rows(ours, BASELINE_ELEMENT_SIZE, n, 'element size 2 mm')
        rows += more
    paper = _case('arpack', PAPER_ELEMENT_SIZE, n)
    # the baseline is not run at paper scale (estimated > 15 min and > 6 GB on a shared 2-core
    # machine); its cost per restart is O(n ncv^2) and its solves O(nnz(LU)) ~ O(n), so it is
    # extrapolated linearly in n from the measured 150k-DOF case (optimistic for the baseline:
    # our own solves grew faster than linearly with n).
    scale = paper['n_dof'] / base['n_dof']
    extrapolated = {'time_s': base['time_s'] * scale, 'peak_rss_gb': base['peak_rss_gb'] * scale}
    rows += _pair(f'{n} modes, paper scale ({paper["n_dof"]} DOF)', paper, extrapolated,
                  f'baseline EXTRAPOLATED x{scale:.2f} from {base["n_dof"]} DOF, not run; '
                  f'highest mode {paper["f_top_hz"]:.0f} Hz; window solver ARPACK, '
                  f'{_processes(paper)}, {paper["factorisations"]} factorisations; goal: '
                  'under 300 s')
    if primme_why:
        rows.append(_primme_missing(n, paper['n_dof'], paper, 'paper scale; not run: at '
                                    f'{ours["n_dof"]} DOF {primme_why}'))
    else:
        rows += _primme_rows(paper, PAPER_ELEMENT_SIZE, n, 'paper scale')[0]
    return rows


def main(argv: list[str] | None = None) -> int:
    """Print the benchmark rows, or run one case and print it as JSON (``--case``)."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0], allow_abbrev=False)
    parser.add_argument('--quick', action='store_true')
    parser.add_argument('--case', choices=('plain', *METHOD))
    parser.add_argument('--element-size', type=float, default=None)
    parser.add_argument('--n-modes', type=int, default=500)
    parser.add_argument('--workers', type=int, default=None,
                        help='window processes (default: solve_modes decides)')
    args = parser.parse_args(argv)
    if args.case:
        print(json.dumps(_one_case(args.case, args.element_size, args.n_modes, args.workers)))
        return 0
    for r in run(args.quick):
        print(f'{r["name"]:55s} {r["value"]:9.3g} {r["unit"]:3s} baseline '
              f'{r["baseline_value"]:9.3g}  ratio {r["ratio"]:5.2f}x  {r["note"]}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
