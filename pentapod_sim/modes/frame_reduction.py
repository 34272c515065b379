"""
Craig-Bampton reduction of the plate frame, cached; and the model builder that ensures it.

:func:`reduce_frame` turns the frame's FE model (:func:`pentapod_sim.fe.frame_model.frame_fe`)
into its superelement: the interface DOFs (feet, BP joint seats, bed), the static constraint
modes ``Psi = -K_ii^-1 K_ib`` and the fixed-interface modes below ``f_cut`` from the
spectrum-slicing solver (:func:`pentapod_sim.modes.solver.solve_modes`, Sturm-counted, so no
mode below ``f_cut`` is missed). :func:`ensure_reduced_frame` does it once per set of frame
parameters and caches the result (:mod:`pentapod_sim.fe.frame_model`); :func:`build_model` is
:func:`pentapod_sim.fe.assembly.build_model` after it, the entry point of every later stage.

Run ``python -m pentapod_sim.modes.frame_reduction [--element-size H]`` to reduce (and cache)
the frame of config/machine.yaml with progress messages. Units: SI, frequencies in Hz.
"""
from __future__ import annotations

import argparse
import logging
import os
import sys
import time
from typing import Callable, Sequence

import numpy as np
import numpy.typing as npt
import scipy.sparse as sp
from threadpoolctl import threadpool_limits

from pentapod_sim.fe.assembly import build_model as build_fe_model
from pentapod_sim.fe.frame_model import (
    frame_fe,
    FrameFE,
    load_reduced,
    reduced_frame_path,
    ReducedFrame,
    remember,
    save_reduced,
)
from pentapod_sim.fe.machine_data import load_machine, MachineParams
from pentapod_sim.fe.model import FEModel
from pentapod_sim.modes import row_split
from pentapod_sim.modes.solver import solve_modes
from pentapod_sim.modes.sturm import choose_backend, Factorisation, factorize_shifted
from pentapod_sim.modes.windows import METHODS

LOG = logging.getLogger(__name__)
Array = npt.NDArray[np.float64]
#: Interface DOFs solved at once for the constraint modes (bounds the dense right-hand side).
RHS_BLOCK = 66
#: Modes per spectrum slice: a shell frame's factorisation costs far more than a beam model's
#: (2D fill), so fewer, larger windows than the solver's default of 30. At 763k DOF a window
#: of 104 modes (80 of them delivered) took 113 s (factorisation and normalisation included)
#: and one of 300 took 218 s: 1.4 against 0.95 s per delivered mode (docs/modes.md).
MODES_PER_WINDOW = 230
#: Window processes of the reduction: one, the windows in this process one after the other,
#: the cores used by its BLAS and MKL threads instead (:func:`frame_threads`): two windows side
#: by side each ran 2-3 times slower, sharing the memory bandwidth (one core reads 15 GB/s
#: here, two together 19 GB/s), and a paper-scale window holds 6-8 GB.
FRAME_WORKERS = 1
#: Window eigensolver of the fixed-interface modes: block shift-invert Lanczos; the same 652
#: modes as ARPACK's at 0.12 m (frequencies to 1e-13) in 97 s instead of 250 s
#: (docs/modes.md, 'Block Lanczos per window').
FRAME_METHOD = 'block'
#: Residual pseudo-modes whose M-norm is below this fraction of the largest are dependent
#: on the others (or on the kept modes) and dropped.
RESIDUAL_RANK_TOL = 1e-10
#: Basis columns per block of the projections T^T A T (bounds ``A @ basis`` to this many
#: columns: 0.8 GB at 763k DOF).
PROJECT_BLOCK = 128
#: Rows of the basis copied at a time where a projected matrix has entries on a part of the
#: frame's DOFs only (at most 0.5 GB at 931 columns).
PROJECT_ROWS = 65536
#: BLAS and MKL threads of a reduction from this many frame DOF on: one per CPU the process
#: may use (below it one, env.sh's choice for small dense work: in the tests two processes
#: share the cores). At 763k DOF on this 2-core machine, idle, two threads against one: a
#: block solve of 16 vectors 0.77 against 0.96 s, a Gram-Schmidt pass against 800 vectors
#: 1.18 against 1.94 s, the numerical factorisation 5.3 against 8.7 s (docs/modes.md).
THREADS_MIN_DOF = 200_000


def _block_solve(lu: Factorisation, rhs: Array) -> Array:
    """``lu.solve`` of the columns of ``rhs``, :data:`RHS_BLOCK` at a time."""
    return np.hstack([lu.solve(np.ascontiguousarray(rhs[:, lo:lo + RHS_BLOCK]))
                      for lo in range(0, rhs.shape[1], RHS_BLOCK)])


