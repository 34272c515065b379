"""
Closed-loop poles per mode: the sampled lockstep loop and the continuous loop, paired by MAC.

The sampled loop is the one the testbed runs (:func:`pentapod_sim.sim.controllers.loop_system`:
zero-order-hold plant, every controller answering ``u_k`` to ``y_k`` through its own dynamics
and delay). Its eigenvalues ``lambda`` map to continuous equivalents ``s = ln(lambda) / dt``
[rad/s], natural frequency ``|s| / 2 pi`` [Hz] and damping ratio ``-Re(s) / |s|``; one pole of
each conjugate pair is kept (``Im s >= 0``). The continuous loop (:func:`continuous_loop_poles`)
closes the continuous modal plant with continuous controllers (a viscous damper's static gain,
its low-pass if any, no delay), so the two together show what sampling costs.

Which poles are structural: every pole is followed from the open loop (controllers' outputs
scaled by t = 0) to the closed loop (t = 1), matching successive eigenvalue sets by the
Hungarian assignment and refining the step where a pole could have come from the other class.
Poles that start at a plant mode are *structural*; those that start at a controller's filter,
delay line or input memory are reported separately (``structural`` False).

Pairing with the open-loop modes: the plant is in modal coordinates, so open-loop mode i is the
unit vector of modal coordinate i. The modal-displacement part ``psi`` of a structural pole's
eigenvector gives ``MAC_i = |psi_i|^2 / |psi|^2`` (mass-weighted, the shapes being
mass-normalised); structural poles and modes are paired by the largest total MAC
(:func:`scipy.optimize.linear_sum_assignment`).

Units: frequencies [Hz], poles [rad/s], sample time [s]; ports as the plant's.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np
from scipy.optimize import linear_sum_assignment

from pentapod_sim.errors import ConfigError
from pentapod_sim.plant.drives import DrivenPlant
from pentapod_sim.plant.model import PlantModel
from pentapod_sim.sim.controllers import controller_blocks, DiscreteController, loop_system
from pentapod_sim.sim.loop_frf import LinearPlant

#: Uniform gain steps of the pole following (refined where ambiguous).
FOLLOW_STEPS = 16
#: Smallest gain step of the refinement.
MIN_STEP = 1e-6


def mac_matrix(shapes: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """
    Modal assurance criterion between the columns of two complex shape matrices.

    ``MAC_jk = |a_j^H b_k|^2 / ((a_j^H a_j)(b_k^H b_k))``; (n_a, n_b), each entry in [0, 1].
    """
    a, b = np.asarray(shapes, dtype=complex), np.asarray(reference, dtype=complex)
    cross = np.abs(a.conj().T @ b) ** 2
    norms = np.outer(np.sum(np.abs(a) ** 2, axis=0), np.sum(np.abs(b) ** 2, axis=0))
    return np.divide(cross, norms, out=np.zeros_like(cross), where=norms > 0)


def pair_by_mac(mac: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rows and columns of the one-to-one pairing with the largest total MAC (Hungarian)."""
    return linear_sum_assignment(np.asarray(mac), maximize=True)


def _scaled(ctrl: DiscreteController, t: float) -> DiscreteController:
    """The controller with its outputs (c, d) scaled by ``t``."""
    return DiscreteController(ctrl.sensor_ports, ctrl.actuator_ports, ctrl.a, ctrl.b,
                              t * ctrl.c, t * ctrl.d)


