"""
FRFs of a sampled closed loop in pole-residue form: exact peaks, band RMS, efforts, statics.

The loop is the testbed's (:func:`pentapod_sim.sim.controllers.loop_system`: zero-order-hold
plant, every controller answering ``u_k`` to ``y_k`` through its own dynamics and delay).
One eigen-decomposition ``a = V diag(l) V^-1`` gives every FRF from an external input as
``H(z) = sum_i r_i / (z - l_i) + z^-1 (sum_i q_i / (z - l_i) + d)`` at ``z = exp(j w dt)``
(the second sum: the plant's feed-through acting on ``u_k-1`` when the loop state does not
hold it), so a peak is searched at the resonances
(:func:`pentapod_sim.plant.frf_peaks.maximise_near_poles`) and a band RMS integrated on a grid
refined at every resonance instead of read from a uniform grid that misses 0.1 % peaks.

Units: as the plant ports; frequencies [Hz].
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Protocol, Sequence

import numpy as np
import numpy.typing as npt
import scipy.linalg as sla

from pentapod_sim.errors import ConfigError
from pentapod_sim.plant.frf_peaks import maximise_near_poles, Peak
from pentapod_sim.sim.controllers import DiscreteController, loop_system, LoopSystem

Matrices4 = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]


class LinearPlant(Protocol):
    """What a loop needs of a plant: port names and its continuous and ZOH matrices."""

    @property
    def input_names(self) -> list[str]:
        """Input port names."""

    @property
    def output_names(self) -> list[str]:
        """Output port names."""

    def state_matrices(self) -> Matrices4:
        """Continuous A, B, C, D."""

    def discrete_matrices(self, dt: float) -> Matrices4:
        """Exact zero-order-hold A_d, B_d, C, D at ``dt`` [s]."""

#: Largest relative error of the pole-residue resolvent at the test points (a closed loop
#: with clusters of nearly equal poles, e.g. one filter on ten channels, has ill-conditioned
#: eigenvectors; what counts is whether the sum over the cluster is still right).
MAX_RESOLVENT_ERROR = 1e-7
#: Points per resonance of the RMS grid, spread over this many decay rates each side.
RESONANCE_POINTS, RESONANCE_DECAYS = 81, 10.0


@dataclass(frozen=True)
class PairFrf:
    """One FRF of the sampled loop: ``H(f)`` callable, with its continuous-equivalent poles."""

    dt: float
    lam: np.ndarray
    r: np.ndarray
    q: np.ndarray
    d_late: float
    direct: float
    fir: np.ndarray = field(default_factory=lambda: np.zeros(0))

    @property
    def poles(self) -> np.ndarray:
        """Continuous equivalents ``ln(l) / dt`` [rad/s] (-inf for l = 0)."""
        with np.errstate(divide='ignore'):
            return np.where(self.lam != 0, np.log(self.lam.astype(complex)) / self.dt, -np.inf)

    def __call__(self, freq_hz: npt.ArrayLike) -> np.ndarray:
        """Complex FRF at the frequencies [Hz] (below Nyquist)."""
        z = np.exp(2j * np.pi * np.asarray(freq_hz, dtype=float) * self.dt).reshape(-1)
        out = np.empty(z.shape, dtype=complex)
        for start in range(0, z.size, 2048):
            part = z[start:start + 2048]
            inv = 1.0 / (part[:, None] - self.lam[None, :])
            out[start:start + 2048] = (inv @ self.r + self.direct
                                       + (inv @ self.q + self.d_late) / part)
            if self.fir.size:                   # the nilpotent part: sum h_k z^-(k+1)
                powers = part[:, None] ** -np.arange(1, self.fir.size + 1)[None, :]
                out[start:start + 2048] += powers @ self.fir
        return out.reshape(np.shape(freq_hz))

    def peak(self, f_lo: float, f_hi: float) -> Peak:
        """Largest |H| on [f_lo, f_hi] Hz, searched at the resonances."""
        poles = self.poles
        return maximise_near_poles(lambda f: np.abs(self(f)), poles[np.isfinite(poles)],
                                   f_lo, f_hi)

    def rms(self, f_lo: float, f_hi: float, spacing_hz: float = 0.1) -> float:
        """``sqrt(mean |H|^2)`` over [f_lo, f_hi] Hz (trapezoids, refined at resonances)."""
        return float(np.sqrt(band_mean_square(self, self.poles, f_lo, f_hi, spacing_hz)))


def band_grid(poles: npt.ArrayLike, f_lo: float, f_hi: float,
              spacing_hz: float = 0.1) -> np.ndarray:
    """A uniform grid on [f_lo, f_hi] Hz plus dense points around every resonance in it."""
    p = np.asarray(poles, dtype=complex)
    p = p[np.isfinite(p) & (p.imag > 0)]
    fd, decay = p.imag / (2 * np.pi), np.abs(p.real) / (2 * np.pi)
    inside = (fd >= f_lo) & (fd <= f_hi)
    offsets = np.linspace(-RESONANCE_DECAYS, RESONANCE_DECAYS, RESONANCE_POINTS)
    dense = (fd[inside, None] + np.maximum(decay[inside], 1e-9 * fd[inside])[:, None]
             * offsets[None, :]).ravel()
    grid = np.concatenate([np.linspace(f_lo, f_hi, max(2, int((f_hi - f_lo) / spacing_hz))),
                           dense[(dense > f_lo) & (dense < f_hi)]])
    return np.unique(grid)


def band_mean_square(frf: Callable[[np.ndarray], np.ndarray], poles: npt.ArrayLike,
                     f_lo: float, f_hi: float, spacing_hz: float = 0.1) -> float:
    """Mean of ``|frf(f)|^2`` over [f_lo, f_hi] Hz on :func:`band_grid` (trapezoids)."""
    grid = band_grid(poles, f_lo, f_hi, spacing_hz)
    mag2 = np.abs(frf(grid)) ** 2
    return float(np.sum(0.5 * (mag2[1:] + mag2[:-1]) * np.diff(grid)) / (f_hi - f_lo))


class SampledLoop:
    """
    The sampled loop of a modal plant and discrete controllers, decomposed once.

    Parameters
    ----------
    plant : LinearPlant
        A modal plant (:class:`~pentapod_sim.plant.model.PlantModel`) or one with drives
        (:class:`~pentapod_sim.plant.drives.DrivenPlant`), discretised exactly at ``dt``.
    controllers : sequence of DiscreteController
        The laws at ``dt`` (empty: the open loop).
    dt : float
        Sample time [s].
    """

    def __init__(self, plant: LinearPlant, controllers: Sequence[DiscreteController],
                 dt: float) -> None:
        if not np.isfinite(dt) or dt <= 0:
            raise ConfigError(f'sample time dt must be > 0 s, got {dt!r}')
        a, b, c, d = plant.discrete_matrices(dt)
        self.plant, self.dt, self.d = plant, float(dt), d
        self.system = loop_system(a, b, c, d, plant.input_names, plant.output_names,
                                  list(controllers))
        self.lam, self._left, self._right_of, self._nil = modal_form(self.system.a)
        self._late = (not self.system.augmented) and bool(np.any(d))

    @property
    def spectral_radius(self) -> float:
        """Largest |eigenvalue| (>= 1: not asymptotically stable)."""
        return float(np.abs(self.lam).max(initial=0.0))

    def _pair(self, row: np.ndarray, input_: str, late_row: np.ndarray | None = None,
              d_late: float = 0.0) -> PairFrf:
        """Pole-residue form of ``row (zI - a)^-1 b_j`` (plus the late term)."""
        j = self.plant.input_names.index(input_)
        column = self.system.b[:, j].astype(complex)
        right = self._right_of(column)
        r = self._left(row) * right[0]
        fir = self._nil(row, right[1])
        q = np.zeros_like(r)
        if late_row is not None:
            q = self._left(late_row) * right[0]
            fir_late = self._nil(late_row, right[1])
            if fir_late.size:         # z^-1 (sum h_k z^-(k+1)): one power of z^-1 later
                both = np.zeros(max(fir.size, fir_late.size + 1), dtype=complex)
                both[:fir.size] += fir
                both[1:1 + fir_late.size] += fir_late
                fir = both
        return PairFrf(self.dt, self.lam[:r.size], r, q, d_late, 0.0, fir)

    def output(self, output: str, input_: str) -> PairFrf:
        """FRF of a plant output per unit external input on ``input_``."""
        o = self.plant.output_names.index(output)
        s = self.system
        if self._late:
            j = self.plant.input_names.index(input_)
            return self._pair(s.c_y[o], input_, self.d[o] @ s.c_u, float(self.d[o, j]))
        return self._pair(s.c_y[o], input_)

    def effort(self, actuator: str, input_: str) -> PairFrf:
        """FRF of the controllers' total effort on ``actuator`` per unit external input."""
        return self._pair(self.system.c_u[self.plant.input_names.index(actuator)], input_)

    def static(self, output: str, input_: str) -> float:
        """Static gain ``H(z = 1)`` (real) of an output per unit external input."""
        return loop_static(self.plant, self.system, self.d, output, input_)


