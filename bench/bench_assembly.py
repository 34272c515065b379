"""
Benchmark of the FE model assembly (pentapod_sim.fe.assembly.build_model).

Rows: DOF count and wall time at the default mesh and at "paper scale" (~800,000 DOF), and
a same-input comparison of the vectorised COO assembly against the textbook per-element loop
into a ``scipy.sparse.lil_matrix`` (same element matrices, only the assembly differs).
"""
from __future__ import annotations

from pathlib import Path
import sys
import time

import numpy as np
import scipy.sparse as sp

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))   # run from a checkout
from pentapod_sim.fe import beam  # noqa: E402
from pentapod_sim.fe.assembly import build_model  # noqa: E402
from pentapod_sim.fe.machine_data import load_machine  # noqa: E402

PAPER_SCALE_ELEMENT_SIZE = 0.00037   # m, gives about 803,000 DOF


def _line_elements(n_el: int) -> tuple[np.ndarray, np.ndarray]:
    """Global stiffness blocks and DOF indices of a bent chain of strut-like beams."""
    rng = np.random.default_rng(0)
    xyz = np.cumsum(0.01 + 0.01 * rng.random((n_el + 1, 3)), axis=0)
    sec = beam.rhs_section(0.1, 0.13, 0.006)
    lens, axes = beam.local_axes(xyz[:-1], xyz[1:], [0.0, 0.0, 1.0])
    k, _ = beam.local_matrices(lens, 2.1e11, 8.08e10, 7850.0, sec.area, sec.iy, sec.iz,
                               sec.torsion, 5 / 6)
    dofs = 6 * np.arange(n_el)[:, None] + np.arange(12)
    return beam.to_global(k, axes), dofs


def _assemble_coo(k: np.ndarray, dofs: np.ndarray, n: int) -> sp.csr_matrix:
    rows = np.repeat(dofs, 12, axis=1).ravel()
    cols = np.tile(dofs, (1, 12)).ravel()
    return sp.coo_matrix((k.ravel(), (rows, cols)), shape=(n, n)).tocsr()


def _assemble_loop(k: np.ndarray, dofs: np.ndarray, n: int) -> sp.csr_matrix:
    mat = sp.lil_matrix((n, n))
    for e in range(len(k)):
        idx = dofs[e]
        mat[np.ix_(idx, idx)] = mat[np.ix_(idx, idx)].toarray() + k[e]
    return mat.tocsr()


def _timed(func, *args):
    t0 = time.perf_counter()
    out = func(*args)
    return out, time.perf_counter() - t0


def run(quick: bool) -> list[dict]:
    """Return benchmark rows (see bench/run_all.py)."""
    machine = load_machine()
    rows = []
    sizes = [('default mesh', None)] + ([] if quick else
                                        [('paper scale', PAPER_SCALE_ELEMENT_SIZE)])
    for label, size in sizes:
        model, seconds = _timed(build_model, machine, 'P1', size)
        rows.append({'name': f'build_model P1 {label} ({model.n_dof} DOF)', 'value': seconds,
                         'unit': 's', 'baseline': None, 'baseline_value': None, 'ratio': None,
                         'note': f'{model.meta["n_beam_elements"]} beam elements'})
    n_el = 500 if quick else 3000
    k, dofs = _line_elements(n_el)
    n = 6 * (n_el + 1)
    ours, t_ours = _timed(_assemble_coo, k, dofs, n)
    ref, t_ref = _timed(_assemble_loop, k, dofs, n)
    agree = abs(ours - ref).max() <= 1e-9 * abs(ref).max()
    rows.append({'name': f'beam assembly, {n_el} elements', 'value': t_ours, 'unit': 's',
                     'baseline': 'per-element loop into lil_matrix', 'baseline_value': t_ref,
                     'ratio': t_ref / t_ours,
                     'note': 'same matrix' if agree else 'MATRICES DIFFER'})
    return rows


if __name__ == '__main__':
    for row in run(quick=False):
        print(row)
