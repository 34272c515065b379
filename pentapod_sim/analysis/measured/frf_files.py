"""
Measured FRFs in: UFF dataset 58 (read with pyuff) and CSV, as receptances with DOF labels.

UFF 58: every dataset of function type 4 (FRF) is one response/reference pair; the ordinate's
specific data type says whether it is a receptance (8, displacement), mobility (11, velocity)
or accelerance (12, acceleration); values are taken as SI. All pairs must share one frequency
axis and together fill the response x reference matrix.

CSV (long form, one line per pair and frequency line): header
``response,reference,frequency_hz,real,imag`` with DOF labels as in
:mod:`pentapod_sim.analysis.measured.labels`; the quantity (displacement, velocity or
acceleration per force) is given by the caller.

Mobilities and accelerances are converted to receptances, ``H / (j w)`` and ``H / (j w)^2``,
so the identified modal constants compare with the model's displacement shapes.
"""
from __future__ import annotations

import csv
from dataclasses import dataclass
import os
from pathlib import Path

import numpy as np
import numpy.typing as npt

from pentapod_sim.analysis.frf.estimation import FrfResult
from pentapod_sim.analysis.frf.export import uff58_block
from pentapod_sim.analysis.measured.labels import DofLabel, parse_label, uff_label
from pentapod_sim.errors import BagError

#: UFF specific data type of the ordinate -> (quantity, power of j w that makes a receptance).
UFF_QUANTITIES = {8: ('displacement', 0), 11: ('velocity', 1), 12: ('acceleration', 2)}
POWERS = dict(UFF_QUANTITIES.values())
CSV_COLUMNS = ('response', 'reference', 'frequency_hz', 'real', 'imag')
#: One FRF of a file: (response, reference).
Pair = tuple[DofLabel, DofLabel]


@dataclass
class MeasuredFrfs:
    """
    Measured receptances.

    Attributes
    ----------
    freq : (F,) ndarray
        Frequencies [Hz].
    H : (No, Ni, F) complex ndarray
        Receptances (response displacement per reference force) [m/N, rad/N, m/(N m)].
    responses, references : list of DofLabel
        What each row / column measures.
    quantity : str
        What the file held: 'displacement', 'velocity' or 'acceleration' per force.
    source : str
        The file.
    """

    freq: npt.NDArray[np.float64]
    H: npt.NDArray[np.complex128]
    responses: list[DofLabel]
    references: list[DofLabel]
    quantity: str = 'displacement'
    source: str = ''


def to_receptance(freq: npt.ArrayLike, H: npt.ArrayLike,
                  quantity: str) -> npt.NDArray[np.complex128]:
    """Receptance from a receptance, mobility or accelerance (``H / (j w)^p``)."""
    if quantity not in POWERS:
        raise BagError(f'unknown FRF quantity {quantity!r}; known: {", ".join(POWERS)}')
    jw = 1j * 2 * np.pi * np.asarray(freq, dtype=float)
    with np.errstate(divide='ignore', invalid='ignore'):
        return np.asarray(H) / jw ** POWERS[quantity]


def _matrix(pairs: dict[Pair, npt.NDArray[np.complex128]], responses: list[DofLabel],
            references: list[DofLabel], source: str) -> npt.NDArray[np.complex128]:
    missing = [f'{r}/{q}' for r in responses for q in references if (r, q) not in pairs]
    if missing:
        raise BagError(f'{source}: the FRFs do not fill the response x reference matrix; '
                       f'missing {", ".join(missing[:6])}{" ..." if len(missing) > 6 else ""}')
    return np.array([[pairs[(r, q)] for q in references] for r in responses])


def read_uff58(path: str | os.PathLike[str], names: dict[int, str] | None = None) -> MeasuredFrfs:
    """
    FRFs of a UFF file (datasets 58 of function type 4; other datasets are skipped).

    Parameters
    ----------
    path : path
        The ``.uff`` / ``.unv`` file.
    names : dict of int to str, optional
        UFF node number -> point name or FE node label (default: the node number).
    """
    import pyuff
    try:
        sets = pyuff.UFF(os.fspath(path)).read_sets()
    except Exception as err:      # pyuff raises bare Exceptions for malformed files
        raise BagError(f'{path}: not a readable UFF file: {err}') from None
    sets = [s for s in (sets if isinstance(sets, list) else [sets])
            if s.get('type') == 58 and s.get('func_type') == 4]
    if not sets:
        raise BagError(f'{path}: no UFF 58 FRF dataset (function type 4)')
    freq = np.asarray(sets[0]['x'], dtype=float)
    kinds = {s.get('ordinate_spec_data_type') for s in sets}
    if len(kinds) != 1 or next(iter(kinds)) not in UFF_QUANTITIES:
        raise BagError(f'{path}: ordinate types {sorted(map(str, kinds))}: expected one of '
                       '8 (displacement), 11 (velocity), 12 (acceleration)')
    quantity = UFF_QUANTITIES[next(iter(kinds))][0]
    pairs: dict[Pair, npt.NDArray[np.complex128]] = {}
    responses: list[DofLabel] = []
    references: list[DofLabel] = []
    for s in sets:
        if len(s['x']) != len(freq) or not np.allclose(s['x'], freq, rtol=1e-9, atol=0):
            raise BagError(f'{path}: FRF {s["rsp_node"]}:{s["rsp_dir"]} / {s["ref_node"]}:'
                           f'{s["ref_dir"]} has another frequency axis')
        r = uff_label(s['rsp_node'], s['rsp_dir'], names or {})
        q = uff_label(s['ref_node'], s['ref_dir'], names or {})
        responses += [r] if r not in responses else []
        references += [q] if q not in references else []
        pairs[(r, q)] = np.asarray(s['data'], dtype=complex)
    H = to_receptance(freq, _matrix(pairs, responses, references, str(path)), quantity)
    return MeasuredFrfs(freq, H, responses, references, quantity, str(path))


