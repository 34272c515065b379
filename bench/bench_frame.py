"""
Benchmark of the plate frame (frame.model: shells): Craig-Bampton against the full model.

Same run, same machine, same pose (P1), same solver (spectrum slicing with Sturm counts):

* the frame's reduction (mesh, assembly, constraint modes, fixed-interface modes), once;
* the per-pose model build and modes below ``shell_frame.f_interest`` with the cached frame;
* the baseline: the same pose with the unreduced frame coupled in (every shell DOF), built
  and solved directly.

The note gives DOF, the modes below f_interest of both models and their largest frequency
deviation (the reduction's error at this pose). A third row measures the factorisation the
frame's reduction and the modal solver repeat per spectrum window: MKL PARDISO's LDL^T
(optional dependency ``pypardiso``) against scipy's SuperLU on the frame's interior stiffness
shifted into the spectrum, one thread each. A fourth times one spectrum window of the frame's
reduction (the fixed-interface modes nearest 500 Hz, as many as the reduction asks a window
for) with the block shift-invert Lanczos against ARPACK's, on the same factorisation, at 0.2 m
elements in both modes. A fifth times the reduction's sparse products split into blocks of
rows on threads (:mod:`pentapod_sim.modes.row_split`, hand-written: scipy's product runs on
one core) against scipy's (``--row-split`` alone). ``quick`` uses a coarse frame (0.3 m
elements, f_interest 300 Hz); the full run uses config/machine.yaml's mesh and f_interest,
and adds the reduction at paper scale (0.04 m elements, 763,416 DOF; about 10 minutes and
19 GB; ``--paper`` alone) against the default mesh's in the same run.
"""
from __future__ import annotations

import dataclasses
import os
from pathlib import Path
import resource
import sys
import tempfile
import time

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))   # run from a checkout
from pentapod_sim.fe.assembly import build_model  # noqa: E402
from pentapod_sim.fe.frame_model import frame_fe, interface_dofs, unreduced_frame  # noqa: E402
from pentapod_sim.fe.machine_data import load_machine  # noqa: E402
from pentapod_sim.modes.causes import mass_mac  # noqa: E402
from pentapod_sim.modes.frame_reduction import (  # noqa: E402
    ensure_reduced_frame,
    MODES_PER_WINDOW,
    PROJECT_BLOCK,
    reduce_frame,
)
from pentapod_sim.modes.row_split import RowSplit  # noqa: E402
from pentapod_sim.modes.slicing import LANCZOS_TOL, WINDOW_PAD  # noqa: E402
from pentapod_sim.modes.solver import solve_modes  # noqa: E402
from pentapod_sim.modes.sturm import choose_backend, factor_at  # noqa: E402
from pentapod_sim.modes.windows import BLOCK_SIZE, mass_normalise, window_eigs  # noqa: E402

#: Element size [m] of the window row's frame (48,522 interior DOF; a window in seconds).
WINDOW_MESH = 0.2
#: Element size [m] of the paper-scale row: 763,416 frame DOF (the paper's model: about
#: 800,000 DOF).
PAPER_MESH = 0.04
#: The goal for the paper-scale reduction [s] (issue 30: under 10 minutes on this machine).
PAPER_GOAL = 600.0


def shell_machine(quick: bool, element_size: float | None = None):
    """config/machine.yaml on the plate frame (coarse if ``quick``; else ``element_size`` [m])."""
    m = load_machine()
    sh = m.shell_frame
    if quick:
        sh = dataclasses.replace(sh, element_size=0.3, f_interest=300.0)
    elif element_size is not None:
        sh = dataclasses.replace(sh, element_size=element_size)
    return dataclasses.replace(m, frame=dataclasses.replace(m.frame, model='shells'),
                               shell_frame=sh)


def _interior(machine):
    """``K_ii``, ``M_ii`` of the frame's FE model: every DOF but the interface's (last)."""
    fe = frame_fe(machine)
    inner = np.arange(fe.n_dof - 6 * len(fe.interface))
    return fe.K[inner][:, inner].tocsr(), fe.M[inner][:, inner].tocsr()


def _timed(func, *args, **kwargs):
    t0 = time.perf_counter()
    out = func(*args, **kwargs)
    return out, time.perf_counter() - t0


def _on_feet(frame, K, machine):
    """``K`` of the frame (full or reduced) with the installation's feet springs added."""
    inst = machine.installation
    k6 = [inst.foot_stiffness_x, inst.foot_stiffness_y, inst.foot_stiffness_z, 0, 0, 0]
    diag = np.zeros(K.shape[0])
    for i in range(1, 6):
        diag[interface_dofs(frame, f'foot{i}')] += k6
    return K + sp.diags(diag)


