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
import scipy.sparse.linalg as spla

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
from pentapod_sim.modes.solver import solve_modes

LOG = logging.getLogger(__name__)
Array = npt.NDArray[np.float64]
#: Interface DOFs solved at once for the constraint modes (bounds the dense right-hand side).
RHS_BLOCK = 66
#: Modes per spectrum slice: a shell frame's factorisation costs far more than a beam model's
#: (2D fill), so fewer, larger windows than the solver's default of 30.
MODES_PER_WINDOW = 80


def reduce_frame(fe: FrameFE, f_cut: float, progress: Callable[[str], None] | None = None,
                 workers: int | None = None) -> ReducedFrame:
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
        Window processes of the modal solver (default: its own choice).

    Returns
    -------
    ReducedFrame
        Reduced coordinates ``[u_b; q]``: the interface DOFs, then the modal coordinates.
    """
    say = progress or (lambda msg: LOG.info('%s', msg))
    t0 = time.perf_counter()
    n, nb = fe.n_dof, 6 * len(fe.interface)
    i, b = np.arange(n - nb), np.arange(n - nb, n)
    K = fe.K
    k_ii = sp.csc_matrix(K[i][:, i])
    say(f'frame: {n} DOF ({nb} at {len(fe.interface)} interface points); factorising K_ii')
    lu = spla.splu(k_ii, permc_spec='MMD_AT_PLUS_A', diag_pivot_thresh=0.0,
                   options={'SymmetricMode': True})
    k_ib = K[i][:, b]
    psi = np.hstack([-lu.solve(k_ib[:, lo:lo + RHS_BLOCK].toarray())
                     for lo in range(0, nb, RHS_BLOCK)])
    del lu
    t_static = time.perf_counter() - t0
    say(f'frame: {nb} constraint modes in {t_static:.1f} s; fixed-interface modes below '
        f'{f_cut:.0f} Hz')

    def slice_progress(found: int, wanted: int | None, msg: str) -> None:
        say(f'frame modes: {msg}')

    modes = solve_modes(k_ii, fe.M[i][:, i], f_max=f_cut, progress=slice_progress,
                        workers=workers, modes_per_window=MODES_PER_WINDOW)
    t_modes = time.perf_counter() - t0 - t_static
    say(f'frame: {modes.n_modes} fixed-interface modes in {t_modes:.1f} s; projecting')
    basis = np.hstack([psi, modes.shapes])           # interior rows of T = [I 0; Psi Phi]
    del psi

    def project(A: sp.csr_matrix) -> Array:
        """T^T A T for the reduced coordinates [u_b; q]."""
        a_ib, a_bb = A[i][:, b], A[b][:, b].toarray()
        out = basis.T @ (A[i][:, i] @ basis)
        cross = np.asarray(a_ib.T @ basis)
        out[:nb, :] += cross
        out[:, :nb] += cross.T
        out[:nb, :nb] += a_bb
        return 0.5 * (out + out.T)

    groups = {g: project(A) for g, A in fe.groups.items()}
    mass = project(fe.M)
    t_all = time.perf_counter() - t0
    meta = {'n_dof': n, 'n_nodes': fe.n_nodes, 'n_boundary': nb, 'n_modes': modes.n_modes,
            'f_cut_hz': float(f_cut), 'static_seconds': t_static, 'modes_seconds': t_modes,
            'reduction_seconds': t_all, 'sturm_count': modes.sturm_count,
            'modes_stats': {k: v for k, v in modes.stats.items()
                            if isinstance(v, (int, float, str))}}
    say(f'frame reduced to {nb} + {modes.n_modes} DOF in {t_all:.1f} s')
    return ReducedFrame(fe.interface, dict(fe.points), groups, mass, modes.frequencies,
                        dict(fe.masses), meta)


def ensure_reduced_frame(machine: MachineParams, cache: str | os.PathLike[str] | None = None,
                         progress: Callable[[str], None] | None = None
                         ) -> ReducedFrame | None:
    """
    The cached reduced frame of ``machine``, reduced and saved first if needed.

    Returns None for the beam frame (``frame.model: beams``). ``cache``: folder of reduced
    frames (default ``$PENTAPOD_FRAME_CACHE`` or ``out/frames``).
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
    frame = reduce_frame(fe, sh.mode_multiple * sh.f_interest, say)
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
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format='%(asctime)s %(message)s')
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
    frame = ensure_reduced_frame(machine, args.cache, lambda m: print(m, file=sys.stderr))
    assert frame is not None
    meta = frame.meta
    print(f'{meta["n_dof"]} DOF -> {frame.n_boundary} interface + {frame.n_modes} modes (below '
          f'{meta["f_cut_hz"]:.0f} Hz); reduction {meta.get("build_seconds", 0.0):.1f} s')
    return 0


if __name__ == '__main__':
    sys.exit(main())
