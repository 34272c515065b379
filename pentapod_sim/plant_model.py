"""
The reduced modal plant: continuous and discrete state space, save/load.

State order: ``x = [q_1..q_m, dq_1..dq_m]`` (modal displacements [sqrt(kg) m] and their
rates), so that ``A = [[0, I], [-W^2, -2 Z W]]``, ``B = [0; b]``, ``C = [c_disp, c_vel]``.
External modal data (frequencies plus mass-normalised shapes at the named points) enters
through :func:`from_modal_data` (files: :mod:`pentapod_sim.modal_data`); the whole chain for a
machine position is :func:`build_plant`.
"""
from __future__ import annotations

from dataclasses import dataclass, field
import hashlib
import json
import logging
import zipfile
from pathlib import Path
from typing import Callable, Mapping, Sequence

import control
import numpy as np
import numpy.typing as npt
import scipy.linalg as spla
import yaml

from pentapod_sim.exceptions import ConfigError, ModelFileError, PortError
from pentapod_sim.ports import (check_names, INPUT_NAMES, input_matrix, modal_points,
                                output_matrices, OUTPUT_NAMES)
from pentapod_sim.ports import ports as port_list
from pentapod_sim.reduction import (modal_dc_gains, modal_resonance_gains, select_modes,
                                    static_compliance)

LOG = logging.getLogger(__name__)

_ARRAYS = ('omega', 'zeta', 'b', 'c_disp', 'c_vel', 'd')
_LISTS = ('input_names', 'output_names', 'input_units', 'output_units',
          'input_descriptions', 'output_descriptions')
FILE_FORMAT = 'pentapod-plant-model-1'