def _residual_modes(k_ii: sp.spmatrix, m_ii: sp.spmatrix, static: Array, load: Array,
                    shapes: Array, omega2: Array) -> tuple[Array, Array]:
    """
    Pseudo-modes of the interface inertia loads' residual response (MTA, Dickens 1997).

    ``static`` = K_ii^-1 ``load``; the kept fixed-interface modes' share of it is removed, so
    the rest is what the truncated modes would carry (K- and M-orthogonal to the kept modes).
    It is orthonormalised in M (dependent columns dropped) and diagonalised in K. Returns
    the pseudo-modes (columns) and their omega^2 [rad^2/s^2].
    """
    resid = static - shapes @ ((shapes.T @ load) / omega2[:, None])
    m_r = resid.T @ (m_ii @ resid)
    w, v = np.linalg.eigh(0.5 * (m_r + m_r.T))
    keep = w > RESIDUAL_RANK_TOL * w.max()
    base = v[:, keep] / np.sqrt(w[keep])
    k_r = base.T @ (resid.T @ (k_ii @ resid)) @ base
    lam, vec = np.linalg.eigh(0.5 * (k_r + k_r.T))
    return resid @ (base @ vec), lam


def _symmetric_projection(A: sp.csr_matrix, basis: Array) -> Array:
    """
    ``basis^T A basis`` of a symmetric ``A``, exactly symmetric.

    Only the blocks on and above the diagonal are multiplied (:data:`PROJECT_BLOCK` columns
    at a time), half the dense products of the whole: at the paper-scale frame (763k DOF,
    about 900 columns) each of those is about 1.2e12 flops. Only the rows where ``A`` has
    entries take part (:data:`PROJECT_ROWS` at a time, so no copy of the whole basis): a
    group of the frame costs its share of the dense products (the walls a fifth, the rest
    four fifths), not the whole frame's each.
    """
    m = basis.shape[1]
    rows = np.flatnonzero(np.diff(A.indptr))
    chunks = ([slice(None)] if rows.size == A.shape[0] else
              [rows[lo:lo + PROJECT_ROWS] for lo in range(0, rows.size, PROJECT_ROWS)])
    out = np.zeros((m, m))
    A_rows = row_split.split(A)          # the sparse products on the reduction's threads
    for lo in range(0, m, PROJECT_BLOCK):
        hi = min(lo + PROJECT_BLOCK, m)
        product = A_rows @ basis[:, lo:hi]
        for r in chunks:
            out[:hi, lo:hi] += basis[r, :hi].T @ product[r]
    return np.triu(out) + np.triu(out, 1).T


def frame_threads(n_dof: int) -> int:
    """BLAS and MKL threads of a frame reduction of ``n_dof`` DOF (:data:`THREADS_MIN_DOF`)."""
    return len(os.sched_getaffinity(0)) if n_dof >= THREADS_MIN_DOF else 1


def reduce_frame(fe: FrameFE, f_cut: float, progress: Callable[[str], None] | None = None,
                 workers: int | None = None, residual: bool = True,
                 method: str = FRAME_METHOD, threads: int | None = None) -> ReducedFrame:
    """
    Craig-Bampton reduction of the frame with the fixed-interface modes below ``f_cut`` [Hz].

    Parameters
    ----------
    fe : FrameFE
        The frame's FE model (interface DOFs last).
    f_cut : float
        Highest fixed-interface mode kept [Hz].
    progress : callable, optional
        Receives one message per stage and per spectrum slice.
    workers : int, optional
        Window processes of the modal solver (default :data:`FRAME_WORKERS`).
    residual : bool
        Add the residual pseudo-modes of the interface inertia loads (one per interface DOF,
        :func:`_residual_modes`): the truncated fixed-interface modes' static share of the
        loads the interface's accelerations put on the frame. Without them the coupled modes
        below ``f_cut`` / 1.5 were up to 2.2 % high on the test's coarse frame.
    method : str
        Window eigensolver of the fixed-interface modes
        (:data:`pentapod_sim.modes.windows.METHODS`; default :data:`FRAME_METHOD`).
    threads : int, optional
        BLAS and MKL threads while it runs, and those of its sparse products
        (:mod:`pentapod_sim.modes.row_split`; default :func:`frame_threads`); the process's
        settings are restored after it.

    Returns
    -------
    ReducedFrame
        Reduced coordinates ``[u_b; q]``: the interface DOFs, then the modal coordinates
        (fixed-interface modes, then the residual pseudo-modes).
    """
    n = fe.n_dof
    threads = frame_threads(n) if threads is None else threads
    if threads < 1:
        raise ValueError(f'threads={threads} must be at least 1')
    # chosen first: that loads MKL where PARDISO is used, so that its threads are limited too
    backend = choose_backend(n - 6 * len(fe.interface))
    with threadpool_limits(limits=threads), row_split.threads(threads):
        return _reduce(fe, f_cut, progress, workers, residual, method, backend, threads)


