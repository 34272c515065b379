"""
From the FE model to the reduced plant of a machine position, and the cache of built plants.

The chain is FE model (:mod:`pentapod_sim.fe`) -> modes (:mod:`pentapod_sim.modes`) -> ports
-> relevance-based reduction with static correction (:mod:`pentapod_sim.plant.reduction`),
configured by config/reduction.yaml. :func:`build_plant` runs it for one position;
:func:`load_or_build_model` caches the result per configuration.
"""
from __future__ import annotations

import hashlib
import logging
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

import numpy as np
import numpy.typing as npt

from pentapod_sim import __version__
from pentapod_sim.errors import ConfigError, ModelFileError
from pentapod_sim.fe.machine_data import load_machine, MachineParams
from pentapod_sim.fe.model import FEModel
from pentapod_sim.modes.causes import strain_energy_shares
from pentapod_sim.modes.frame_reduction import build_model
from pentapod_sim.modes.slicing import Progress
from pentapod_sim.modes.solver import ModalResult, solve_modes
from pentapod_sim.paths import config_dir
from pentapod_sim.plant.config import (
    damping_file_path,
    DampingGroup,
    load_reduction_config,
    ReductionConfig,
    relevance_rule,
    RelevanceRule,
)
from pentapod_sim.plant.model import PlantModel
from pentapod_sim.plant.ports import (
    check_names,
    direct_matrix,
    input_matrix,
    INPUT_NAMES,
    load_points,
    modal_points,
    output_matrices,
    OUTPUT_NAMES,
)
from pentapod_sim.plant.ports import ports as port_list
from pentapod_sim.plant.reduction import (
    modal_dc_gains,
    modal_resonance_gains,
    select_modes,
    static_compliance,
)

LOG = logging.getLogger(__name__)


def modal_damping(frequencies_hz: npt.ArrayLike, damping_ratio: npt.ArrayLike,
                  groups: Sequence[DampingGroup] = ()) -> npt.NDArray[np.float64]:
    """
    Damping ratio of every mode: ``damping_ratio``, overridden in the bands of ``groups``.

    Parameters
    ----------
    frequencies_hz : (m,) array_like
        Natural frequencies [Hz].
    damping_ratio : float or (m,) array_like
        Uniform (or per-mode) modal damping ratio [-].
    groups : sequence of DampingGroup
        Modes with ``f_min <= f < f_max`` [Hz] get the group's ``ratio`` [-].
    """
    freq = np.asarray(frequencies_hz, dtype=float)
    zeta = np.asarray(damping_ratio, dtype=float)
    if zeta.ndim > 0 and zeta.shape != freq.shape:
        raise ConfigError(f'damping ratios: {zeta.size} given for {freq.size} modes')
    zeta = np.broadcast_to(zeta, freq.shape).copy()
    for group in groups:
        zeta[(freq >= group.f_min) & (freq < group.f_max)] = group.ratio
    return zeta


def config_damping(frequencies_hz: npt.ArrayLike, cfg: ReductionConfig) -> np.ndarray:
    """Damping ratio of every mode by the config: its damping_file, else ratio and groups."""
    path = damping_file_path(cfg)
    if path is not None:
        from pentapod_sim.plant.damping_file import load_damping_file
        return load_damping_file(path).ratios(frequencies_hz)
    return modal_damping(frequencies_hz, cfg.damping_ratio, getattr(cfg, 'damping_groups', ()))