@dataclass
class PlantModel:
    """
    Modal state-space plant model with named ports.

    Attributes
    ----------
    omega : (m,) ndarray
        Natural angular frequencies of the kept modes [rad/s].
    zeta : (m,) ndarray
        Modal damping ratios [-].
    b : (m, n_in) ndarray
        Modal input matrix ``Phi^T B``.
    c_disp, c_vel : (n_out, m) ndarray
        Modal output matrices acting on modal displacements and modal velocities.
    d : (n_out, n_in) ndarray
        Feed-through (static correction of dropped modes for displacement outputs).
    input_names, output_names : list of str
        Port names (docs/architecture.md).
    input_units, output_units, input_descriptions, output_descriptions : list of str
        SI units and descriptions of the ports.
    meta : dict
        JSON-serialisable provenance: position, pose, machine parameter hash, package version,
        kept mode indices, reduction settings.
    """

    omega: npt.NDArray[np.float64]
    zeta: npt.NDArray[np.float64]
    b: npt.NDArray[np.float64]
    c_disp: npt.NDArray[np.float64]
    c_vel: npt.NDArray[np.float64]
    d: npt.NDArray[np.float64]
    input_names: list[str]
    output_names: list[str]
    input_units: list[str]
    output_units: list[str]
    input_descriptions: list[str]
    output_descriptions: list[str]
    meta: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        """Convert to float arrays and check shapes (ModelFileError names the mismatch)."""
        for name in _ARRAYS:
            setattr(self, name, np.asarray(getattr(self, name), dtype=float))
        m = self.omega.size
        self.zeta = np.broadcast_to(self.zeta, (m,)).copy() if self.zeta.ndim == 0 else self.zeta
        n_in, n_out = len(self.input_names), len(self.output_names)
        expected = {'zeta': (m,), 'b': (m, n_in), 'c_disp': (n_out, m), 'c_vel': (n_out, m),
                    'd': (n_out, n_in)}
        for name, shape in expected.items():
            if getattr(self, name).shape != shape:
                raise ModelFileError(f'{name} has shape {getattr(self, name).shape}, expected '
                                     f'{shape} for {m} modes, {n_in} inputs, {n_out} outputs')
        for name in _LISTS:
            if len(getattr(self, name)) != (n_in if name.startswith('input') else n_out):
                raise ModelFileError(f'{name} has {len(getattr(self, name))} entries')
        if np.any(self.omega < 0) or np.any(self.zeta < 0):
            raise ConfigError('omega and zeta must be >= 0; got min omega '
                              f'{self.omega.min(initial=0)}, min zeta {self.zeta.min(initial=0)}')

    @property
    def n_modes(self) -> int:
        """Number of modes m (state dimension 2 m)."""
        return self.omega.size

    @property
    def frequencies_hz(self) -> npt.NDArray[np.float64]:
        """Natural frequencies [Hz]."""
        return self.omega / (2 * np.pi)

    def state_names(self) -> list[str]:
        """Names of the 2 m states: q1..qm, dq1..dqm."""
        return ([f'q{i + 1}' for i in range(self.n_modes)]
                + [f'dq{i + 1}' for i in range(self.n_modes)])

    def state_matrices(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """
        Continuous-time matrices A (2m, 2m), B (2m, n_in), C (n_out, 2m), D (n_out, n_in).
        """
        m = self.n_modes
        a = np.zeros((2 * m, 2 * m))
        a[:m, m:] = np.eye(m)
        a[m:, :m] = -np.diag(self.omega ** 2)
        a[m:, m:] = -np.diag(2 * self.zeta * self.omega)
        b = np.vstack([np.zeros_like(self.b), self.b])
        c = np.hstack([self.c_disp, self.c_vel])
        return a, b, c, self.d.copy()

    def to_statespace(self) -> control.StateSpace:
        """Continuous modal state space with named inputs, outputs and states."""
        a, b, c, d = self.state_matrices()
        return control.ss(a, b, c, d, inputs=list(self.input_names),
                          outputs=list(self.output_names), states=self.state_names(),
                          name='pentapod_plant')

    def zoh_blocks(self, dt: float) -> tuple[np.ndarray, np.ndarray]:
        """
        Exact zero-order-hold discretisation, mode by mode.

        Parameters
        ----------
        dt : float
            Sample time [s], > 0.

        Returns
        -------
        phi : (m, 2, 2) ndarray
            Per mode ``expm(A_i dt)`` acting on ``[q_i, dq_i]``.
        gamma : (m, 2) ndarray
            Per mode ``int_0^dt expm(A_i s) ds [0, 1]^T``; the modal force is ``b_i . u``.

        Notes
        -----
        One batched 3x3 matrix exponential per mode (Van Loan's block trick), which is exact
        for any damping including omega = 0; cost O(m) instead of expm of the full 2m x 2m A.
        """
        if not np.isfinite(dt) or dt <= 0:
            raise ConfigError(f'sample time dt must be > 0 s, got {dt!r}')
        m = self.n_modes
        blocks = np.zeros((m, 3, 3))
        blocks[:, 0, 1] = 1.0
        blocks[:, 1, 0] = -self.omega ** 2
        blocks[:, 1, 1] = -2 * self.zeta * self.omega
        blocks[:, 1, 2] = 1.0
        expo = spla.expm(blocks * dt)
        return expo[:, :2, :2].copy(), expo[:, :2, 2].copy()

    def discrete_matrices(self, dt: float) -> tuple[np.ndarray, np.ndarray, np.ndarray,
                                                    np.ndarray]:
        """Discrete (ZOH) matrices A_d, B_d, C, D in the state order of :meth:`state_names`."""
        phi, gamma = self.zoh_blocks(dt)
        m = self.n_modes
        idx = np.arange(m)
        a_d = np.zeros((2 * m, 2 * m))
        a_d[idx, idx] = phi[:, 0, 0]
        a_d[idx, idx + m] = phi[:, 0, 1]
        a_d[idx + m, idx] = phi[:, 1, 0]
        a_d[idx + m, idx + m] = phi[:, 1, 1]
        b_d = np.vstack([gamma[:, :1] * self.b, gamma[:, 1:] * self.b])
        return a_d, b_d, np.hstack([self.c_disp, self.c_vel]), self.d.copy()

    def discretize(self, dt: float) -> control.StateSpace:
        """
        Discrete state space (exact ZOH, sample time ``dt`` [s]) with the same names.
        """
        a_d, b_d, c, d = self.discrete_matrices(dt)
        return control.ss(a_d, b_d, c, d, dt, inputs=list(self.input_names),
                          outputs=list(self.output_names), states=self.state_names(),
                          name='pentapod_plant_d')

    def select(self, inputs: list[str] | None = None,
               outputs: list[str] | None = None) -> 'PlantModel':
        """Return a copy restricted to the named inputs/outputs (PortError if unknown)."""
        inputs = list(self.input_names) if inputs is None else list(inputs)
        outputs = list(self.output_names) if outputs is None else list(outputs)
        check_names(inputs, 'input')
        check_names(outputs, 'output')
        for name, have in [(n, self.input_names) for n in inputs] + \
                [(n, self.output_names) for n in outputs]:
            if name not in have:
                raise PortError(f'port {name!r} is not in this plant model; it has '
                                + ', '.join(have))
        ii = [self.input_names.index(n) for n in inputs]
        oo = [self.output_names.index(n) for n in outputs]
        meta = dict(self.meta)
        if 'static_compliance_full' in meta:     # (n_out, n_in) like d
            meta['static_compliance_full'] = np.asarray(
                meta['static_compliance_full'])[np.ix_(oo, ii)].tolist()
        return PlantModel(self.omega, self.zeta, self.b[:, ii], self.c_disp[oo],
                          self.c_vel[oo], self.d[np.ix_(oo, ii)], inputs, outputs,
                          [self.input_units[i] for i in ii], [self.output_units[o] for o in oo],
                          [self.input_descriptions[i] for i in ii],
                          [self.output_descriptions[o] for o in oo], meta)

    def content_hash(self) -> str:
        """SHA-256 over all numbers and names (hex); identical models give identical hashes."""
        digest = hashlib.sha256()
        for name in _ARRAYS:
            arr = np.ascontiguousarray(getattr(self, name), dtype='<f8')
            digest.update(name.encode() + str(arr.shape).encode() + arr.tobytes())
        digest.update(json.dumps({n: list(getattr(self, n)) for n in _LISTS},
                                 sort_keys=True).encode())
        return digest.hexdigest()

    def save(self, path: str | Path) -> Path:
        """
        Write the model to an .npz file (arrays + JSON metadata + content hash).

        Returns
        -------
        Path
            The written file.
        """
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        header = {n: list(getattr(self, n)) for n in _LISTS}
        header.update(format=FILE_FORMAT, meta=self.meta, content_hash=self.content_hash())
        with open(path, 'wb') as stream:
            np.savez(stream, header=np.array(json.dumps(header)),
                     **{n: getattr(self, n) for n in _ARRAYS})
        LOG.info('saved plant model (%d modes) to %s', self.n_modes, path)
        return path

    @classmethod
    def load(cls, path: str | Path) -> 'PlantModel':
        """
        Read a model written by :meth:`save` and verify its content hash.

        Raises
        ------
        ModelFileError
            If the file is unreadable, lacks arrays, or its numbers do not match the hash.
        """
        try:
            with np.load(path, allow_pickle=False) as data:
                header = json.loads(str(data['header']))
                arrays = {n: data[n] for n in _ARRAYS}
        except (OSError, ValueError, KeyError, zipfile.BadZipFile) as err:
            raise ModelFileError(f'cannot read plant model {path}: {err}') from None
        if header.get('format') != FILE_FORMAT:
            raise ModelFileError(f'{path}: format {header.get("format")!r}, expected '
                                 f'{FILE_FORMAT!r}')
        try:
            model = cls(**arrays, **{n: header[n] for n in _LISTS}, meta=header.get('meta', {}))
        except KeyError as err:
            raise ModelFileError(f'{path}: header lacks {err}') from None
        if model.content_hash() != header.get('content_hash'):
            raise ModelFileError(f'{path}: content hash mismatch (file corrupted or edited)')
        return model


def load_reduction_config(path: str | Path | None = None) -> dict:
    """
    Read config/reduction.yaml (or ``path``) and check its values.

    Raises
    ------
    ConfigError
        For a missing file, a missing key or a bad value (the message names it).
    """
    from pentapod_sim.params import config_dir
    path = Path(path) if path is not None else config_dir() / 'reduction.yaml'
    try:
        cfg = yaml.safe_load(path.read_text())
    except (OSError, yaml.YAMLError) as err:
        raise ConfigError(f'cannot read reduction config {path}: {err}') from None
    for key in ('inputs', 'outputs', 'relevance', 'damping_ratio', 'static_correction',
                'modes_f_max', 'frequency', 'sample_rate'):
        if key not in cfg:
            raise ConfigError(f'{path}: missing key {key!r}')
    zeta = np.asarray(cfg['damping_ratio'], dtype=float)
    if np.any(~np.isfinite(zeta)) or np.any(zeta < 0):
        raise ConfigError(f'{path}: damping_ratio must be >= 0, got {cfg["damping_ratio"]!r}')
    for key in ('modes_f_max', 'sample_rate'):
        if not isinstance(cfg[key], (int, float)) or cfg[key] <= 0:
            raise ConfigError(f'{path}: {key} must be > 0, got {cfg[key]!r}')
    return cfg


def _names(spec, known: tuple[str, ...], direction: str) -> list[str]:
    names = list(known) if spec == 'all' else list(spec)
    check_names(names, direction)
    return names


def from_modal_data(frequencies_hz: npt.ArrayLike, point_shapes: Mapping[str, npt.ArrayLike],
                    strut_frames: npt.ArrayLike | None, inputs: Sequence[str],
                    outputs: Sequence[str], zeta: npt.ArrayLike = 0.001,
                    d: npt.ArrayLike | None = None, meta: dict | None = None) -> PlantModel:
    """
    Plant model from modal data: frequencies and mass-normalised shapes at named points.

    Parameters
    ----------
    frequencies_hz : (m,) array_like
        Natural frequencies [Hz].
    point_shapes : mapping of point name to (6, m) array_like
        Mode shapes at the named points (ux, uy, uz [m], rx, ry, rz [rad] per unit modal
        coordinate, mass-normalised: ``Phi^T M Phi = I``); only the points the ports need.
    strut_frames : (5, 3, 3) array_like or None
        Strut frames (rows e1, e2, e3); needed only by strut ports.
    inputs, outputs : sequence of str
        Port names.
    zeta : float or (m,) array_like
        Modal damping ratio(s) [-].
    d : (n_out, n_in) array_like, optional
        Feed-through (static correction); default zero.
    meta : dict, optional
        Provenance stored with the model.
    """
    check_names(inputs, 'input')
    check_names(outputs, 'output')
    omega = 2 * np.pi * np.asarray(frequencies_hz, dtype=float)
    frames = np.full((5, 3, 3), np.nan) if strut_frames is None else strut_frames
    in_ports = port_list(point_shapes, frames, inputs)
    out_ports = port_list(point_shapes, frames, outputs)
    for p in in_ports + out_ports:
        if not np.all(np.isfinite(p.vector)):
            raise ModelFileError(f'port {p.name!r} needs strut frames, none were given')
    c_disp, c_vel = output_matrices(out_ports)
    d = np.zeros((len(outputs), len(inputs))) if d is None else d
    zeta = np.asarray(zeta, float)
    if zeta.ndim > 0 and zeta.shape != omega.shape:
        raise ConfigError(f'damping ratios: {zeta.size} given for {omega.size} modes')
    return PlantModel(omega, np.broadcast_to(zeta, omega.shape),
                      input_matrix(in_ports), c_disp, c_vel, d, list(inputs), list(outputs),
                      [p.unit for p in in_ports], [p.unit for p in out_ports],
                      [p.description for p in in_ports], [p.description for p in out_ports],
                      dict(meta or {}))


def keep_by_relevance(plant_all: PlantModel, relevance: Sequence[dict]) -> np.ndarray:
    """
    Indices of the modes kept by any of the relevance criteria (see config/reduction.yaml).

    A rule's optional ``measure`` is 'dc' (default, ``c b / omega^2``) or 'resonance'
    (``c b / (2 zeta omega^2)``, for modes with individual damping ratios).
    """
    keep = np.zeros(plant_all.n_modes, dtype=bool)
    for rule in relevance:
        sub = plant_all.select(rule['inputs'], rule['outputs'])
        criterion = {k: rule[k] for k in ('abs_limit', 'rel_limit', 'count') if k in rule}
        if rule.get('measure', 'dc') == 'resonance':
            gains = modal_resonance_gains(sub.omega, sub.zeta, sub.b, sub.c_disp)
        elif rule.get('measure', 'dc') == 'dc':
            gains = modal_dc_gains(sub.omega, sub.b, sub.c_disp)
        else:
            raise ConfigError(f'relevance measure must be dc or resonance, got '
                              f'{rule["measure"]!r}')
        keep[select_modes(gains, **criterion)] = True
    return np.flatnonzero(keep)


def plant_from_fe(fe, reduction_cfg: dict, progress: Callable[[str], None] | None = None
                  ) -> tuple[PlantModel, np.ndarray]:
    """
    Plant with every mode below ``modes_f_max`` of an FE model, and the relevant modes.

    Parameters
    ----------
    fe : FEModel
        The FE model (:func:`pentapod_sim.assembly.build_model`).
    reduction_cfg : dict
        As :func:`load_reduction_config` returns.
    progress : callable, optional
        Receives one message per stage.

    Returns
    -------
    plant_all : PlantModel
        All computed modes; ``d`` holds the residual flexibility of the modes that were not
        computed (``C K^-1 B`` minus all computed modes), so its static gain is exact, and
        ``meta['static_compliance_full']`` the exact static gain ``C K^-1 B``.
    keep : (r,) ndarray of int
        Indices of the modes kept by the relevance criteria.
    """
    from pentapod_sim import __version__
    from pentapod_sim.modal import solve_modes
    say = progress or (lambda msg: LOG.info('%s', msg))
    cfg = reduction_cfg
    say(f'FE model: {fe.n_dof} DOF; solving modes below {cfg["modes_f_max"]} Hz')
    modes = solve_modes(fe.K, fe.M, f_max=float(cfg['modes_f_max']))
    say(f'{modes.n_modes} modes, {modes.frequencies[0]:.2f} .. {modes.frequencies[-1]:.2f} Hz')
    inputs = _names(cfg['inputs'], INPUT_NAMES, 'input')
    outputs = _names(cfg['outputs'], OUTPUT_NAMES, 'output')
    plant_all = from_modal_data(modes.frequencies, modal_points(fe.points, modes.shapes),
                                fe.strut_frames, inputs, outputs, cfg['damping_ratio'])
    keep = keep_by_relevance(plant_all, cfg['relevance'])
    c_disp_full, _ = output_matrices(port_list(fe.points, fe.strut_frames, outputs))
    g_full = static_compliance(fe.K, input_matrix(port_list(fe.points, fe.strut_frames, inputs)),
                               c_disp_full)
    plant_all.d = g_full - modal_dc_gains(plant_all.omega, plant_all.b,
                                          plant_all.c_disp).sum(axis=0)
    plant_all.meta.update({
        'pose': [float(v) for v in fe.pose], 'params_sha256': fe.meta.get('params_sha256'),
        'package_version': __version__, 'n_dof': fe.n_dof, 'n_modes_computed': modes.n_modes,
        'modes_f_max_hz': float(cfg['modes_f_max']), 'static_compliance_full': g_full.tolist()})
    return plant_all, keep


def reduce_plant(plant_all: PlantModel, keep: npt.ArrayLike,
                 static_correction: bool = True) -> PlantModel:
    """
    Keep the modes ``keep`` of :func:`plant_from_fe`'s plant, with or without static correction.

    With the correction, ``d = C K^-1 B - sum_kept c b^T / omega^2`` (exact static gain);
    without it, ``d = 0``.
    """
    keep = np.asarray(keep, dtype=int)
    d = np.zeros_like(plant_all.d)
    if static_correction:
        if 'static_compliance_full' not in plant_all.meta:
            raise ConfigError('static correction needs the FE compliance C K^-1 B '
                              "(meta['static_compliance_full']); this plant has none")
        g_kept = modal_dc_gains(plant_all.omega[keep], plant_all.b[keep],
                                plant_all.c_disp[:, keep]).sum(axis=0)
        d = np.asarray(plant_all.meta['static_compliance_full']) - g_kept
    meta = dict(plant_all.meta, kept_modes=(keep + 1).tolist(),
                static_correction=bool(static_correction))
    return PlantModel(plant_all.omega[keep], plant_all.zeta[keep], plant_all.b[keep],
                      plant_all.c_disp[:, keep], plant_all.c_vel[:, keep], d,
                      plant_all.input_names, plant_all.output_names, plant_all.input_units,
                      plant_all.output_units, plant_all.input_descriptions,
                      plant_all.output_descriptions, meta)


def build_plant(position: str | npt.ArrayLike, machine=None, reduction_cfg: dict | None = None,
                progress: Callable[[str], None] | None = None) -> PlantModel:
    """
    Whole chain for one machine position: FE model -> modes -> ports -> reduction.

    Parameters
    ----------
    position : str or (5,) array_like
        Position name of config/positions.yaml or a pose x, y, z [m], a, b [rad].
    machine : MachineParams, optional
        Default :func:`pentapod_sim.params.load_machine`.
    reduction_cfg : dict, optional
        Default :func:`load_reduction_config`.
    progress : callable, optional
        Receives one message per stage.

    Returns
    -------
    PlantModel
        Kept modes only, static correction in ``d`` if configured; ``meta`` records the
        position, pose, parameter hash, package version and kept mode numbers (1-based).
    """
    from pentapod_sim.assembly import build_model
    from pentapod_sim.params import load_machine
    cfg = load_reduction_config() if reduction_cfg is None else reduction_cfg
    machine = load_machine() if machine is None else machine
    plant_all, keep = plant_from_fe(build_model(machine, position), cfg, progress)
    plant_all.meta['position'] = position if isinstance(position, str) else None
    plant = reduce_plant(plant_all, keep, bool(cfg['static_correction']))
    (progress or (lambda msg: LOG.info('%s', msg)))(
        f'kept {keep.size} of {plant_all.n_modes} modes; static correction '
        f'{"on" if cfg["static_correction"] else "off"}')
    return plant
