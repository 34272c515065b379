"""
External modal data files: frequencies and mass-normalised mode shapes at the named points.

Users of a commercial FE code (ANSYS, Abaqus, ...) export their modes at the named points of
docs/architecture.md and build the testbed's plant from them with
:func:`pentapod_sim.plant.model.from_modal_data` (CLI: ``statespace build --modal-data``).
Two formats are read:

NPZ (``numpy.savez``)
    ``frequencies_hz`` (m,) [Hz]; ``point:<name>`` (6, m) per point: ux, uy, uz [m] and
    rx, ry, rz [rad] per unit modal coordinate, global frame; optional ``strut_frames``
    (5, 3, 3) (rows e1, e2, e3 per strut) and ``zeta`` (m,).
CSV (one header line, one row per mode and point)
    ``mode,frequency_hz,point,ux,uy,uz,rx,ry,rz`` with mode numbers 1..m. Strut frames, if
    strut ports are wanted, come from a YAML file ``strut_frames: [[e1, e2, e3], ...]``.

Shapes must be mass-normalised (``Phi^T M Phi = I``, units m/sqrt(kg)); a file cannot prove
this, so the loader checks shapes, finiteness and consistency only.
"""
from __future__ import annotations

import csv
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

import numpy as np
import numpy.typing as npt
import yaml

from pentapod_sim.errors import ModelFileError
from pentapod_sim.plant.model import read_npz
from pentapod_sim.plant.ports import modal_points

CSV_COLUMNS = ('mode', 'frequency_hz', 'point', 'ux', 'uy', 'uz', 'rx', 'ry', 'rz')


@dataclass(frozen=True)
class ModalData:
    """
    Modes known only at named points.

    Attributes
    ----------
    frequencies_hz : (m,) ndarray
        Natural frequencies [Hz], ascending.
    point_shapes : dict of str to (6, m) ndarray
        Mass-normalised shapes at the named points.
    strut_frames : (5, 3, 3) ndarray or None
        Strut frames, needed by strut ports only.
    zeta : (m,) ndarray or None
        Modal damping ratios [-], if the file has them.
    source : str
        Where the data came from.
    """

    frequencies_hz: npt.NDArray[np.float64]
    point_shapes: dict[str, npt.NDArray[np.float64]]
    strut_frames: npt.NDArray[np.float64] | None = None
    zeta: npt.NDArray[np.float64] | None = None
    source: str = ''
    meta: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        """Check sizes and values; ModelFileError names the bad entry."""
        m = self.frequencies_hz.size
        if m == 0 or not np.all(np.isfinite(self.frequencies_hz)) \
                or np.any(self.frequencies_hz < 0):
            raise ModelFileError(f'{self.source}: frequencies must be finite and >= 0 Hz')
        if np.any(np.diff(self.frequencies_hz) < 0):
            raise ModelFileError(f'{self.source}: frequencies are not ascending')
        for name, shape in self.point_shapes.items():
            if shape.shape != (6, m) or not np.all(np.isfinite(shape)):
                raise ModelFileError(f'{self.source}: point {name!r} has shape {shape.shape} '
                                     f'or non-finite values, expected (6, {m}) finite')
        if self.strut_frames is not None and self.strut_frames.shape != (5, 3, 3):
            raise ModelFileError(f'{self.source}: strut_frames has shape '
                                 f'{self.strut_frames.shape}, expected (5, 3, 3)')
        if self.zeta is not None and self.zeta.shape != (m,):
            raise ModelFileError(f'{self.source}: zeta has shape {self.zeta.shape}, '
                                 f'expected ({m},)')


def from_fe_modes(points: Mapping[str, Any], strut_frames: npt.ArrayLike,
                  frequencies_hz: npt.ArrayLike, shapes: npt.ArrayLike,
                  names: list[str] | None = None) -> ModalData:
    """Modal data of an FE model's modes at its named points (all, or ``names``)."""
    chosen = {n: points[n] for n in (names or points)}
    return ModalData(np.asarray(frequencies_hz, float), modal_points(chosen, shapes),
                     np.asarray(strut_frames, float), source='FE model')