def _reduce(fe: FrameFE, f_cut: float, progress: Callable[[str], None] | None,
            workers: int | None, residual: bool, method: str, backend: str,
            threads: int) -> ReducedFrame:
    """Body of :func:`reduce_frame`, within its thread limits."""
    say = progress or (lambda msg: LOG.info('%s', msg))
    t0 = time.perf_counter()
    n, nb = fe.n_dof, 6 * len(fe.interface)
    i, b = np.arange(n - nb), np.arange(n - nb, n)
    K = fe.K
    k_ii = sp.csr_matrix(K[i][:, i])
    m_ii = sp.csr_matrix(fe.M[i][:, i])
    say(f'frame: {n} DOF ({nb} at {len(fe.interface)} interface points); factorising K_ii '
        f'({backend}, {threads} thread{"s" if threads > 1 else ""})')
    lu = factorize_shifted(k_ii, m_ii, 0.0, backend)
    psi = -_block_solve(lu, K[i][:, b].toarray())
    # the interior's inertia load per unit interface acceleration, and its static response
    load = m_ii @ psi + fe.M[i][:, b].toarray()
    static = _block_solve(lu, load) if residual else None
    del lu
    t_static = time.perf_counter() - t0
    say(f'frame: {nb} constraint modes in {t_static:.1f} s; fixed-interface modes below '
        f'{f_cut:.0f} Hz')

    def slice_progress(found: int, wanted: int | None, msg: str) -> None:
        say(f'frame modes: {msg}')

    modes = solve_modes(k_ii, m_ii, f_max=f_cut, progress=slice_progress,
                        workers=FRAME_WORKERS if workers is None else workers,
                        modes_per_window=MODES_PER_WINDOW, method=method,
                        share_last_windows=True)
    t_modes = time.perf_counter() - t0 - t_static
    say(f'frame: {modes.n_modes} fixed-interface modes in {t_modes:.1f} s; projecting')
    columns, omega2 = [psi, modes.shapes], [modes.omega ** 2]
    if static is not None:
        pseudo, lam_p = _residual_modes(k_ii, m_ii, static, load, modes.shapes,
                                        modes.omega ** 2)
        columns.append(pseudo)
        omega2.append(lam_p)
        del static
    basis = np.hstack(columns)             # interior rows of T = [I 0; Psi Phi Phi_r]
    del psi, columns

    def project(A: sp.csr_matrix) -> Array:
        """T^T A T for the reduced coordinates [u_b; q]."""
        a_ib, a_bb = A[i][:, b], A[b][:, b].toarray()
        out = _symmetric_projection(sp.csr_matrix(A[i][:, i]), basis)
        cross = np.asarray(a_ib.T @ basis)
        out[:nb, :] += cross
        out[:, :nb] += cross.T
        out[:nb, :nb] += a_bb
        return 0.5 * (out + out.T)

    groups = {g: project(A) for g, A in fe.groups.items()}
    mass = project(fe.M)
    t_all = time.perf_counter() - t0
    n_resid = basis.shape[1] - nb - modes.n_modes
    meta = {'n_dof': n, 'n_nodes': fe.n_nodes, 'n_boundary': nb, 'n_modes': modes.n_modes,
            'n_residual': n_resid, 'factorisation': backend, 'method': method,
            'threads': threads,
            'f_cut_hz': float(f_cut), 'static_seconds': t_static, 'modes_seconds': t_modes,
            'reduction_seconds': t_all, 'sturm_count': modes.sturm_count,
            'modes_stats': {k: v for k, v in modes.stats.items()
                            if isinstance(v, (int, float, str))}}
    say(f'frame reduced to {nb} + {modes.n_modes} + {n_resid} residual DOF in {t_all:.1f} s')
    freqs = np.sqrt(np.clip(np.concatenate(omega2), 0.0, None)) / (2.0 * np.pi)
    return ReducedFrame(fe.interface, dict(fe.points), groups, mass, freqs,
                        dict(fe.masses), meta)


