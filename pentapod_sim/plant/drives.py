"""
The struts' feed drives as part of the machine: the motor side of each ball-screw drive.

The FE model holds each strut on its gimbal through the drive link (nut, screw, bearings;
axial stiffness k_a) with the motor locked. A real drive adds the motor side: the rotor,
rotating nut and pulley, whose inertia reflected along the strut is a mass
``m_r = J (2 pi / lead)^2`` at the position ``x_m`` (relative to the gimbal), moved by the
motor force ``F_m`` and held by the link force ``k_a (x_m - delta)``, ``delta`` the strut
against its gimbal (``strut<i>_drive_displacement``)::

    m_r x_m'' = F_m - k_a (x_m - delta),        F_m' = w_c (F_cmd - F_m)

(the current loop as a first-order low-pass of bandwidth ``w_c``). On the plant the link is
already there, so the rotor acts as the force ``k_a x_m`` on ``strut<i>_drive_force`` (the
force of a displacement source in series with the link): with ``x_m = 0`` the machine is the
FE model's. :class:`DrivenPlant` couples the rotors to a modal plant in continuous time and
discretises the whole exactly, so nothing of the stiff link is sampled; its new ports are the
force command ``strut<i>_motor_force`` [N] (what a servo amplifier's velocity loop outputs,
held over a step) and the motor encoder ``strut<i>_motor_position`` [m] and
``strut<i>_motor_velocity`` [m/s] (along the strut). The digital cascade that closes them is
:class:`pentapod_sim.sim.drives.FeedDrives`.

Parameters and their sources: config/drives.yaml (:func:`load_drives`), docs/dampers.md.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
import os
from pathlib import Path
from typing import Any, Sequence

import control
import numpy as np
import numpy.typing as npt
import scipy.linalg as sla

from pentapod_sim.errors import ConfigError, PortError
from pentapod_sim.paths import config_dir
from pentapod_sim.plant.model import PlantModel
from pentapod_sim.schema import internal, load, NON_NEGATIVE, POSITIVE, spec

#: Largest state count discretised with a dense matrix exponential; above it the exact
#: discretisation goes through the eigen-decomposition (a fraction of the cost).
EXPM_STATES = 600


@dataclass(frozen=True)
class DriveParams:
    """Feed-drive parameters of config/drives.yaml (the same for every strut)."""

    rotor_mass: float = spec('kg', POSITIVE, description='rotor, rotating nut and pulley '
                             'inertia reflected along the strut, J (2 pi / lead)^2')
    velocity_bandwidth_hz: float = spec('Hz', POSITIVE, description='velocity-loop bandwidth '
                                        'f_v; P gain K_v = rotor_mass 2 pi f_v')
    velocity_reset_time: float = spec('s', POSITIVE, description='reset (integral) time T_n '
                                      'of the velocity PI')
    position_gain: float = spec('1/s', NON_NEGATIVE, description='position-loop gain K_p '
                                '(the Kv factor)')
    current_bandwidth_hz: float = spec('Hz', POSITIVE, description='current (force) loop as '
                                       'a first-order low-pass')
    delay_steps: int = spec('samples', NON_NEGATIVE, description="the drive's computational "
                            'delay at the loop rate')
    source: str = internal()

    @property
    def velocity_gain(self) -> float:
        """Velocity-loop P gain K_v [N s/m]."""
        return self.rotor_mass * 2 * np.pi * self.velocity_bandwidth_hz


def load_drives(path: str | os.PathLike[str] | None = None) -> DriveParams:
    """Read and validate config/drives.yaml (or ``path``); ConfigError names the bad value."""
    path = Path(path) if path is not None else config_dir() / 'drives.yaml'
    return replace(load(DriveParams, path), source=str(path))


def drives_path(value: str | os.PathLike[str]) -> Path:
    """
    The drives file a node parameter names: the path, or a bare name in the config folder.

    ``drives.yaml`` is config/drives.yaml wherever the node runs (a checkout or installed)
    unless the working folder has a file of that name. ConfigError names a missing file.
    """
    path = Path(value)
    if path.is_file():
        return path
    shipped = config_dir() / path
    if not path.is_absolute() and path.parent == Path('.') and shipped.is_file():
        return shipped
    raise ConfigError(f'drives file {str(value)!r} not found (give a path, or the name of a '
                      f'file in {config_dir()})')


def drive_set(value: str | os.PathLike[str], struts: Sequence[int] = (1, 2, 3, 4, 5)
              ) -> 'DriveSet | None':
    """
    The feed drives of the plant parameters ``drives`` and ``drive_struts``; None for ``''``.

    The one reading of those parameters: the plant node steps them, and every offline model of
    a scenario (:func:`pentapod_sim.scenario.laws.scenario_plant`) closes its laws on them.
    ConfigError names a missing or bad file or bad struts.
    """
    if not str(value):
        return None
    return DriveSet(load_drives(drives_path(value)), tuple(struts))


def link_stiffness(plant: PlantModel, strut: int) -> float:
    """
    Axial stiffness k_a [N/m] of strut ``strut``'s drive link, read from the plant's ports.

    The load cell row is ``-k_a`` times the drive displacement row (both on the same modes),
    so this is the model's own k_a, whatever FE model or stiffness variant it came from.

    Raises
    ------
    PortError
        If the plant lacks ``strut<i>_force`` or ``strut<i>_drive_displacement``.
    ConfigError
        If the two rows are not proportional (not a single spring).
    """
    names = (f'strut{strut}_force', f'strut{strut}_drive_displacement')
    for name in names:
        if name not in plant.output_names:
            raise PortError(f'the feed drive of strut {strut} needs the output {name!r}; the '
                            'plant has none')
    c_f, c_d = (plant.c_disp[plant.output_names.index(n)] for n in names)
    k = -float(c_f @ c_d) / float(c_d @ c_d)
    if not k > 0 or np.linalg.norm(c_f + k * c_d) > 1e-6 * np.linalg.norm(c_f):
        raise ConfigError(f'strut {strut}: the load cell row is not -k_a times the drive '
                          'displacement row; the drive link is not one axial spring')
    return k


def motor_ports(strut: int) -> tuple[str, str, str]:
    """(force command input, encoder position, encoder velocity) of strut ``strut``'s motor."""
    return (f'strut{strut}_motor_force', f'strut{strut}_motor_position',
            f'strut{strut}_motor_velocity')