def save_npz(data: ModalData, path: str | Path) -> Path:
    """Write modal data in the NPZ format above."""
    path = Path(path)
    arrays = {f'point:{n}': s for n, s in data.point_shapes.items()}
    arrays['frequencies_hz'] = data.frequencies_hz
    if data.strut_frames is not None:
        arrays['strut_frames'] = data.strut_frames
    if data.zeta is not None:
        arrays['zeta'] = data.zeta
    with open(path, 'wb') as stream:
        # numpy >= 2.1's stubs match **arrays also against the flag allow_pickle (a bool)
        np.savez(stream, **arrays)  # type: ignore[arg-type]
    return path


def save_csv(data: ModalData, path: str | Path) -> Path:
    """Write the shapes in the CSV format above (strut frames are not part of it)."""
    path = Path(path)
    with open(path, 'w', newline='') as stream:
        writer = csv.writer(stream)
        writer.writerow(CSV_COLUMNS)
        for j, f in enumerate(data.frequencies_hz):
            for name, shape in data.point_shapes.items():
                writer.writerow([j + 1, repr(float(f)), name] + [repr(float(v))
                                                                 for v in shape[:, j]])
    return path


def _load_npz(path: Path) -> ModalData:
    arrays = read_npz(path, 'modal data file')
    if 'frequencies_hz' not in arrays:
        raise ModelFileError(f'{path}: no array frequencies_hz')
    shapes = {k.split(':', 1)[1]: np.asarray(v, float) for k, v in arrays.items()
              if k.startswith('point:')}
    return ModalData(np.asarray(arrays['frequencies_hz'], float), shapes,
                     arrays.get('strut_frames'), arrays.get('zeta'), str(path))


def _load_csv(path: Path, strut_frames: np.ndarray | None) -> ModalData:
    try:
        with open(path, newline='') as stream:
            reader = csv.DictReader(stream)
            missing = set(CSV_COLUMNS) - set(reader.fieldnames or ())
            if missing:
                raise ModelFileError(f'{path}: missing columns {sorted(missing)}')
            rows = list(reader)
        modes = np.array([int(r['mode']) for r in rows])
        freqs = np.array([float(r['frequency_hz']) for r in rows])
        values = np.array([[float(r[c]) for c in CSV_COLUMNS[3:]] for r in rows])
    except (OSError, ValueError) as err:
        raise ModelFileError(f'cannot read modal data {path}: {err}') from None
    m = modes.max(initial=0)
    freq = np.full(m, np.nan)
    shapes: dict[str, np.ndarray] = {}
    for mode, f, row, r in zip(modes, freqs, values, rows):
        if mode < 1 or (not np.isnan(freq[mode - 1]) and freq[mode - 1] != f):
            raise ModelFileError(f'{path}: mode {mode} has inconsistent number or frequency')
        freq[mode - 1] = f
        shapes.setdefault(r['point'], np.full((6, m), np.nan))[:, mode - 1] = row
    return ModalData(freq, shapes, strut_frames, None, str(path))


def load_modal_data(path: str | Path, strut_frames_path: str | Path | None = None
                    ) -> ModalData:
    """
    Read modal data from an .npz or .csv file (format in the module docstring).

    Parameters
    ----------
    path : str or Path
        The data file.
    strut_frames_path : str or Path, optional
        YAML file with ``strut_frames`` (for CSV files, or to override the NPZ's frames).

    Raises
    ------
    ModelFileError
        For unreadable files, missing entries, wrong shapes, missing (mode, point) rows.
    """
    path = Path(path)
    frames = None
    if strut_frames_path is not None:
        try:
            frames = np.asarray(yaml.safe_load(Path(strut_frames_path).read_text())
                                ['strut_frames'], dtype=float)
        except (OSError, yaml.YAMLError, KeyError, TypeError, ValueError) as err:
            raise ModelFileError(f'cannot read strut frames {strut_frames_path}: {err}') \
                from None
    if path.suffix.lower() == '.npz':
        data = _load_npz(path)
        if frames is not None:
            data = ModalData(data.frequencies_hz, data.point_shapes, frames, data.zeta,
                             data.source)
        return data
    if path.suffix.lower() == '.csv':
        return _load_csv(path, frames)
    raise ModelFileError(f'{path}: unknown modal data format {path.suffix!r} '
                         '(use .npz or .csv)')
