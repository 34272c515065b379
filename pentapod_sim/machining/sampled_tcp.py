"""
The TCP FRF of the sampled closed loop: what the testbed's cutting runs act on.

A cutting node answers y_k with u_k like every lockstep source, and the plant holds the force
over the step (zero-order hold). So the FRF that decides a recorded cut's stability is the
sampled loop's: the zero-order-hold plant closed with the scenario's laws as they run (their
filters, delays and sampling included; :func:`pentapod_sim.sim.closed_loop.closed_loop_system`),
from a held TCP force to the TCP displacement at the steps, ``H(z)`` at ``z = exp(j w dt)``.
Its zero-order lobes are those of the sampled regenerative loop (up to the linear
interpolation of the delay). Below about a tenth of the sample rate it differs from the
continuous FRF by the hold's lag of half a step.

The FRF is evaluated in pole-residue form, ``H(z) = sum_i R_i / (z - l_i)`` (plus the plant's
feed-through acting one step late), from one eigen-decomposition of the loop, on
:func:`pentapod_sim.machining.tcp_frf.resonance_grid` of the loop's continuous-equivalent poles
``ln(l_i) / dt``; checked against a direct solve at a few frequencies, with a Schur form as the
fallback when the eigenvectors are too ill-conditioned.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np
import numpy.typing as npt
import scipy.linalg

from pentapod_sim.errors import ConfigError
from pentapod_sim.machining.tcp_frf import resonance_grid, TCP_DISPLACEMENTS, TCP_FORCES, TcpFrf
from pentapod_sim.plant.model import PlantModel
from pentapod_sim.sim.closed_loop import closed_loop_system, Law
from pentapod_sim.sim.stepping import DiscretePlant

#: Largest relative error of the pole-residue FRF at the test frequencies before the Schur
#: form is used instead.
MAX_RESIDUE_ERROR = 1e-8
#: Frequencies per block of the pole-residue sum (memory: block x states complex numbers).
BLOCK = 4096


@dataclass(frozen=True)
class SampledTcpFrf:
    """
    The sampled loop's TCP FRF and what it rests on.

    Attributes
    ----------
    frf : TcpFrf
        ``H[i, j]`` TCP displacement i per held TCP force j (x, y) [m/N].
    dt : float
        Sample time [s].
    spectral_radius : float
        Largest |eigenvalue| of the loop (below 1: stable).
    poles : ndarray
        Continuous equivalents ``ln(l) / dt`` [rad/s] of the loop's eigenvalues (nonzero ones).
    """

    frf: TcpFrf
    dt: float
    spectral_radius: float
    poles: np.ndarray


def _columns(core: DiscretePlant, names: Sequence[str], what: str) -> list[int]:
    index = core.input_names if what == 'input' else core.output_names
    missing = [n for n in names if n not in index]
    if missing:
        raise ConfigError(f'the plant model lacks the TCP {what}s {", ".join(missing)}')
    return [index.index(n) for n in names]


def sampled_tcp_frf(plant: PlantModel, laws: Sequence[Law], dt: float, f_min: float,
                    f_max: float, label: str = '') -> SampledTcpFrf:
    """
    TCP FRF of the plant held over ``dt`` [s] and closed with ``laws`` (module docstring).

    Parameters
    ----------
    plant : PlantModel
        Continuous plant with the TCP x/y ports (and those of the laws).
    laws : sequence
        Linear laws (``discrete_model()`` or ``linear_gain()``) sampled with ``dt``; empty for
        the open loop.
    dt : float
        Sample time [s].
    f_min, f_max : float
        Band [Hz] of the frequency grid; ``f_max`` below the Nyquist frequency.
    label : str
        Legend text.

    Raises
    ------
    ConfigError
        If the loop is unstable (no lobes: the machine vibrates without cutting), a law has
        no linear model, a TCP port is missing, or the band reaches the Nyquist frequency.
    """
    if not 0 <= f_min < f_max < 0.5 / dt:
        raise ConfigError(f'band {f_min:g}..{f_max:g} Hz must lie below the Nyquist frequency '
                          f'{0.5 / dt:g} Hz')
    core = DiscretePlant(plant.discretize(dt))
    inputs = _columns(core, TCP_FORCES, 'input')
    outputs = _columns(core, TCP_DISPLACEMENTS, 'output')
    loop = closed_loop_system(core, laws)
    lam, vec = np.linalg.eig(loop.a)
    radius = float(np.max(np.abs(lam))) if lam.size else 0.0
    if radius >= 1.0:
        raise ConfigError(f'{label or "the loop"}: the sampled loop at {1 / dt:g} Hz is '
                          f'unstable (spectral radius {radius:.6f}); it has no lobes')
    nonzero = lam[np.abs(lam) > 0]
    poles = np.log(nonzero.astype(complex)) / dt
    freq = resonance_grid(poles, f_min, f_max)
    b = loop.b[:, inputs]
    c_y = loop.c_y[outputs]
    # the plant's feed-through acts on u_{k-1} when the loop state does not hold it
    late = core.d[outputs] if (not loop.augmented and core.has_feedthrough) else None
    c_late = late @ loop.c_u if late is not None else None
    unit = np.zeros((len(core.input_names), 2))
    unit[inputs, [0, 1]] = 1.0
    matrix = _residue_frf(lam, vec, b, c_y, c_late, freq, dt)
    test = freq[np.linspace(0, freq.size - 1, 16).astype(int)]
    direct = _direct_frf(loop.a, b, c_y, c_late, test, dt)
    scale = np.max(np.abs(direct))
    if not np.allclose(_residue_frf(lam, vec, b, c_y, c_late, test, dt), direct, rtol=0,
                       atol=MAX_RESIDUE_ERROR * scale):
        matrix = _schur_frf(loop.a, b, c_y, c_late, freq, dt)
    if late is not None:
        z = np.exp(2j * np.pi * freq * dt)
        matrix = matrix + (late @ unit)[:, :, None] / z[None, None, :]
    return SampledTcpFrf(TcpFrf(freq, matrix, label), dt, radius, poles)


def _residue_frf(lam: np.ndarray, vec: np.ndarray, b: np.ndarray, c_y: np.ndarray,
                 c_late: np.ndarray | None, freq: npt.NDArray[np.float64],
                 dt: float) -> npt.NDArray[np.complex128]:
    """``c (zI - a)^-1 b`` (plus ``c_late`` one step late) from ``a = V diag(lam) V^-1``."""
    right = np.linalg.solve(vec, b.astype(complex))                    # (n, 2)
    n = lam.size
    # residues R_n[i, j] = left[i, n] right[n, j], as (n, 4): one matrix product per block
    res = ((c_y @ vec).T[:, :, None] * right[:, None, :]).reshape(n, 4)
    res_late = (((c_late @ vec).T[:, :, None] * right[:, None, :]).reshape(n, 4)
                if c_late is not None else None)
    z = np.exp(2j * np.pi * np.asarray(freq) * dt)
    out = np.empty((4, z.size), dtype=complex)
    for start in range(0, z.size, BLOCK):
        zs = z[start:start + BLOCK]
        inv = 1.0 / (zs[:, None] - lam[None, :])                       # (F, n)
        h = inv @ res
        if res_late is not None:
            h += (inv @ res_late) / zs[:, None]
        out[:, start:start + BLOCK] = h.T
    return out.reshape(2, 2, z.size)


def _direct_frf(a: np.ndarray, b: np.ndarray, c_y: np.ndarray, c_late: np.ndarray | None,
                freq: npt.NDArray[np.float64], dt: float) -> npt.NDArray[np.complex128]:
    """The same by one dense solve per frequency."""
    eye = np.eye(a.shape[0])
    out = np.empty((2, 2, freq.size), dtype=complex)
    for k, zf in enumerate(np.exp(2j * np.pi * freq * dt)):
        x = np.linalg.solve(zf * eye - a, b)
        out[:, :, k] = c_y @ x + (c_late @ x / zf if c_late is not None else 0.0)
    return out


def _schur_frf(a: np.ndarray, b: np.ndarray, c_y: np.ndarray, c_late: np.ndarray | None,
               freq: npt.NDArray[np.float64], dt: float) -> npt.NDArray[np.complex128]:
    """The same from the complex Schur form ``a = Q T Q^H``: one triangular solve each."""
    t, q = scipy.linalg.schur(a.astype(complex), output='complex')
    qb, cq = q.conj().T @ b, c_y @ q
    lq = c_late @ q if c_late is not None else None
    eye = np.eye(a.shape[0])
    out = np.empty((2, 2, freq.size), dtype=complex)
    for k, zf in enumerate(np.exp(2j * np.pi * freq * dt)):
        x = scipy.linalg.solve_triangular(zf * eye - t, qb)
        out[:, :, k] = cq @ x + (lq @ x / zf if lq is not None else 0.0)
    return out
