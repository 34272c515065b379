"""
The reduced modal plant: continuous and discrete state space, save/load.

State order: ``x = [q_1..q_m, dq_1..dq_m]`` (modal displacements [sqrt(kg) m] and their
rates), so that ``A = [[0, I], [-W^2, -2 Z W]]``, ``B = [0; b]``, ``C = [c_disp, c_vel]``.
External modal data (frequencies plus mass-normalised shapes at the named points) enters
through :func:`pentapod_sim.plant.build.from_modal_data` (files:
:mod:`pentapod_sim.plant.external_modes`); the whole chain for a machine position is
:func:`pentapod_sim.plant.build.build_plant`.
"""
from __future__ import annotations

import contextlib
from dataclasses import dataclass, field
import hashlib
import json
import logging
import os
from pathlib import Path
from typing import Any
import zipfile

import control
import numpy as np
import numpy.typing as npt
import scipy.linalg as spla

from pentapod_sim.errors import ConfigError, ModelFileError, PortError
from pentapod_sim.plant.ports import check_names

LOG = logging.getLogger(__name__)

_ARRAYS = ('omega', 'zeta', 'b', 'c_disp', 'c_vel', 'd')
_LISTS = ('input_names', 'output_names', 'input_units', 'output_units',
          'input_descriptions', 'output_descriptions')
FILE_FORMAT = 'pentapod-plant-model-1'
#: First bytes of a zip archive (an .npz) and of a single saved array (.npy).
ZIP_MAGIC, NPY_MAGIC = b'PK\x03\x04', b'\x93NUMPY'


def _file_kind(head: bytes) -> str:
    """What a file that is no .npz archive is, from its first bytes (for error messages)."""
    if not head:
        return 'an empty file'
    if head.startswith(NPY_MAGIC):
        return 'a single array (.npy), not an archive of named arrays'
    text = '\0'
    for cut in range(4):        # the first bytes may end inside a multi-byte character
        try:
            text = head[:len(head) - cut].decode('utf-8')
            break
        except UnicodeDecodeError:
            pass
    if not all(c.isprintable() or c in '\t\r\n' for c in text):
        return f'binary data starting {head[:8]!r}'
    first = text.splitlines()[0] if text.strip() else ''
    return f'a text file starting {first[:40]!r}' if first else 'a text file'


def read_npz(path: str | Path, what: str) -> dict[str, np.ndarray]:
    """
    The arrays of an .npz archive; a file of another kind is one :class:`ModelFileError` line.

    Nothing is unpickled: an array of Python objects is refused, naming it. ``what`` names the
    expected content in messages (e.g. ``plant model``).
    """
    path = Path(path)
    try:
        with open(path, 'rb') as stream:
            head = stream.read(64)
    except OSError as err:
        raise ModelFileError(f'cannot read {what} {path}: {err.strerror or err}') from None
    if not head.startswith(ZIP_MAGIC):
        raise ModelFileError(f'{path} is not a {what} (an .npz archive): it is '
                             f'{_file_kind(head)}')
    arrays, unreadable = {}, []
    try:
        with np.load(path, allow_pickle=False) as data:
            for name in data.files:
                try:
                    arrays[name] = data[name]
                except ValueError:          # object arrays (pickles) or a damaged header
                    unreadable.append(name)
    except (OSError, EOFError, zipfile.BadZipFile, ValueError) as err:
        raise ModelFileError(f'{path} is not a readable {what}: a damaged .npz archive '
                             f'({type(err).__name__})') from None
    if unreadable:
        raise ModelFileError(f'{path} is not a {what}: its array(s) {", ".join(unreadable)} '
                             'hold Python objects (never loaded) or are damaged')
    return arrays


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
    meta: dict[str, Any] = field(default_factory=dict)

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
        """Continuous-time matrices A (2m, 2m), B (2m, n_in), C (n_out, 2m), D (n_out, n_in)."""
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
        """Discrete state space (exact ZOH, sample time ``dt`` [s]) with the same names."""
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

    def fe_mode(self, mode: int) -> tuple[int, str]:
        """
        FE mode number (1-based) and cause of this plant's mode ``mode`` (1-based).

        A reduced plant keeps some of the FE model's modes (``meta['kept_modes']``), so its
        mode numbers differ from the FE model's once a lower mode was left out; the cause is
        the stiffness group with the largest share of the mode's strain energy
        (``meta['mode_causes']``, :func:`pentapod_sim.plant.build.mode_causes`). A plant
        without these records (made from modal data) gives its own number and no cause.
        """
        kept = self.meta.get('kept_modes')
        fe_mode = int(kept[mode - 1]) if kept else mode
        causes = self.meta.get('mode_causes') or []
        return fe_mode, str(causes[fe_mode - 1]) if fe_mode - 1 < len(causes) else ''

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

        Raises
        ------
        ModelFileError
            One line if the folder or file cannot be made (e.g. a folder that is a file).
        """
        path = Path(path)
        header: dict[str, Any] = {n: list(getattr(self, n)) for n in _LISTS}
        header.update(format=FILE_FORMAT, meta=self.meta, content_hash=self.content_hash())
        # written next to it and renamed: a process reading the same cache file (two studies,
        # parallel tests) sees the old file or the whole new one, never a half-written one
        part = path.with_name(f'{path.name}.{os.getpid()}.part')
        try:        # e.g. a cache folder that is a file: one line, not a traceback
            path.parent.mkdir(parents=True, exist_ok=True)
            with open(part, 'wb') as stream:
                np.savez(stream, header=np.array(json.dumps(header)),
                         **{n: getattr(self, n) for n in _ARRAYS})
            os.replace(part, path)
        except OSError as err:
            with contextlib.suppress(OSError):
                part.unlink()
            raise ModelFileError(f'cannot write plant model {path}: {err.strerror or err} '
                                 f'({err.filename or path})') from None
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
        data = read_npz(path, 'plant model')
        missing = [n for n in ('header', *_ARRAYS) if n not in data]
        if missing:
            raise ModelFileError(f'{path} is an .npz archive but not a plant model: it lacks '
                                 f'{", ".join(missing)} (has {", ".join(sorted(data)) or "none"})')
        try:
            header = json.loads(str(data['header']))
        except ValueError:
            header = None
        if not isinstance(header, dict):
            raise ModelFileError(f'{path}: its header is not the JSON mapping of a plant model')
        arrays: dict[str, Any] = {n: data[n] for n in _ARRAYS}
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
