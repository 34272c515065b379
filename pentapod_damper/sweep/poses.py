"""
Poses of a sweep: a grid over x, y, z and the two tilts, a list, or a CSV file; pose keys.

A pose is TCP x, y, z [m] and spindle tilts a (about x), b (about y) [rad], as
:func:`pentapod_sim.fe.assembly.build_model` takes it. On the command line and in CSV files
the tilts may be given in degrees (``a_deg``, ``b_deg``). Reachability is not checked here:
the FE model of an unreachable pose raises, and the sweep records the limit it names.
"""
from __future__ import annotations

import csv
import hashlib
import itertools
from pathlib import Path
from typing import Iterable, Sequence

import numpy as np

from pentapod_sim.errors import ConfigError
from pentapod_sim.fe.machine_data import load_positions

#: Pose components, in order, with their units.
AXES = ('x', 'y', 'z', 'a', 'b')
UNITS = {'x': 'm', 'y': 'm', 'z': 'm', 'a': 'rad', 'b': 'rad'}
#: Decimals a pose is rounded to before hashing: 1 um and 1 urad.
KEY_DECIMALS = 6


def parse_range(text: str, what: str) -> np.ndarray:
    """
    Values of one grid axis: ``v`` (one value) or ``lo:hi:n`` (n evenly spaced, ends included).

    Raises
    ------
    ConfigError
        Naming the axis and the bad text.
    """
    parts = str(text).split(':')
    try:
        if len(parts) == 1:
            return np.array([float(parts[0])])
        if len(parts) == 3:
            lo, hi, n = float(parts[0]), float(parts[1]), int(parts[2])
            if n >= 1 and np.isfinite(lo) and np.isfinite(hi):
                return np.linspace(lo, hi, n) if n > 1 else np.array([lo])
    except ValueError:
        pass
    raise ConfigError(f'{what} = {text!r}: give one value or lo:hi:n (n >= 1 points)')


def grid(x: str, y: str, z: str, a_deg: str = '0', b_deg: str = '0') -> np.ndarray:
    """
    (N, 5) poses of the full grid; ranges as :func:`parse_range`, tilts in degrees.

    The order is z, a, b outermost and x innermost, so poses of one x-y slice are adjacent.
    """
    xs, ys, zs = (parse_range(v, k) for v, k in ((x, 'x'), (y, 'y'), (z, 'z')))
    a_s = np.radians(parse_range(a_deg, 'a_deg'))
    b_s = np.radians(parse_range(b_deg, 'b_deg'))
    rows = [(xv, yv, zv, av, bv) for zv, av, bv, yv, xv in itertools.product(zs, a_s, b_s, ys, xs)]
    return np.array(rows, dtype=float).reshape(-1, 5)


def parse_pose(text: str) -> np.ndarray:
    """One pose ``x,y,z,a_deg,b_deg`` [m, m, m, deg, deg] as x, y, z [m], a, b [rad]."""
    try:
        values = [float(v) for v in text.split(',')]
    except ValueError:
        values = []
    if len(values) != 5 or not np.all(np.isfinite(values)):
        raise ConfigError(f'pose {text!r}: give x,y,z,a_deg,b_deg (5 finite numbers, m and '
                          'deg)')
    return np.array(values[:3] + list(np.radians(values[3:])))


def named_poses(names: Sequence[str], positions_file: str | None = None) -> np.ndarray:
    """(N, 5) poses of named positions of config/positions.yaml."""
    known = load_positions(positions_file)
    missing = [n for n in names if n not in known]
    if missing:
        raise ConfigError(f'unknown position(s) {", ".join(missing)}; known: '
                          f'{", ".join(known)}')
    return np.array([known[n] for n in names], dtype=float).reshape(-1, 5)


def read_csv(path: str | Path) -> np.ndarray:
    """
    (N, 5) poses of a CSV file with a header: x, y, z [m] and a, b [rad] or a_deg, b_deg.

    Raises
    ------
    ConfigError
        Naming the file and the row or column at fault.
    """
    path = Path(path)
    try:
        with open(path, newline='', encoding='utf-8') as stream:
            rows = list(csv.DictReader(stream))
            header = rows[0].keys() if rows else []
    except OSError as err:
        raise ConfigError(f'cannot read pose file {path}: {err}') from None
    if not rows:
        raise ConfigError(f'pose file {path} has no rows under its header')
    cols = []
    for name in AXES:
        deg = f'{name}_deg'
        col = name if name in header else deg if name in 'ab' and deg in header else None
        if col is None:
            raise ConfigError(f'pose file {path}: no column {name!r}'
                              + (f' or {deg!r}' if name in 'ab' else '')
                              + f'; columns: {", ".join(header)}')
        cols.append(col)
    poses = np.empty((len(rows), 5))
    for i, row in enumerate(rows):
        try:
            values = [float(row[c]) for c in cols]
        except (TypeError, ValueError):
            values = [np.nan]
        if len(values) != 5 or not np.all(np.isfinite(values)):
            raise ConfigError(f'pose file {path}, row {i + 2}: {dict(row)} is not five finite '
                              'numbers')
        poses[i] = [v if not c.endswith('_deg') else np.radians(v)
                    for v, c in zip(values, cols)]
    return poses


def rounded(pose: Iterable[float]) -> tuple[float, ...]:
    """The pose rounded to :data:`KEY_DECIMALS` (what its key depends on)."""
    return tuple(round(float(v), KEY_DECIMALS) + 0.0 for v in pose)


def pose_key(pose: Iterable[float], digest: str) -> str:
    """Stable 16-hex key of a pose under settings with ``digest``."""
    text = digest + '|' + ','.join(f'{v:.{KEY_DECIMALS}f}' for v in rounded(pose))
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def unique(poses: np.ndarray) -> np.ndarray:
    """The poses without repeats (after rounding), in their first order."""
    seen, keep = set(), []
    for i, pose in enumerate(poses):
        r = rounded(pose)
        if r not in seen:
            seen.add(r)
            keep.append(i)
    return poses[keep]
