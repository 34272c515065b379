"""
The work of one pose: FE model, first frame and strut modes, reduced plant, closed loops.

:func:`compute_pose` never raises: an unreachable pose gives a row with status
``unreachable`` and the limit it violates, any other error a row with status ``failed`` and
the error, so one bad pose cannot stop a sweep. :func:`columns` is the one list of result
columns with their units; the Parquet schema, the docs table and the plots use it.
"""
from __future__ import annotations

import os
import socket
import time
from typing import Any, Sequence

import numpy as np

from pentapod_damper.sweep.loops import DIRECTIONS, Loop, loop_columns
from pentapod_damper.sweep.poses import AXES, UNITS
from pentapod_damper.sweep.settings import SweepSettings
from pentapod_sim.errors import UnreachablePoseError
from pentapod_sim.fe.model import FEModel
from pentapod_sim.modes.causes import strain_energy_shares, tcp_directions
from pentapod_sim.modes.frame_reduction import build_model
from pentapod_sim.modes.solver import ModalResult, solve_modes
from pentapod_sim.parameters import sample_time
from pentapod_sim.plant.build import plant_from_fe, reduce_plant

#: Stiffness groups whose modes count as frame modes (the paper's frame modes are caused by
#: the installation) and as strut modes.
FRAME_GROUPS = ('frame', 'frame_walls', 'installation')
STRUT_GROUPS = ('struts',)
#: Outcome of a pose.
OK, UNREACHABLE, FAILED = 'ok', 'unreachable', 'failed'
#: Columns that describe how a row was computed, not what (differ between runs).
BOOKKEEPING = ('seconds', 'cpu_seconds', 'worker', 'peak_rss_mb', 'finished_at')


def columns(settings: SweepSettings) -> list[tuple[str, str, str, str]]:
    """
    (name, type, unit, meaning) of every result column, in order.

    Types are ``str``, ``float`` and ``int``; directions ``dd`` are TCP displacement d over
    TCP force d; loop labels are ``open`` and those of :meth:`SweepSettings.labels`.
    """
    cols = [('key', 'str', '-', 'hash of the rounded pose and the settings digest'),
            ('status', 'str', '-', 'ok, unreachable or failed'),
            ('error', 'str', '-', 'violated limit or error of a pose that is not ok')]
    cols += [(a, 'float', UNITS[a], f'pose {a}') for a in AXES]
    cols += [('n_dof', 'int', '-', 'DOF of the FE model'),
             ('n_modes_kept', 'int', '-', 'modes of the reduced plant')]
    for kind in ('frame', 'strut'):
        cols += [(f'{kind}_mode_f', 'float', 'Hz', f'frequency of the first {kind} mode'),
                 (f'{kind}_mode_dir', 'str', '-', f'dominant TCP component of the first '
                  f'{kind} mode (x, y, z, rx, ry, rz)')]
    labels = ['open'] + [label for label, _, _ in settings.labels()]
    for d in DIRECTIONS:
        dd = d + d
        cols += [(f'dom_f_{dd}', 'float', 'Hz', f'open-loop mode with the largest {dd} peak'),
                 (f'f_peak_{dd}_open', 'float', 'Hz', f'frequency of the open-loop {dd} peak')]
        for label in labels:
            cols += [(f'peak_{dd}_{label}', 'float', 'm/N', f'peak |H_{dd}| in the band, '
                      f'{label}'),
                     (f'rms_{dd}_{label}', 'float', 'm/N', f'RMS of |H_{dd}| in the band, '
                      f'{label}'),
                     (f'zeta_{dd}_{label}', 'float', '-', f'damping ratio of the {dd} '
                      f'dominant mode, {label}')]
    for label, loop in loops_of(settings).items():
        cols.append((f'rho_{label}', 'float', '-', 'spectral radius of the sampled loop '
                     '(>= 1: unstable on the testbed)'))
        for pma in loop.pmas:
            for axis in (port[-1] for port in pma.sensor_ports):
                cols += [(f'pma_stroke_{axis}_{label}', 'float', 'm', 'largest PMA stroke '
                          'for the harmonic TCP force'),
                         (f'pma_force_{axis}_{label}', 'float', 'N', 'largest PMA force '
                          'for the harmonic TCP force')]
    for tail, _, _ in settings.share_labels():
        for d in DIRECTIONS:
            for kind in ('peak', 'rms'):
                cols.append((f'share_{kind}_{d}{d}{tail}', 'float', '-', f'struts-1+2 share '
                             f'of the all-struts {kind} improvement'))
    cols += [('seconds', 'float', 's', 'wall time of the pose'),
             ('cpu_seconds', 'float', 's', 'CPU time of the pose in its process'),
             ('worker', 'str', '-', 'host:pid that computed it'),
             ('peak_rss_mb', 'float', 'MB', 'peak resident memory of that process so far'),
             ('finished_at', 'float', 's', 'Unix time the row was made')]
    return list(dict.fromkeys(cols))