def ensure_reduced_frame(machine: MachineParams, cache: str | os.PathLike[str] | None = None,
                         progress: Callable[[str], None] | None = None,
                         method: str | None = None,
                         threads: int | None = None) -> ReducedFrame | None:
    """
    The cached reduced frame of ``machine``, reduced and saved first if needed.

    Returns None for the beam frame (``frame.model: beams``). ``cache``: folder of reduced
    frames (default ``$PENTAPOD_FRAME_CACHE`` or ``out/frames``). ``method`` and ``threads``:
    the window eigensolver and the BLAS and MKL threads of a reduction (defaults
    :data:`FRAME_METHOD` and :func:`frame_threads`; neither is part of the cache key).
    """
    if machine.frame.model != 'shells':
        return None
    path = reduced_frame_path(machine, cache=cache)
    if path.exists():
        try:
            frame = load_reduced(path)
        except (OSError, ValueError, KeyError) as err:
            LOG.warning('reduced frame %s unreadable (%s); reducing again', path, err)
        else:
            remember(path, frame)
            return frame
    say = progress or (lambda msg: LOG.info('%s', msg))
    sh = machine.shell_frame
    assert sh is not None                       # MachineParams checks it
    t0 = time.perf_counter()
    fe = frame_fe(machine)
    say(f'frame: meshed and assembled {fe.n_dof} DOF ({fe.n_nodes} nodes) in '
        f'{time.perf_counter() - t0:.1f} s')
    frame = reduce_frame(fe, sh.mode_multiple * sh.f_interest, say,
                         method=method or FRAME_METHOD, threads=threads)
    frame.meta.update(element_size=sh.element_size, build_seconds=time.perf_counter() - t0,
                      key=path.stem)
    save_reduced(frame, path)
    remember(path, frame)
    say(f'frame: saved {path}')
    return frame


def build_model(machine: MachineParams, pose: npt.ArrayLike | str,
                element_size: float | None = None, installed: bool = True,
                frame_cache: str | None = None,
                progress: Callable[[str], None] | None = None) -> FEModel:
    """:func:`pentapod_sim.fe.assembly.build_model`, after :func:`ensure_reduced_frame`."""
    ensure_reduced_frame(machine, frame_cache, progress)
    return build_fe_model(machine, pose, element_size, installed, frame_cache)


def main(argv: Sequence[str] | None = None) -> int:
    """Reduce and cache the plate frame of a machine file (progress on stderr)."""
    parser = argparse.ArgumentParser(prog='python -m pentapod_sim.modes.frame_reduction',
                                     description=__doc__.split('\n\n')[0], allow_abbrev=False)
    parser.add_argument('--machine', help='machine.yaml (default: the package config)')
    parser.add_argument('--element-size', type=float,
                        help='shell element edge [m] (default: shell_frame.element_size)')
    parser.add_argument('--cache', help='folder of reduced frames (default: out/frames)')
    parser.add_argument('--method', choices=sorted(METHODS), default=FRAME_METHOD,
                        help=f'window eigensolver (default: {FRAME_METHOD})')
    parser.add_argument('--threads', type=int,
                        help='BLAS and MKL threads of the reduction (default: one per CPU from '
                             f'{THREADS_MIN_DOF} frame DOF, else one)')
    args = parser.parse_args(argv)
    if args.threads is not None and args.threads < 1:
        parser.error(f'--threads {args.threads}: must be at least 1')
    logging.basicConfig(level=logging.INFO, format='%(asctime)s %(message)s')
    # scikit-fem logs every basis it builds at INFO: hundreds of lines per frame
    logging.getLogger('skfem').setLevel(logging.WARNING)
    import dataclasses
    machine = load_machine(args.machine)
    if machine.shell_frame is None:
        print('machine file has no shell_frame section', file=sys.stderr)
        return 2
    sh = machine.shell_frame
    if args.element_size:
        sh = dataclasses.replace(sh, element_size=args.element_size)
    machine = dataclasses.replace(machine, shell_frame=sh,
                                  frame=dataclasses.replace(machine.frame, model='shells'))
    frame = ensure_reduced_frame(machine, args.cache, lambda m: print(m, file=sys.stderr),
                                 args.method, args.threads)
    assert frame is not None
    meta = frame.meta
    print(f'{meta["n_dof"]} DOF -> {frame.n_boundary} interface + {meta["n_modes"]} modes (below '
          f'{meta["f_cut_hz"]:.0f} Hz) + {meta["n_residual"]} residual pseudo-modes; reduction '
          f'{meta.get("build_seconds", 0.0):.1f} s')
    return 0


if __name__ == '__main__':
    sys.exit(main())
