"""
The plate frame's own lowest modes per mesh size: the frame alone, without struts or platform.

The frame on its feet springs (``shell_frame.foot_stiffness``) with the bed mass and inertia on
its bed point, nothing else: the cheap way to see whether the shell frame itself converges with
the mesh (the coupled model's frame modes also move when a frame mode crosses a strut or
platform mode). Per mode: the frequency, the effective mass fractions along x, y, z (of the
frame plus bed; the rigid translations of every DOF) and the feet's share of the strain
energy; the lines follow each global mode (largest effective mass along x, y, z) across the
meshes.

Usage: ``python bench/frame_alone.py [--sizes 0.3,0.2,0.15,0.12] [--modes 12]
[--set shell_frame.wall_thickness=0.01 ...]``.
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
from frame_convergence import machine_for  # noqa: E402
from frame_tuning import with_values  # noqa: E402

from pentapod_sim.fe.frame_model import frame_on_feet  # noqa: E402
from pentapod_sim.modes.solver import solve_modes  # noqa: E402


def frame_alone_modes(machine, size: float | None = None, n_modes: int = 12):
    """Frequencies [Hz], effective mass fractions (n, 3) and feet strain-energy share (n,)."""
    K, M, k_feet, fe = frame_on_feet(machine, size)
    modes = solve_modes(K, M, n_modes=n_modes)
    phi = modes.shapes
    comp = np.arange(fe.n_dof) % 6          # every DOF block is one node's 6 DOFs
    r = np.stack([(comp == d).astype(float) for d in range(3)], axis=1)
    mr = M @ r
    total = np.einsum('id,id->d', r, mr)
    gamma = phi.T @ mr                       # (modes, 3), phi M-normalised
    eff = gamma ** 2 / total
    se = np.einsum('im,im->m', phi, K @ phi)
    feet = np.einsum('im,im->m', phi, k_feet @ phi) / se
    return modes.frequencies, eff, feet, fe.n_dof


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0], allow_abbrev=False)
    parser.add_argument('--sizes', default='0.3,0.2,0.15,0.12')
    parser.add_argument('--modes', type=int, default=12)
    parser.add_argument('--set', action='append', default=[], metavar='KEY=VALUE')
    args = parser.parse_args()
    for size in (float(s) for s in args.sizes.split(',')):
        machine = with_values(machine_for(size), args.set)
        t0 = time.perf_counter()
        f, eff, feet, n_dof = frame_alone_modes(machine, None, args.modes)
        print(f'--- {size:g} m: {n_dof:,} DOF, {time.perf_counter() - t0:.0f} s '
              f'{" ".join(args.set)}', flush=True)
        for k in range(f.size):
            d = 'xyz'[int(np.argmax(eff[k]))]
            print(f'  {f[k]:8.2f} Hz  eff x {eff[k, 0]:.3f} y {eff[k, 1]:.3f} '
                  f'z {eff[k, 2]:.3f}  ({d})  feet {feet[k]:.2f}', flush=True)


if __name__ == '__main__':
    main()