def continuous_loop_system(plant: LinearPlant, controllers: Sequence[DiscreteController]
                           ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """
    The continuous plant closed with continuous controllers: ``(a, b, c_y)``.

    ``controllers`` hold *continuous* matrices in the :class:`DiscreteController` container:
    ``dxc/dt = a xc + b y``, ``u = c xc + d y + e``; plant ``dx/dt = A x + B u``,
    ``y = C x + D u``. State ``[x; xc]``, ``dz/dt = a z + b e``, ``y = c_y z`` (+ a direct
    term); an algebraic loop through D is solved exactly.
    """
    a, b, c, d = plant.state_matrices()
    n_in, n_out = len(plant.input_names), len(plant.output_names)
    gain, a_c, b_full, c_full = controller_blocks(controllers, plant.input_names,
                                                  plant.output_names)
    n_c = a_c.shape[0]
    loop = np.eye(n_in) - gain @ d
    if np.linalg.cond(loop) > 1e12:
        raise ConfigError('the continuous loop has no solution (I - K D is singular)')
    u_of = np.linalg.solve(loop, np.hstack([gain @ c, c_full]))     # u = u_of z + u_e e
    u_e = np.linalg.inv(loop)
    y_of = np.hstack([c, np.zeros((n_out, n_c))]) + d @ u_of
    a_cl = np.vstack([np.hstack([a, np.zeros((a.shape[0], n_c))]) + b @ u_of,
                      np.hstack([np.zeros((n_c, a.shape[0])), a_c]) + b_full @ y_of])
    b_cl = np.vstack([b @ u_e, b_full @ d @ u_e])
    return a_cl, b_cl, y_of


def _open_loop_start(plant: PlantModel | DrivenPlant, controllers: Sequence[DiscreteController],
                     size: int, dt: float | None) -> tuple[np.ndarray, np.ndarray]:
    """Eigenvalues at t = 0 and their origin: mode index (>= 0) or -1 (controller)."""
    m = plant.n_modes
    if not isinstance(plant, PlantModel):
        lam, origin = _labelled_start(plant, dt)
    elif dt is None:
        w, z = plant.omega, plant.zeta
        root = np.sqrt((z ** 2 - 1).astype(complex))
        lam = np.concatenate([w * (-z + root), w * (-z - root)])
        origin = np.concatenate([np.arange(m), np.arange(m)])
    else:
        lam = np.linalg.eigvals(plant.zoh_blocks(dt)[0]).T.ravel()
        origin = np.concatenate([np.arange(m), np.arange(m)])
    blocks = [np.linalg.eigvals(k.a) for k in controllers if k.n_states]
    ctrl = np.concatenate(blocks) if blocks else np.zeros(0)
    rest = size - lam.size - ctrl.size        # input memory u_{k-1}: eigenvalues 0 at t = 0
    lam = np.concatenate([lam, ctrl, np.zeros(rest)]).astype(complex)
    return lam, np.concatenate([origin, np.full(ctrl.size + rest, -1, dtype=int)])


def _labelled_start(plant: DrivenPlant, dt: float | None) -> tuple[np.ndarray, np.ndarray]:
    """
    Eigenvalues of a plant with the drives' rotors (no controller), every one structural.

    The rotors are part of the machine and couple the modes (with free rotors several struts'
    motions share eigenvalues), so no eigenvalue is one mode's: each is labelled with its own
    index (>= 0, structural), and the structural poles of the loop are paired with the modes
    by MAC at the end (:func:`_poles`). Only the controllers' states start as -1.
    """
    a = plant.state_matrices()[0] if dt is None else plant.discrete_matrices(dt)[0]
    lam = np.linalg.eigvals(a)
    return lam, np.arange(lam.size)


def _match(old: np.ndarray, old_origin: np.ndarray, new: np.ndarray) -> tuple[np.ndarray, bool]:
    """Origins of ``new`` by nearest assignment; False if a pole may have switched class."""
    dist = np.abs(old[:, None] - new[None, :])
    rows, cols = linear_sum_assignment(dist)
    origin = np.empty_like(old_origin)
    origin[cols] = old_origin[rows]
    plant_old = old_origin >= 0
    for r, c in zip(rows, cols):
        other = dist[plant_old != plant_old[r], c]
        if other.size and other.min() < 2 * dist[r, c] and dist[r, c] > 0:
            return origin, False
    return origin, True


def follow_poles(matrix_at: Callable[[float], np.ndarray], start: np.ndarray,
                 start_origin: np.ndarray, steps: int = FOLLOW_STEPS
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """
    Eigenvalues and eigenvectors of ``matrix_at(1)`` with the origin of every eigenvalue.

    ``start`` and ``start_origin`` are the eigenvalues at t = 0 and their labels (mode index or
    -1); the eigenvalues are followed over t in ``steps`` steps, each halved until no pole
    could have come from the other class (down to :data:`MIN_STEP`).
    """
    t, lam, origin = 0.0, start, start_origin
    step = 1.0 / steps
    while t < 1.0:
        t_next = min(1.0, t + step)
        new = np.linalg.eigvals(matrix_at(t_next))
        labels, clear = _match(lam, origin, new)
        if not clear and step > MIN_STEP:
            step /= 2
            continue
        t, lam, origin = t_next, new, labels
        step = min(step * 2, 1.0 / steps)
    final, vectors = np.linalg.eig(matrix_at(1.0))
    rows, cols = linear_sum_assignment(np.abs(lam[:, None] - final[None, :]))
    labels = np.empty_like(origin)
    labels[cols] = origin[rows]
    return final, vectors, labels


@dataclass(frozen=True)
class LoopPoles:
    """
    Closed-loop poles, one of each conjugate pair, with their class and open-loop mode.

    Attributes
    ----------
    s : (p,) complex ndarray
        Continuous(-equivalent) poles [rad/s]; ``-inf`` for a discrete eigenvalue 0 (delay).
    lam : (p,) complex ndarray
        Discrete eigenvalues (sampled loop) or ``s`` (continuous loop).
    structural : (p,) bool ndarray
        The pole starts at a plant mode (False: controller filter, delay or input memory).
    mode : (p,) int ndarray
        Open-loop mode paired by MAC (0-based), -1 for none.
    mac : (p,) ndarray
        MAC with the paired mode (NaN for none).
    dt : float or None
        Sample time [s]; None for the continuous loop.
    index : (p,) int ndarray
        Columns of the kept poles in ``vectors`` (all eigenvalues ``all_lam``).
    all_lam, vectors : ndarray
        Every eigenvalue and eigenvector of the loop (state: plant first, q then dq).
    b, c_y, c_late : ndarray
        External input, output and late-output (``D u_{k-1}``, sampled loop without input
        memory; else zero) matrices of the loop, for :meth:`peaks`.
    """

    s: np.ndarray
    lam: np.ndarray
    structural: np.ndarray
    mode: np.ndarray
    mac: np.ndarray
    dt: float | None
    index: np.ndarray
    all_lam: np.ndarray
    vectors: np.ndarray
    b: np.ndarray
    c_y: np.ndarray
    c_late: np.ndarray

    @property
    def freq_hz(self) -> np.ndarray:
        """Natural frequencies ``|s| / 2 pi`` [Hz]."""
        return np.abs(self.s) / (2 * np.pi)

    @property
    def zeta(self) -> np.ndarray:
        """Damping ratios ``-Re(s) / |s|`` [-] (1 for a real pole, NaN for s = 0)."""
        mag = np.abs(self.s)
        with np.errstate(invalid='ignore', divide='ignore'):
            return np.where(np.isfinite(mag), -self.s.real / mag, 1.0)

    def of_mode(self, mode: int) -> int:
        """Index of the pole paired with open-loop mode ``mode`` (0-based); -1 if none."""
        hit = np.flatnonzero(self.mode == mode)
        return int(hit[0]) if hit.size else -1

    def peaks(self, output: int, input_: int) -> np.ndarray:
        """
        Peak magnitude of every kept pole's term in one FRF [output unit / input unit].

        The term ``r / (z - lambda)`` peaks at ``|r| / (1 - |lambda|)`` on the unit circle
        (sampled loop), ``r / (j w - s)`` at ``|r| / |Re s|`` (continuous); near a lightly
        damped pole that term is the FRF's peak. The late output ``D u_{k-1}`` adds
        ``q / lambda`` to the residue.
        """
        vec = self.vectors[:, self.index]
        right = np.linalg.solve(self.vectors, self.b[:, input_].astype(complex))[self.index]
        r = (self.c_y[output] @ vec) * right
        late = (self.c_late[output] @ vec) * right
        with np.errstate(divide='ignore', invalid='ignore'):
            r = r + np.where(self.lam != 0, late / self.lam, 0.0)
            width = (np.abs(self.lam.real) if self.dt is None else 1.0 - np.abs(self.lam))
            return np.where(width > 0, np.abs(r) / width, np.inf)

    def rows(self, plant: PlantModel | DrivenPlant) -> list[dict[str, float | str]]:
        """
        One dict per pole by frequency: class, frequency, damping, mode, MAC.

        ``mode``: the plant's mode paired by MAC (1-based, 0 for none); ``fe_mode`` and
        ``cause``: the same mode's number in the FE model and its cause
        (:meth:`PlantModel.fe_mode`).
        """
        out: list[dict[str, float | str]] = []
        for j in np.argsort(self.freq_hz):
            i = int(self.mode[j])
            fe_mode, cause = plant.fe_mode(i + 1) if i >= 0 else (0, '')
            out.append({'structural': bool(self.structural[j]),
                        'freq_hz': float(self.freq_hz[j]), 'zeta': float(self.zeta[j]),
                        'mode': i + 1 if i >= 0 else 0, 'fe_mode': fe_mode, 'cause': cause,
                        'open_freq_hz': float(plant.frequencies_hz[i]) if i >= 0 else np.nan,
                        'open_zeta': float(plant.zeta[i]) if i >= 0 else np.nan,
                        'mac': float(self.mac[j])})
        return out


def _poles(plant: PlantModel | DrivenPlant, lam: np.ndarray, vectors: np.ndarray,
           origin: np.ndarray, dt: float | None,
           system: tuple[np.ndarray, np.ndarray, np.ndarray]) -> LoopPoles:
    """Keep one pole per conjugate pair, classify, pair the structural ones by MAC."""
    index = np.flatnonzero(lam.imag >= 0)
    kept, origin = lam[index], origin[index]
    if dt is None:
        s = kept.astype(complex)
    else:
        with np.errstate(divide='ignore'):
            s = np.where(np.abs(kept) > 0, np.log(kept.astype(complex)) / dt, -np.inf)
    structural = origin >= 0
    mode, mac = -np.ones(kept.size, dtype=int), np.full(kept.size, np.nan)
    m = plant.n_modes
    cand = np.flatnonzero(structural)
    if m and cand.size:
        values = mac_matrix(vectors[:m, index[cand]], np.eye(m))
        rows, cols = pair_by_mac(values)
        mode[cand[rows]] = cols
        mac[cand[rows]] = values[rows, cols]
    return LoopPoles(s, kept, structural, mode, mac, dt, index, lam, vectors, *system)


def closed_loop_poles(plant: PlantModel | DrivenPlant,
                      controllers: Sequence[DiscreteController], dt: float,
                      steps: int = FOLLOW_STEPS) -> LoopPoles:
    """
    Poles of the sampled lockstep loop (:func:`sampled_loop`) per mode.

    Parameters
    ----------
    plant : PlantModel or DrivenPlant
        Continuous modal plant (discretised with zero-order hold at ``dt``), or one with the
        feed drives' rotors (:class:`pentapod_sim.plant.drives.DrivenPlant`: its structural
        poles are those that start at the modes it couples, paired with the underlying
        plant's modes).
    controllers : sequence of DiscreteController
        The laws' discrete models at ``dt`` (:func:`pentapod_sim.sim.controllers.controller_of`).
    dt : float
        Sample time [s].
    steps : int
        Initial gain steps of the pole following.
    """
    if not np.isfinite(dt) or dt <= 0:
        raise ConfigError(f'sample time dt must be > 0 s, got {dt!r}')
    a, b, c, d = plant.discrete_matrices(dt)

    def matrix_at(t: float) -> np.ndarray:
        return loop_system(a, b, c, d, plant.input_names, plant.output_names,
                           [_scaled(k, t) for k in controllers]).a
    loop = loop_system(a, b, c, d, plant.input_names, plant.output_names, controllers)
    size = loop.a.shape[0]
    start, origin = _open_loop_start(plant, controllers, size, dt)
    if matrix_at(0.0).shape[0] != size:       # input memory only with gains: start just above 0
        lam0 = np.linalg.eigvals(matrix_at(MIN_STEP))
        origin, _ = _match(start, origin, lam0)
        start = lam0
    lam, vectors, labels = follow_poles(matrix_at, start, origin, steps)
    late = np.zeros_like(loop.c_y) if loop.augmented else d @ loop.c_u
    return _poles(plant, lam, vectors, labels, dt, (loop.b, loop.c_y, late))


def continuous_loop_poles(plant: PlantModel | DrivenPlant,
                          controllers: Sequence[DiscreteController],
                          steps: int = FOLLOW_STEPS) -> LoopPoles:
    """
    Poles of the continuous loop (no sampling, no delay) per mode.

    ``controllers`` carry continuous matrices (:func:`continuous_loop_system`): a viscous
    damper is the static gain ``-b``, a low-pass its continuous state space.
    """
    def matrix_at(t: float) -> np.ndarray:
        return continuous_loop_system(plant, [_scaled(k, t) for k in controllers])[0]
    a, b, c_y = continuous_loop_system(plant, controllers)
    start, origin = _open_loop_start(plant, controllers, a.shape[0], None)
    lam, vectors, labels = follow_poles(matrix_at, start, origin, steps)
    return _poles(plant, lam, vectors, labels, None, (b, c_y, np.zeros_like(c_y)))