def loop_static(plant: LinearPlant, system: LoopSystem, d: np.ndarray, output: str,
                input_: str) -> float:
    """``H(z = 1)`` of a :func:`~pentapod_sim.sim.controllers.loop_system` (one solve)."""
    j = plant.input_names.index(input_)
    o = plant.output_names.index(output)
    x = np.linalg.solve(np.eye(system.a.shape[0]) - system.a, system.b[:, j])
    value = system.c_y[o] @ x
    if not system.augmented and np.any(d):
        value += d[o] @ (system.c_u @ x + np.eye(len(plant.input_names))[j])
    return float(value)


def static_gain(plant: LinearPlant, controllers: Sequence[DiscreteController], dt: float,
                output: str, input_: str) -> float:
    """Static gain of the sampled loop of ``plant`` and ``controllers`` (no decomposition)."""
    a, b, c, d = plant.discrete_matrices(dt)
    system = loop_system(a, b, c, d, plant.input_names, plant.output_names, list(controllers))
    return loop_static(plant, system, d, output, input_)


Resolvent = tuple[np.ndarray, Callable[[np.ndarray], np.ndarray],
                  Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]],
                  Callable[[np.ndarray, np.ndarray], np.ndarray]]


def modal_form(a: np.ndarray, zero_tol: float = 1e-10) -> Resolvent:
    """
    Eigenvalues of ``a`` and the maps of its resolvent, robust to the delay lines' Jordan chains.

    Delay cells and input memory give ``a`` exactly-zero eigenvalues in chains (nilpotent, not
    diagonalisable), so ``np.linalg.eig`` has no usable eigenvectors there. The complex Schur
    form ``a = Q T Q^H`` is sorted with the nonzero eigenvalues first, decoupled from the zero
    block ``N`` by a Sylvester solve, and the nonzero block diagonalised; then
    ``row (zI - a)^-1 col = sum_i l_i r_i / (z - lam_i) + sum_k (row_N N^k col_N) z^-(k+1)``
    (the second sum is finite: N is nilpotent).

    ``a`` is balanced first (a diagonal similarity ``a = S b S^-1``, LAPACK's balancing as
    ``np.linalg.eig`` does): a loop with the drives' rotors mixes link stiffnesses of 4e8 N/m
    with metres and radians (entries up to 1e10), and the unbalanced Schur form's backward
    error of eps ||a|| moved its eigenvalues by up to 0.2 (a spurious pole of modulus 1.23
    for HAC-LAC at P1, where the loop's largest is 0.99991; test/test_loop_frf.py).

    Returns
    -------
    lam : (n,) complex ndarray
        Every eigenvalue (the zero block's as 0).
    left : callable
        ``row -> l`` (one entry per nonzero eigenvalue).
    right : callable
        ``col -> (r, col_N)``.
    nil : callable
        ``(row, col_N) -> h`` (FIR coefficients of the zero block, possibly empty).
    """
    balanced, (scale, _) = sla.matrix_balance(a, permute=False, separate=True)
    t, q, k = sla.schur(balanced.astype(complex), output='complex',
                        sort=lambda x: abs(x) > zero_tol)
    t11, t12, t22 = t[:k, :k], t[:k, k:], t[k:, k:]
    x = sla.solve_sylvester(t11, -t22, -t12) if k and k < t.shape[0] else np.zeros((k, 0))
    lam1, v1 = np.linalg.eig(t11)
    v1_inv = np.linalg.inv(v1) if k else v1
    lam = np.concatenate([lam1, np.zeros(t.shape[0] - k)])
    _validate(t11, lam1, v1, v1_inv)

    def left(row: np.ndarray) -> np.ndarray:
        w = (row * scale) @ q                      # row D Q S, S = [[I, X], [0, I]]
        return w[:k] @ v1

    def right(col: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        w = q.conj().T @ (col / scale)             # S^-1 Q^H D^-1 col
        top = w[:k] - x @ w[k:]
        return v1_inv @ top, w[k:]

    def nil(row: np.ndarray, col_n: np.ndarray) -> np.ndarray:
        if k == t.shape[0]:
            return np.zeros(0)
        w = (row * scale) @ q
        row_n = w[:k] @ x + w[k:]
        out, vec = [], col_n
        for _ in range(t22.shape[0]):
            out.append(row_n @ vec)
            vec = t22 @ vec
            if not np.any(np.abs(vec) > 0):
                break
        return np.array(out)
    return lam, left, right, nil


def _validate(t11: np.ndarray, lam: np.ndarray, v: np.ndarray, v_inv: np.ndarray) -> None:
    """ConfigError unless ``V diag(1 / (z - lam)) V^-1`` solves ``(zI - T) x = w`` at test z."""
    n = t11.shape[0]
    if n == 0:
        return
    rng = np.random.default_rng(0)
    w = rng.standard_normal(n) + 1j * rng.standard_normal(n)
    for angle in (0.0137, 0.31, 1.7):
        z = np.exp(1j * angle)
        exact = sla.solve_triangular(z * np.eye(n) - t11, w)
        modal = v @ ((v_inv @ w) / (z - lam))
        error = np.linalg.norm(modal - exact) / np.linalg.norm(exact)
        if not error < MAX_RESOLVENT_ERROR:
            raise ConfigError(f'the closed loop is (nearly) defective: its pole-residue form '
                              f'errs by {error:.1e} at z = exp({angle} j)')