def accuracy_row() -> dict:
    """
    Craig-Bampton against the full frame on its feet, with and without residual pseudo-modes.

    The test's coarse frame (0.3 m, f_interest 300 Hz, fixed-interface modes to
    ``mode_multiple`` x); the modes below f_interest.
    """
    machine = shell_machine(quick=True)
    sh = machine.shell_frame
    fe = frame_fe(machine)
    full = solve_modes(_on_feet(fe, fe.K, machine).tocsr(), fe.M, f_max=sh.f_interest)
    n = full.n_modes
    b_full = np.concatenate([interface_dofs(fe, p) for p in fe.interface])
    figures = {}
    for residual in (False, True):
        red = reduce_frame(fe, sh.mode_multiple * sh.f_interest, lambda msg: None,
                           residual=residual)
        lam, phi = sla.eigh(_on_feet(red, sum(red.groups.values()), machine), red.M)
        err = np.sqrt(lam[:n]) / (2 * np.pi) / full.frequencies - 1.0
        mac = np.diag(mass_mac(full.shapes[b_full], phi[:red.n_boundary, :n],
                               sp.identity(len(b_full))))
        figures[residual] = (100 * float(np.max(np.abs(err))), float(mac.min()),
                             red.n_boundary + red.n_modes)
    (e0, m0, r0), (e1, m1, r1) = figures[False], figures[True]
    return {'name': 'plate frame, Craig-Bampton error with residual pseudo-modes', 'value': e1,
            'unit': '%', 'baseline': 'without them (fixed-interface modes only)',
            'baseline_value': e0, 'ratio': e0 / e1,
            'note': f'largest frequency error of the {n} modes below {sh.f_interest:g} Hz of '
                    f'the frame on its feet ({fe.n_dof} DOF, mesh {sh.element_size} m, '
                    f'fixed-interface modes to {sh.mode_multiple:g} x); lowest interface MAC '
                    f'{m1:.4f} against {m0:.4f}; {r1} against {r0} reduced DOF'}


def factorisation_row(machine) -> dict | None:
    """PARDISO against SuperLU on ``K_ii - sigma M_ii`` of the frame (None without PARDISO)."""
    K, M = _interior(machine)
    if choose_backend(K.shape[0]) != 'pardiso':
        return None
    sigma = (2 * np.pi * machine.shell_frame.f_interest) ** 2     # inside the spectrum
    rhs = np.random.default_rng(0).standard_normal((K.shape[0], 66))
    out = {}
    for backend in ('superlu', 'pardiso'):
        factor = factor_at(K, M, sigma, backend)
        _, t_solve = _timed(factor.lu.solve, rhs)
        fill = (factor.lu.factor_nnz if backend == 'pardiso'
                else factor.lu.L.nnz)       # SymmetricMode: U = D L^T, as many as L
        out[backend] = (factor.seconds, t_solve, fill, factor.count)
        del factor
    (t_s, s_s, n_s, c_s), (t_p, s_p, n_p, c_p) = out['superlu'], out['pardiso']
    if c_s != c_p:
        raise RuntimeError(f'Sturm counts differ: SuperLU {c_s}, PARDISO {c_p}')
    return {'name': 'plate frame, factorisation of K_ii - sigma M_ii (PARDISO LDL^T)',
            'value': t_p, 'unit': 's', 'baseline': 'SuperLU (scipy), symmetric mode',
            'baseline_value': t_s, 'ratio': t_s / t_p,
            'note': f'{K.shape[0]} DOF (mesh {machine.shell_frame.element_size} m), shift '
                    f'{machine.shell_frame.f_interest:g} Hz, same Sturm count {c_p}; fill '
                    f'{n_p / 1e6:.1f}M against {n_s / 1e6:.1f}M (L); 66 solves '
                    f'{s_p:.2f} s against {s_s:.2f} s; OMP_NUM_THREADS='
                    f'{os.environ.get("OMP_NUM_THREADS", "unset")}; load '
                    f'{os.getloadavg()[0]:.1f}'}


def window_row() -> dict:
    """One window of the frame's fixed-interface modes: block Lanczos against ARPACK."""
    K, M = _interior(shell_machine(quick=False, element_size=WINDOW_MESH))
    factor = factor_at(K, M, (2 * np.pi * 500.0) ** 2)
    k = int(WINDOW_PAD * MODES_PER_WINDOW)
    out = {}
    for method in ('arpack', 'block'):
        (lam, phi), seconds = _timed(window_eigs, K, M, factor, k, method, LANCZOS_TOL)
        out[method] = (seconds, lam, float(mass_normalise(K, M, lam, phi).max()))
    (t_a, lam_a, r_a), (t_b, lam_b, r_b) = out['arpack'], out['block']
    dev = float(np.max(np.abs(lam_b / lam_a - 1.0)))
    return {'name': 'plate frame, one spectrum window (block shift-invert Lanczos)',
            'value': t_b, 'unit': 's', 'baseline': "ARPACK's shift-invert Lanczos",
            'baseline_value': t_a, 'ratio': t_a / t_b,
            'note': f'{K.shape[0]} interior DOF (mesh {WINDOW_MESH} m), the {k} modes nearest '
                    f'500 Hz, one {choose_backend(K.shape[0])} factorisation ({factor.seconds:.1f}'
                    f' s, not counted); blocks of {BLOCK_SIZE}; eigenvalues agree to {dev:.1e}; '
                    f'max residual {r_b:.1e} against {r_a:.1e}; load {os.getloadavg()[0]:.1f}'}


