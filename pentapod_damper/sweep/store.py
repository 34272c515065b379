"""
The result dataset of a sweep: one Parquet file per finished task under ``<out>/results``.

A file is written to a temporary name and renamed when complete, so a killed sweep leaves
only whole files. Every column carries its unit and meaning in the Parquet field metadata
(:func:`pentapod_damper.sweep.compute.columns`). ``<out>/sweep.json`` records the settings
digest: a sweep with other settings refuses to write into the same folder, and a rerun with
the same settings skips every pose whose row is ``ok`` or ``unreachable`` (``failed`` poses are
computed again; the newest row of a pose wins).
"""
from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path
from typing import Any, Sequence

import numpy as np
import pyarrow as pa
import pyarrow.dataset as pads
import pyarrow.parquet as pq

from pentapod_sim.errors import ConfigError

#: Arrow type of each column type of :func:`pentapod_damper.sweep.compute.columns`.
TYPES = {'str': pa.string(), 'float': pa.float64(), 'int': pa.int64()}
#: Statuses of rows that a rerun does not compute again.
FINAL = ('ok', 'unreachable')


def schema(cols: Sequence[tuple[str, str, str, str]]) -> pa.Schema:
    """Arrow schema of (name, type, unit, meaning) columns, unit and meaning as metadata."""
    return pa.schema([pa.field(name, TYPES[kind], metadata={'unit': unit, 'meaning': text})
                      for name, kind, unit, text in cols])


class ResultStore:
    """
    The Parquet dataset of one sweep.

    Parameters
    ----------
    out_dir : str or Path
        Folder of the sweep (``results/`` and ``sweep.json`` go there).
    cols : sequence
        Result columns (:func:`pentapod_damper.sweep.compute.columns`).
    digest : str
        Settings digest (:attr:`SweepSettings.digest`).
    """

    def __init__(self, out_dir: str | Path, cols: Sequence[tuple[str, str, str, str]],
                 digest: str) -> None:
        self.out_dir = Path(out_dir)
        self.results = self.out_dir / 'results'
        self.schema = schema(cols)
        self.digest = digest

    def open(self) -> 'ResultStore':
        """Create the folder or check that it holds a sweep with the same settings."""
        meta = self.out_dir / 'sweep.json'
        if meta.exists():
            old = json.loads(meta.read_text()).get('digest')
            if old != self.digest:
                raise ConfigError(f'{self.out_dir} holds a sweep with other settings (digest '
                                  f'{str(old)[:12]}, now {self.digest[:12]}); choose another '
                                  '--out or delete that folder')
        self.results.mkdir(parents=True, exist_ok=True)
        meta.write_text(json.dumps({'digest': self.digest,
                                    'columns': self.schema.names}, indent=1))
        return self

    def files(self) -> list[Path]:
        """The finished task files."""
        return sorted(self.results.glob('*.parquet')) if self.results.exists() else []

    def write(self, rows: Sequence[dict[str, Any]]) -> Path:
        """One file with ``rows`` (missing columns become null), named after their keys."""
        table = pa.Table.from_pylist([self._typed(r) for r in rows], schema=self.schema)
        name = hashlib.sha256('|'.join(r['key'] for r in rows).encode()).hexdigest()[:16]
        path = self.results / f'{name}.parquet'
        tmp = path.with_suffix(f'.tmp{os.getpid()}')
        pq.write_table(table, tmp)
        os.replace(tmp, path)
        return path

    def _typed(self, row: dict[str, Any]) -> dict[str, Any]:
        out = {}
        for field in self.schema:
            value = row.get(field.name)
            if value is not None and field.type == pa.float64():
                value = float(value)
            out[field.name] = value
        return out

    def load(self, columns: Sequence[str] | None = None) -> pa.Table:
        """All rows (newest per key), or an empty table."""
        files = self.files()
        if not files:
            return self.schema.empty_table()
        names = list(columns) if columns else self.schema.names
        want = list(dict.fromkeys(names + ['key', 'finished_at']))
        table = pads.dataset([str(f) for f in files], schema=self.schema,
                             format='parquet').to_table(columns=want)
        keys = table.column('key').to_pylist()
        order = np.argsort(table.column('finished_at').to_numpy(zero_copy_only=False),
                           kind='stable')
        newest = {keys[i]: i for i in order}
        table = table.take(sorted(newest.values()))
        return table.select(names)

    def done_keys(self) -> set[str]:
        """Keys of poses with a final row (``ok`` or ``unreachable``)."""
        table = self.load(['key', 'status'])
        return {k for k, s in zip(table.column('key').to_pylist(),
                                  table.column('status').to_pylist()) if s in FINAL}


def as_arrays(table: pa.Table) -> dict[str, np.ndarray]:
    """Column name -> numpy array (floats with NaN for null, objects for strings)."""
    out = {}
    for name in table.column_names:
        col = table.column(name)
        if pa.types.is_floating(col.type) or pa.types.is_integer(col.type):
            out[name] = np.asarray(col.cast(pa.float64()).fill_null(np.nan).to_numpy(),
                                   dtype=float)
        else:
            out[name] = np.array(col.to_pylist(), dtype=object)
    return out
