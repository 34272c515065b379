"""
Export measured FRFs as CSV and as universal file format (UFF) dataset 58.

The UFF 58 writer is hand-written (pyuff is not a project dependency; the format is small):
one block per FRF, records 1-5 ID lines (80A1), record 6 DOF identification
(2(I5,I10),2(1X,I10,1X,A10,I10,I4)), record 7 data form (3I10,3E13.5), records 8-11 axis
characteristics (I10,3I5,2(1X,A20)), record 12 data; complex double precision with even
abscissa spacing (ordinate type 6) written as 4E20.12 (two complex values per line).
"""
import csv
import datetime
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from pentapod_sim.analysis.frf.estimation import FrfResult
from pentapod_sim.errors import BagError

FUNCTION_TYPE_FRF = 4
ORDINATE_COMPLEX_DOUBLE = 6
# UFF 58 specific data types and their (length, force) unit exponents
DATA_TYPES = {
    'm': (8, 1, 0),        # displacement
    'm/s': (11, 1, 0),     # velocity
    'm/s^2': (12, 1, 0),   # acceleration
    'N': (13, 0, 1),       # excitation force
    'N m': (13, 1, 1),     # moment (force type, length x force)
    'rad': (1, 0, 0),      # general
    'rad/s': (1, 0, 0),
    'Hz': (18, 0, 0),      # frequency
}


def write_csv(path: str | Path, results: Sequence[FrfResult]) -> Path:
    """
    Write FRFs as CSV: freq_Hz, then per FRF re, im, magnitude, phase_rad, coherence.

    Parameters
    ----------
    path : str or Path
        Output file.
    results : list of FrfResult
        FRFs on the same frequency grid.

    Returns
    -------
    Path
    """
    path = Path(path)
    freq = results[0].freq
    if any(len(r.freq) != len(freq) or not np.allclose(r.freq, freq) for r in results):
        raise BagError('CSV export needs FRFs on one frequency grid; write one file per FRF')
    header = ['freq_Hz']
    columns = [freq]
    for k, res in enumerate(results):
        tag = f'H{k}[{res.unit}]'
        header += [f'{tag}_re', f'{tag}_im', f'{tag}_abs', f'{tag}_phase_rad',
                   f'{tag}_coherence']
        columns += [res.H.real, res.H.imag, np.abs(res.H), np.angle(res.H), res.coherence]
    with open(path, 'w', newline='', encoding='utf-8') as handle:
        writer = csv.writer(handle)
        writer.writerow(header)
        writer.writerows(np.column_stack(columns).tolist())
    return path


def _axis_record(unit: str, label: str) -> str:
    data_type, length_exp, force_exp = DATA_TYPES.get(unit, (0, 0, 0))
    return f'{data_type:10d}{length_exp:5d}{force_exp:5d}{0:5d} {label[:20]:<20s} {unit[:20]:<20s}'


def _e13(value: float) -> str:
    return f'{value:13.5E}'


def uff58_block(result: FrfResult, response_node: int = 1, response_dir: int = 1,
                reference_node: int = 1, reference_dir: int = 1, function_id: int = 1,
                name: str = '') -> str:
    """
    Format one FRF as a UFF dataset 58 block (text between two ``    -1`` lines included).

    Parameters
    ----------
    result : FrfResult
        FRF with evenly spaced frequencies.
    response_node, response_dir, reference_node, reference_dir : int
        UFF node numbers and directions (1..3 = +X..+Z, 4..6 = +RX..+RZ, negative = -).
    function_id : int
        Function identification number (record 6 field 2).
    name : str
        ID line 1 text (default: the result label).

    Returns
    -------
    str
    """
    freq = np.asarray(result.freq, dtype=float)
    if len(freq) > 1 and not np.allclose(np.diff(freq), freq[1] - freq[0], rtol=1e-6):
        raise BagError('UFF 58 export supports evenly spaced frequencies only')
    step = freq[1] - freq[0] if len(freq) > 1 else 0.0
    stamp = datetime.datetime.now(datetime.timezone.utc).strftime('%d-%b-%y %H:%M:%S')
    lines = [f'{-1:6d}', f'{58:6d}']
    lines += [(name or result.label or 'FRF')[:80], f'{result.excitation} excitation, '
              f'{result.n_averages} averages, H [{result.unit}]'[:80], stamp, 'pentapod_testbed',
              'NONE']
    lines.append(f'{FUNCTION_TYPE_FRF:5d}{function_id:10d}{1:5d}{0:10d} {"NONE":<10s}'
                 f'{response_node:10d}{response_dir:4d} {"NONE":<10s}{reference_node:10d}'
                 f'{reference_dir:4d}')
    lines.append(f'{ORDINATE_COMPLEX_DOUBLE:10d}{len(freq):10d}{1:10d}'
                 + _e13(freq[0]) + _e13(step) + _e13(0.0))
    lines.append(_axis_record('Hz', 'Frequency'))
    lines.append(_axis_record(result.output_unit, 'Response'))
    lines.append(_axis_record(result.input_unit, 'Reference'))
    lines.append(_axis_record('', 'NONE'))
    pairs = np.column_stack([result.H.real, result.H.imag]).ravel()
    pairs = np.nan_to_num(pairs)
    for start in range(0, len(pairs), 4):
        lines.append(''.join(f'{v:20.12E}' for v in pairs[start:start + 4]))
    lines.append(f'{-1:6d}')
    return '\n'.join(lines) + '\n'


def write_uff58(path: str | Path, results: Sequence[FrfResult], **kwargs: Any) -> Path:
    """
    Write FRFs as consecutive UFF 58 datasets (function ids 1, 2, ...).

    Parameters
    ----------
    path : str or Path
        Output ``.uff`` file.
    results : list of FrfResult
        FRFs to write.
    **kwargs
        Passed to :func:`uff58_block` (node numbers, directions).

    Returns
    -------
    Path
    """
    path = Path(path)
    text = ''.join(uff58_block(r, function_id=k + 1, **kwargs) for k, r in enumerate(results))
    path.write_text(text, encoding='ascii')
    return path