def row_split_row(machine) -> dict:
    """The reduction's sparse products in row blocks on threads against scipy's one thread."""
    K, _ = _interior(machine)
    X = np.random.default_rng(0).standard_normal((K.shape[0], PROJECT_BLOCK))
    parts = max(2, len(os.sched_getaffinity(0)))
    split = RowSplit(K, parts)

    def best_of_3(product):
        return min((_timed(product, X) for _ in range(3)), key=lambda timed: timed[1])

    (ours, t_ours), (theirs, t_theirs) = best_of_3(split.__matmul__), best_of_3(K.__matmul__)
    return {'name': f'plate frame, K_ii times {PROJECT_BLOCK} vectors in {parts} row blocks '
                    'on threads (row_split)',
            'value': t_ours, 'unit': 's', 'baseline': "scipy's CSR product (one thread)",
            'baseline_value': t_theirs, 'ratio': t_theirs / t_ours,
            'note': f'{K.shape[0]} interior DOF, {K.nnz} non-zeros (mesh '
                    f'{machine.shell_frame.element_size} m); the same numbers: '
                    f'{np.array_equal(ours, theirs)}; best of 3; load {os.getloadavg()[0]:.1f}'}


def paper_row(default_seconds: float, default_mesh: float, default_threads: int) -> dict:
    """The frame's reduction at paper scale (progress on stderr), against the default mesh's."""
    machine = shell_machine(quick=False, element_size=PAPER_MESH)
    load = os.getloadavg()[0]
    with tempfile.TemporaryDirectory() as cache:
        frame, seconds = _timed(ensure_reduced_frame, machine, cache,
                                lambda msg: print(f'  {msg}', file=sys.stderr, flush=True))
    meta, stats = frame.meta, frame.meta['modes_stats']
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024 ** 2   # kB -> GB
    return {'name': 'plate frame, Craig-Bampton reduction at paper scale (once per frame)',
            'value': seconds, 'unit': 's',
            'baseline': f'the same at the default mesh ({default_mesh} m), this run',
            'baseline_value': default_seconds, 'ratio': default_seconds / seconds,
            'note': f'{meta["n_dof"]} frame DOF (mesh {PAPER_MESH} m) -> {frame.n_boundary} '
                    f'interface + {meta["n_modes"]} fixed-interface modes below '
                    f'{meta["f_cut_hz"]:.0f} Hz + {meta["n_residual"]} residual pseudo-modes; '
                    f'constraint modes {meta["static_seconds"]:.0f} s, fixed-interface modes '
                    f'{meta["modes_seconds"]:.0f} s ({stats["windows"]} windows, '
                    f'{stats.get("gap_windows", 0)} in gaps, {stats["retries"]} solved again, '
                    f'{stats["factorisations"]} factorisations); {meta["threads"]} BLAS and '
                    f'MKL threads (the default mesh: {default_threads}); goal {PAPER_GOAL:.0f} s: '
                    f'{"met" if seconds < PAPER_GOAL else "NOT met"}; peak RSS of the bench '
                    f'process {peak:.1f} GB; load {load:.1f}'}


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
                 f'{frame.meta["n_modes"]} fixed-interface modes below '
                 f'{frame.meta["f_cut_hz"]:.0f} Hz + {frame.meta["n_residual"]} residual '
                 f'pseudo-modes (mesh {machine.shell_frame.element_size} m, factorisation '
                 f'{frame.meta["factorisation"]})'},
        accuracy_row(),
        window_row(),
        row_split_row(machine),
    ] + [row for row in [factorisation_row(machine)] if row is not None] + (
        [] if quick else [paper_row(t_reduce, machine.shell_frame.element_size,
                                    frame.meta['threads'])])


if __name__ == '__main__':
    if '--accuracy' in sys.argv:
        print(accuracy_row())
    elif '--window' in sys.argv:
        print(window_row())
    elif '--row-split' in sys.argv:
        print(row_split_row(shell_machine(quick=False)))
    elif '--paper' in sys.argv:
        default = shell_machine(quick=False)
        with tempfile.TemporaryDirectory() as tmp:
            small, t_default = _timed(ensure_reduced_frame, default, tmp, lambda msg: None)
        print(paper_row(t_default, default.shell_frame.element_size, small.meta['threads']))
    else:
        for row in run(quick='--quick' in sys.argv):
            print(row)