def from_modal_data(frequencies_hz: npt.ArrayLike, point_shapes: Mapping[str, npt.ArrayLike],
                    strut_frames: npt.ArrayLike | None, inputs: Sequence[str],
                    outputs: Sequence[str], zeta: npt.ArrayLike = 0.001,
                    d: npt.ArrayLike | None = None, meta: dict[str, Any] | None = None,
                    chord_position: float = 0.5) -> PlantModel:
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
        Feed-through (static correction and the direct terms of load outputs); default the
        direct terms alone (:func:`pentapod_sim.plant.ports.direct_matrix`).
    meta : dict, optional
        Provenance stored with the model.
    chord_position : float
        Chord point of the chord ports (0 = BP joint, 1 = WP joint).
    """
    check_names(inputs, 'input')
    check_names(outputs, 'output')
    omega = 2 * np.pi * np.asarray(frequencies_hz, dtype=float)
    frames = np.full((5, 3, 3), np.nan) if strut_frames is None else strut_frames
    in_ports = port_list(point_shapes, frames, inputs, chord_position)
    out_ports = port_list(point_shapes, frames, outputs, chord_position)
    for p in in_ports + out_ports:
        if not np.all(np.isfinite(p.vector)):
            raise ModelFileError(f'port {p.name!r} needs strut frames, none were given')
    c_disp, c_vel = output_matrices(out_ports)
    d = direct_matrix(out_ports, inputs) if d is None else np.asarray(d, dtype=float)
    zeta = np.asarray(zeta, float)
    if zeta.ndim > 0 and zeta.shape != omega.shape:
        raise ConfigError(f'damping ratios: {zeta.size} given for {omega.size} modes')
    return PlantModel(omega, np.broadcast_to(zeta, omega.shape),
                      input_matrix(in_ports), c_disp, c_vel, d, list(inputs), list(outputs),
                      [p.unit for p in in_ports], [p.unit for p in out_ports],
                      [p.description for p in in_ports], [p.description for p in out_ports],
                      dict(meta or {}))


def keep_by_relevance(plant_all: PlantModel,
                      relevance: Sequence[RelevanceRule | Mapping[str, Any]]
                      ) -> npt.NDArray[np.intp]:
    """
    Indices of the modes kept by any of the relevance criteria (see config/reduction.yaml).

    A rule is a :class:`RelevanceRule` or a mapping with the keys of the file's rules (checked
    the same way). Its ``measure`` is 'dc' (default, ``c b / omega^2``) or 'resonance'
    (``c b / (2 zeta omega^2)``, for modes with individual damping ratios).
    """
    keep = np.zeros(plant_all.n_modes, dtype=bool)
    for rule in map(relevance_rule, relevance):
        sub = plant_all.select(list(rule.inputs), list(rule.outputs))
        if rule.measure == 'resonance':
            gains = modal_resonance_gains(sub.omega, sub.zeta, sub.b, sub.c_disp)
        else:
            gains = modal_dc_gains(sub.omega, sub.b, sub.c_disp)
        keep[select_modes(gains, rule.abs_limit, rule.rel_limit, rule.count)] = True
    return np.flatnonzero(keep)


def plant_from_fe(fe: FEModel, reduction_cfg: ReductionConfig,
                  progress: Callable[[str], None] | None = None,
                  modes: ModalResult | None = None,
                  modes_progress: Progress | None = None,
                  ) -> tuple[PlantModel, npt.NDArray[np.intp]]:
    """
    Plant with every mode below ``modes_f_max`` of an FE model, and the relevant modes.

    Parameters
    ----------
    fe : FEModel
        The FE model (:func:`pentapod_sim.fe.assembly.build_model`).
    reduction_cfg : ReductionConfig
        As :func:`load_reduction_config` returns.
    progress : callable, optional
        Receives one message per stage.
    modes_progress : callable, optional
        The mode solver's progress callback (:func:`pentapod_sim.modes.solver.solve_modes`).
    modes : ModalResult, optional
        Modes of ``fe`` already solved up to at least ``modes_f_max`` (those above are left
        out); default: solved here.

    Returns
    -------
    plant_all : PlantModel
        All computed modes; ``d`` holds the residual flexibility of the modes that were not
        computed (``C K^-1 B`` minus all computed modes), so its static gain is exact, and
        ``meta['static_compliance_full']`` the exact static gain ``C K^-1 B``.
    keep : (r,) ndarray of int
        Indices of the modes kept by the relevance criteria.
    """
    say = progress or (lambda msg: LOG.info('%s', msg))
    cfg = reduction_cfg
    if modes is None:
        say(f'FE model: {fe.n_dof} DOF; solving modes below {cfg.modes_f_max} Hz')
        modes = solve_modes(fe.K, fe.M, f_max=cfg.modes_f_max, progress=modes_progress)
    elif modes.f_max is None or modes.f_max < cfg.modes_f_max:
        raise ConfigError(f'modes solved up to {modes.f_max} Hz; the plant needs every mode '
                          f'below modes_f_max = {cfg.modes_f_max} Hz')
    else:
        n = modes.count_below(cfg.modes_f_max)
        modes = ModalResult(modes.frequencies[:n], modes.shapes[:, :n], n,
                            cfg.modes_f_max, modes.stats)
    say(f'{modes.n_modes} modes, {modes.frequencies[0]:.2f} .. {modes.frequencies[-1]:.2f} Hz')
    inputs, outputs = list(cfg.inputs), list(cfg.outputs)
    chord = cfg.chord_position
    zeta = config_damping(modes.frequencies, cfg)
    points = {**fe.points, **load_points(fe.points, fe.stiffness_groups)}
    plant_all = from_modal_data(modes.frequencies, modal_points(points, modes.shapes),
                                fe.strut_frames, inputs, outputs, zeta, chord_position=chord)
    keep = keep_by_relevance(plant_all, cfg.relevance)
    out_ports = port_list(points, fe.strut_frames, outputs, chord)
    c_disp_full, _ = output_matrices(out_ports)
    g_full = static_compliance(fe.K, input_matrix(port_list(points, fe.strut_frames, inputs,
                                                            chord)), c_disp_full)
    g_full = g_full + direct_matrix(out_ports, inputs)
    plant_all.d = g_full - modal_dc_gains(plant_all.omega, plant_all.b,
                                          plant_all.c_disp).sum(axis=0)
    plant_all.meta.update({
        'pose': [float(v) for v in fe.pose], 'params_sha256': fe.meta.get('params_sha256'),
        'package_version': __version__, 'n_dof': fe.n_dof, 'n_modes_computed': modes.n_modes,
        'modes_f_max_hz': float(cfg.modes_f_max), 'static_compliance_full': g_full.tolist(),
        'mode_causes': mode_causes(fe, modes)})
    return plant_all, keep


def mode_causes(fe: FEModel, modes: ModalResult) -> list[str]:
    """
    Each mode's cause: the stiffness group with the largest share of its strain energy.

    The same rule as :func:`pentapod_sim.modes.causes.analyse_causes`' ``cause`` column (names
    of ``fe.stiffness_groups``: struts, joints, frame, ...); empty strings for a model without
    stiffness groups. :meth:`PlantModel.fe_mode` reads them back per plant mode.
    """
    if not fe.stiffness_groups:
        return [''] * modes.n_modes
    names = list(fe.stiffness_groups)
    shares = strain_energy_shares(fe.stiffness_groups, modes)
    return [names[k] for k in np.argmax(shares, axis=1)]


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


def build_plant(position: str | npt.ArrayLike, machine: MachineParams | None = None,
                reduction_cfg: ReductionConfig | None = None,
                progress: Callable[[str], None] | None = None) -> PlantModel:
    """
    Whole chain for one machine position: FE model -> modes -> ports -> reduction.

    Parameters
    ----------
    position : str or (5,) array_like
        Position name of config/positions.yaml or a pose x, y, z [m], a, b [rad].
    machine : MachineParams, optional
        Default :func:`pentapod_sim.fe.machine_data.load_machine`.
    reduction_cfg : ReductionConfig, optional
        Default :func:`load_reduction_config`.
    progress : callable, optional
        Receives one message per stage.

    Returns
    -------
    PlantModel
        Kept modes only, static correction in ``d`` if configured; ``meta`` records the
        position, pose, parameter hash, package version and kept mode numbers (1-based).
    """
    cfg = load_reduction_config() if reduction_cfg is None else reduction_cfg
    machine = load_machine() if machine is None else machine
    plant_all, keep = plant_from_fe(build_model(machine, position), cfg, progress)
    plant_all.meta['position'] = position if isinstance(position, str) else None
    plant = reduce_plant(plant_all, keep, cfg.static_correction)
    (progress or (lambda msg: LOG.info('%s', msg)))(
        f'kept {keep.size} of {plant_all.n_modes} modes; static correction '
        f'{"on" if cfg.static_correction else "off"}')
    return plant


#: What a built plant records beyond the matrices; a new item gives older cache files a new key.
CACHE_CONTENT = 'kept_modes,mode_causes'


def model_cache_key(position: str) -> str:
    """
    SHA-256 (hex, 16 chars) over the configuration a built model depends on.

    Covers machine.yaml, positions.yaml and reduction.yaml of
    :func:`pentapod_sim.paths.config_dir` (and the damping file reduction.yaml names), the
    position name, the package version, :data:`CACHE_CONTENT` and the port names (a model
    built before a port was added lacks it), so any edit gives a new cache file.
    """
    digest = hashlib.sha256(
        f'{position}|{__version__}|{CACHE_CONTENT}|{INPUT_NAMES}|{OUTPUT_NAMES}'.encode())
    for name in ('machine.yaml', 'positions.yaml', 'reduction.yaml'):
        path = config_dir() / name
        digest.update(path.read_bytes() if path.exists() else b'')
    damping = damping_file_path(load_reduction_config())
    if damping is not None:                 # a new calibration must not load a stale plant
        digest.update(damping.read_bytes() if damping.exists() else b'missing')
    return digest.hexdigest()[:16]


def load_or_build_model(model_file: str = '', position: str = '',
                        cache_dir: str | Path = 'out/models') -> tuple[PlantModel, str]:
    """
    Load a saved PlantModel, or build it for a position (cached under ``cache_dir``).

    Parameters
    ----------
    model_file : str
        Path of a model saved by :meth:`PlantModel.save`; wins over ``position``.
    position : str
        Position name of config/positions.yaml (used if ``model_file`` is empty).
    cache_dir : str or Path
        Folder of cached models ``plant_<position>_<key>.npz``.

    Returns
    -------
    (PlantModel, str)
        The model and a sentence saying where it came from.
    """
    if model_file:
        return PlantModel.load(model_file), f'loaded {model_file}'
    if not position:
        raise ConfigError('set model_file or position (neither was given)')
    cached = Path(cache_dir) / f'plant_{position}_{model_cache_key(position)}.npz'
    if cached.exists():
        return PlantModel.load(cached), f'loaded cached {cached}'
    model = build_plant(position, progress=lambda msg: LOG.info('build_plant: %s', msg))
    model.save(cached)
    return model, f'built for {position} and cached in {cached}'