def read_csv(path: str | os.PathLike[str], quantity: str = 'displacement') -> MeasuredFrfs:
    """FRFs of a long-form CSV (module docstring); ``quantity`` per unit force."""
    pairs: dict[Pair, list[tuple[float, complex]]] = {}
    try:
        with open(path, newline='', encoding='utf-8') as stream:
            reader = csv.DictReader(stream)
            if tuple(reader.fieldnames or ())[:5] != CSV_COLUMNS:
                raise BagError(f'{path}: expected the header {",".join(CSV_COLUMNS)}')
            for row in reader:
                key = (parse_label(row['response']), parse_label(row['reference']))
                pairs.setdefault(key, []).append((float(row['frequency_hz']),
                                                  complex(float(row['real']),
                                                          float(row['imag']))))
    except OSError as err:
        raise BagError(f'{path}: cannot read: {err}') from None
    except (TypeError, ValueError) as err:
        raise BagError(f'{path}: bad FRF line: {err}') from None
    if not pairs:
        raise BagError(f'{path}: no FRF lines')
    responses = list(dict.fromkeys(r for r, _ in pairs))
    references = list(dict.fromkeys(q for _, q in pairs))
    freq = np.array([f for f, _ in next(iter(pairs.values()))])
    values: dict[Pair, npt.NDArray[np.complex128]] = {}
    for key, lines in pairs.items():
        f = np.array([v[0] for v in lines])
        if len(f) != len(freq) or not np.allclose(f, freq, rtol=1e-12, atol=0):
            raise BagError(f'{path}: FRF {key[0]}/{key[1]} has another frequency axis')
        values[key] = np.array([v[1] for v in lines])
    H = to_receptance(freq, _matrix(values, responses, references, str(path)), quantity)
    return MeasuredFrfs(freq, H, responses, references, quantity, str(path))


def write_csv(path: str | os.PathLike[str], data: MeasuredFrfs) -> Path:
    """Write receptances in the long CSV form (exact doubles)."""
    with open(path, 'w', newline='', encoding='utf-8') as stream:
        writer = csv.writer(stream)
        writer.writerow(CSV_COLUMNS)
        for i, r in enumerate(data.responses):
            for k, q in enumerate(data.references):
                for f, h in zip(data.freq, data.H[i, k]):
                    writer.writerow([r, q, repr(float(f)), repr(float(h.real)),
                                     repr(float(h.imag))])
    return Path(path)


def _uff_dof(label: DofLabel, numbers: dict[str, int]) -> tuple[int, int]:
    """UFF node number and signed direction (+-1..6) of a point or node label."""
    if label.component is None or label.target not in numbers:
        raise BagError(f'UFF 58 export: {label} needs a node number and direction')
    return numbers[label.target], int(label.sign * (label.component + 1))


def write_uff58(path: str | os.PathLike[str], data: MeasuredFrfs, numbers: dict[str, int],
                input_unit: str = 'N', output_unit: str = 'm') -> Path:
    """
    Write receptances as UFF 58 datasets (the project's writer); ``numbers``: target -> node.

    Raises
    ------
    BagError
        For a label without a node number or a port label (UFF needs node and direction).
    """
    blocks: list[str] = []
    for i, r in enumerate(data.responses):
        for k, q in enumerate(data.references):
            (r_node, r_dir), (q_node, q_dir) = (_uff_dof(label, numbers) for label in (r, q))
            h = data.H[i, k]
            result = FrfResult(data.freq, h, h, h, np.ones(len(h)), input_unit, output_unit,
                               'measured', 1, None, f'{r} / {q}')
            blocks.append(uff58_block(result, r_node, r_dir, q_node, q_dir,
                                      function_id=len(blocks) + 1))
    path = Path(path)
    path.write_text(''.join(blocks), encoding='ascii')
    return path