class DrivenPlant:
    """
    A modal plant with the rotors of the feed drives on the given struts, continuous.

    State ``[x (plant), x_m (per strut), v_m, F_m]``; inputs the plant's and the motors' force
    commands; outputs the plant's and the motor encoders'. ``y = C x + D u`` keeps the plant's
    feed-through (the lockstep ``y_k = C x_k + D u_k-1``); the rotors' force on the drive
    ports is part of the state, so the plant's feed-through of it lands in ``C``.

    Parameters
    ----------
    plant : PlantModel
        Modal plant with ``strut<i>_drive_force`` inputs and ``strut<i>_drive_displacement``,
        ``strut<i>_force`` outputs for the struts.
    params : DriveParams
        The drives.
    struts : sequence of int
        Struts with drives (default all five).
    """

    def __init__(self, plant: PlantModel, params: DriveParams,
                 struts: Sequence[int] = (1, 2, 3, 4, 5)) -> None:
        self.plant, self.params, self.struts = plant, params, tuple(int(i) for i in struts)
        self.link_stiffness = np.array([link_stiffness(plant, i) for i in self.struts])
        self.input_names = list(plant.input_names) + [motor_ports(i)[0] for i in self.struts]
        self.output_names = list(plant.output_names) + [
            motor_ports(i)[k] for k in (1, 2) for i in self.struts]
        self.meta: dict[str, Any] = dict(plant.meta, drives=list(self.struts))
        self._discrete: dict[float, tuple[np.ndarray, ...]] = {}

    def _indices(self, names: Sequence[str], table: Sequence[str]) -> npt.NDArray[np.intp]:
        try:
            return np.array([list(table).index(n) for n in names], dtype=np.intp)
        except ValueError as err:
            raise PortError(f'the drives need the plant port {err}') from None

    def state_matrices(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Continuous A, B, C, D of the plant with its drives' rotors and current loops."""
        a, b, c, d = self.plant.state_matrices()
        n, r = a.shape[0], len(self.struts)
        n_in, n_out = b.shape[1], c.shape[0]
        k = self.link_stiffness
        m, w_c = self.params.rotor_mass, 2 * np.pi * self.params.current_bandwidth_hz
        drive_in = self._indices([f'strut{i}_drive_force' for i in self.struts],
                                 self.plant.input_names)
        delta_out = self._indices([f'strut{i}_drive_displacement' for i in self.struts],
                                  self.plant.output_names)
        # the rotors' force k x_m on the drive ports: u_plant = u_ext + S diag(k) x_m
        s_k = np.zeros((n_in, r))
        s_k[drive_in, np.arange(r)] = k
        xm, vm, fm = slice(n, n + r), slice(n + r, n + 2 * r), slice(n + 2 * r, n + 3 * r)
        size = n + 3 * r
        a_all, b_all = np.zeros((size, size)), np.zeros((size, n_in + r))
        c_all, d_all = np.zeros((n_out + 2 * r, size)), np.zeros((n_out + 2 * r, n_in + r))
        a_all[:n, :n], a_all[:n, xm] = a, b @ s_k
        b_all[:n, :n_in] = b
        # delta = C_d x + D_d (u_ext + S k x_m); m v_m' = F_m - k x_m + k delta
        c_delta, d_delta = c[delta_out], d[delta_out]
        a_all[xm, vm] = np.eye(r)
        a_all[vm, :n] = (k[:, None] * c_delta) / m
        a_all[vm, xm] = (-np.diag(k) + k[:, None] * (d_delta @ s_k)) / m
        a_all[vm, fm] = np.eye(r) / m
        b_all[vm, :n_in] = (k[:, None] * d_delta) / m
        a_all[fm, fm] = -w_c * np.eye(r)
        b_all[fm, n_in:] = w_c * np.eye(r)
        c_all[:n_out, :n], c_all[:n_out, xm] = c, d @ s_k
        d_all[:n_out, :n_in] = d
        c_all[n_out:n_out + r, xm] = np.eye(r)
        c_all[n_out + r:, vm] = np.eye(r)
        return a_all, b_all, c_all, d_all

    def state_scale(self) -> np.ndarray:
        """
        Weights that make every state a mass-normalised coordinate, for the divergence guard.

        The plant's modal coordinates are mass-normalised (sqrt(kg) m, sqrt(kg) m/s): weight 1.
        A rotor's position and velocity weigh ``sqrt(m_r)`` (its own mass-normalised
        coordinates, so its kinetic energy counts as a mode's), its motor force
        ``sqrt(m_r) / k_a``: the rotor displacement that force holds against its link. So one
        ``max_state_norm`` bounds the rotors as tightly as the modes (without the weights a
        motor force of kN alone, held statically under a machining force, exceeds the default
        bound of 1e3).
        """
        n, r = 2 * self.plant.n_modes, len(self.struts)
        root = np.sqrt(self.params.rotor_mass)
        return np.concatenate([np.ones(n), np.full(2 * r, root), root / self.link_stiffness])

    def discrete_matrices(self, dt: float) -> tuple[np.ndarray, np.ndarray, np.ndarray,
                                                    np.ndarray]:
        """Exact zero-order-hold discretisation at ``dt`` [s] (cached per dt)."""
        if not np.isfinite(dt) or dt <= 0:
            raise ConfigError(f'sample time dt must be > 0 s, got {dt!r}')
        if dt not in self._discrete:
            a, b, c, d = self.state_matrices()
            self._discrete[dt] = (*zoh(a, b, dt), c, d)
        a_d, b_d, c, d = self._discrete[dt]
        return a_d.copy(), b_d.copy(), c.copy(), d.copy()

    def discretize(self, dt: float) -> control.StateSpace:
        """Discrete state space (exact ZOH) with the port names, like PlantModel's."""
        a_d, b_d, c, d = self.discrete_matrices(dt)
        return control.ss(a_d, b_d, c, d, dt, inputs=list(self.input_names),
                          outputs=list(self.output_names), name='pentapod_plant_with_drives')

    @property
    def n_modes(self) -> int:
        """Modes of the underlying plant."""
        return self.plant.n_modes

    # the open-loop modes a loop's poles are paired with are the underlying plant's
    @property
    def frequencies_hz(self) -> np.ndarray:
        """Natural frequencies [Hz] of the underlying plant's modes."""
        return self.plant.frequencies_hz

    @property
    def zeta(self) -> np.ndarray:
        """Modal damping ratios [-] of the underlying plant's modes."""
        return self.plant.zeta

    def fe_mode(self, mode: int) -> tuple[int, str]:
        """FE mode number and cause of the underlying plant's mode ``mode`` (1-based)."""
        return self.plant.fe_mode(mode)


@dataclass(frozen=True)
class DriveSet:
    """
    The feed drives a plant steps (plant node parameters ``drives``, ``drive_struts``).

    Attributes
    ----------
    params : DriveParams
        The drives (their ``source`` names the file).
    struts : tuple of int
        Struts with drives, distinct numbers 1..5.
    """

    params: DriveParams
    struts: tuple[int, ...] = (1, 2, 3, 4, 5)

    def __post_init__(self) -> None:
        struts = tuple(int(i) for i in self.struts)
        if not struts or any(not 1 <= i <= 5 for i in struts) or len(set(struts)) != len(struts):
            raise ConfigError('feed-drive struts must be distinct numbers 1..5, got '
                              f'{list(self.struts)}')
        object.__setattr__(self, 'struts', struts)

    def on(self, plant: PlantModel) -> DrivenPlant:
        """``plant`` with these drives' rotors (PortError if it lacks the drive ports)."""
        return DrivenPlant(plant, self.params, self.struts)

    def describe(self) -> str:
        """``<file> on struts [...]`` (the run status' ``drives``)."""
        return f'{self.params.source} on struts {list(self.struts)}'


def with_drives(plant: PlantModel, drives: 'DriveSet | None') -> 'PlantModel | DrivenPlant':
    """
    ``plant`` as a plant node with these feed drives steps it.

    ``drives.on(plant)``, or ``plant`` itself for None (no drives): the one place that choice
    is made.
    """
    return plant if drives is None else drives.on(plant)


def zoh(a: np.ndarray, b: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """
    Exact zero-order-hold ``(A_d, B_d)`` of ``dx/dt = a x + b u`` over ``dt`` [s].

    Small systems by Van Loan's augmented exponential; large ones by the eigen-decomposition
    ``a = V diag(l) V^-1``: ``A_d = V diag(e^(l dt)) V^-1``, ``B_d = V diag((e^(l dt) - 1) / l)
    V^-1 b`` (``dt`` for l = 0), a fraction of a dense exponential's cost for the thousands of
    states of a check model with drives.
    """
    n, m = a.shape[0], b.shape[1]
    if n <= EXPM_STATES:
        expo = sla.expm(np.block([[a, b], [np.zeros((m, n + m))]]) * dt)
        return expo[:n, :n], expo[:n, n:]
    lam, vec = np.linalg.eig(a)
    if not np.linalg.cond(vec) < 1e10:
        raise ConfigError('the plant with its drives is (nearly) defective; no exact '
                          'discretisation by eigenvectors')
    inv = np.linalg.inv(vec)
    ed = np.exp(lam * dt)
    with np.errstate(divide='ignore', invalid='ignore'):
        phi1 = np.where(np.abs(lam * dt) > 1e-12, (ed - 1) / lam, dt)
    a_d = ((vec * ed) @ inv).real
    b_d = ((vec * phi1) @ (inv @ b)).real
    return a_d, b_d