def first_modes(fe: FEModel, f_max: float, modes: ModalResult | None = None) -> dict[str, Any]:
    """
    Frequency [Hz] and TCP direction of the first frame mode and the first strut mode.

    A mode's cause is the set of groups (:data:`FRAME_GROUPS` or :data:`STRUT_GROUPS`, or
    another group) with the largest modal strain energy
    (:func:`pentapod_sim.modes.causes.strain_energy_shares`). Modes below ``f_max`` are
    searched; NaN and ``-`` if none is found there. ``modes``: the model's modes solved up to
    at least ``f_max`` (default: solved here).
    """
    if modes is None:
        modes = solve_modes(fe.K, fe.M, f_max=f_max)
    n = modes.count_below(f_max)
    modes = ModalResult(modes.frequencies[:n], modes.shapes[:, :n], n, f_max)
    names = list(fe.stiffness_groups)
    shares = strain_energy_shares(fe.stiffness_groups, modes)
    sets = {'frame': FRAME_GROUPS, 'strut': STRUT_GROUPS}
    sets.update({g: (g,) for g in names if not any(g in s for s in sets.values())})
    total = {k: shares[:, [names.index(g) for g in v if g in names]].sum(axis=1)
             for k, v in sets.items()}
    cause = np.array(list(total))[np.argmax(np.stack(list(total.values())), axis=0)]
    dirs = tcp_directions(modes, fe.points['tcp'])
    row: dict[str, Any] = {}
    for kind in ('frame', 'strut'):
        hits = np.flatnonzero(cause == kind)
        j = int(hits[0]) if hits.size else None
        row[f'{kind}_mode_f'] = float(modes.frequencies[j]) if j is not None else np.nan
        row[f'{kind}_mode_dir'] = dirs[j] if j is not None else '-'
    return row


def loops_of(settings: SweepSettings) -> dict[str, Loop]:
    """Column label -> damped loop of every scenario and gain factor."""
    dt = sample_time(settings.sample_rate)
    return {label: Loop(settings.sections[name], dt, factor, settings.drives.get(name))
            for label, name, factor in settings.labels()}


def evaluate(pose: np.ndarray, settings: SweepSettings) -> dict[str, Any]:
    """Result columns of a reachable pose (raises UnreachablePoseError otherwise)."""
    fe = build_model(settings.machine, np.asarray(pose, dtype=float))
    # one modal solve serves the mode columns and the plant (it was two)
    modes = solve_modes(fe.K, fe.M, f_max=max(settings.mode_f_max,
                                              settings.reduction.modes_f_max))
    row: dict[str, Any] = {'n_dof': fe.n_dof, **first_modes(fe, settings.mode_f_max, modes)}
    plant_all, keep = plant_from_fe(fe, settings.reduction, progress=lambda msg: None,
                                    modes=modes)
    plant = reduce_plant(plant_all, keep, settings.reduction.static_correction)
    row['n_modes_kept'] = plant.n_modes
    freq = np.linspace(settings.freq[0], settings.freq[1], int(settings.freq[2]))
    row.update(loop_columns(plant, loops_of(settings), freq, settings.band,
                            sample_time(settings.sample_rate), settings.pma_force_amplitude,
                            settings.share_labels()))
    return row


def peak_rss_mb() -> float:
    """Peak resident memory [MB] of this process so far (VmHWM)."""
    try:
        with open('/proc/self/status', encoding='ascii') as stream:
            for line in stream:
                if line.startswith('VmHWM:'):
                    return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    import resource
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def compute_pose(pose: Sequence[float], key: str, settings: SweepSettings) -> dict[str, Any]:
    """
    One result row of a pose (never raises; see the module docstring).

    Parameters
    ----------
    pose : (5,) sequence
        x, y, z [m], a, b [rad].
    key : str
        Its key (:func:`pentapod_damper.sweep.poses.pose_key`).
    settings : SweepSettings
        What to compute.
    """
    t0, cpu0 = time.perf_counter(), time.process_time()
    row: dict[str, Any] = {'key': key, 'status': OK, 'error': '',
                           **{a: float(v) for a, v in zip(AXES, pose)}}
    try:
        row.update(evaluate(np.asarray(pose, dtype=float), settings))
    except UnreachablePoseError as err:
        row.update(status=UNREACHABLE, error=str(err))
    except Exception as err:  # noqa: BLE001 -- recorded, the sweep goes on
        row.update(status=FAILED, error=f'{type(err).__name__}: {err}')
    row.update(seconds=time.perf_counter() - t0, cpu_seconds=time.process_time() - cpu0,
               worker=f'{socket.gethostname()}:{os.getpid()}',
               peak_rss_mb=peak_rss_mb(), finished_at=time.time())
    return row


def compute_batch(poses: Sequence[Sequence[float]], keys: Sequence[str],
                  settings: SweepSettings) -> list[dict[str, Any]]:
    """Rows of several poses (one Dask task)."""
    return [compute_pose(p, k, settings) for p, k in zip(poses, keys)]
