"""UFF dataset 58 and CSV export: fixed-width fields parsed per the format specification."""
import csv

import numpy as np
from numpy.testing import assert_allclose
import pytest

from pentapod_sim.analysis.frf.estimation import FrfResult
from pentapod_sim.analysis.frf.export import uff58_block, write_csv, write_uff58
from pentapod_sim.errors import BagError


def first_order_frf(n: int = 41, df: float = 0.25) -> FrfResult:
    freq = np.arange(n) * df + 1.0  # Hz
    h = 2e-6 / (1 + 1j * freq / 3.0)  # m/N
    return FrfResult(freq, h, h, h, np.linspace(0.5, 1.0, n), 'N', 'm', 'random', 12, None,
                     '/pentapod/excitation.force.x -> /pentapod/tcp_state.position.tcp_x')


def parse_block(lines: list) -> dict:
    """Read one dataset 58 block by the column layout of the UFF 58 specification."""
    assert lines[0] == '    -1' and lines[1] == '    58' and lines[-1] == '    -1'
    r6, r7 = lines[7], lines[8]
    out = {
        'id1': lines[2],
        'function_type': int(r6[0:5]), 'function_id': int(r6[5:15]),
        'version': int(r6[15:20]), 'load_case': int(r6[20:30]),
        'response_entity': r6[31:41].strip(), 'response_node': int(r6[41:51]),
        'response_dir': int(r6[51:55]), 'reference_entity': r6[56:66].strip(),
        'reference_node': int(r6[66:76]), 'reference_dir': int(r6[76:80]),
        'ordinate_type': int(r7[0:10]), 'n_values': int(r7[10:20]),
        'even_spacing': int(r7[20:30]), 'x_min': float(r7[30:43]),
        'x_step': float(r7[43:56]), 'z_value': float(r7[56:69]),
    }
    for key, line in zip(('abscissa', 'numerator', 'denominator', 'z_axis'), lines[9:13]):
        out[key] = (int(line[0:10]), int(line[10:15]), int(line[15:20]), int(line[20:25]),
                    line[26:46].strip(), line[47:67].strip())
    values = []
    for line in lines[13:-1]:
        assert len(line) <= 80 and len(line) % 20 == 0
        values += [float(line[k:k + 20]) for k in range(0, len(line), 20)]
    out['data'] = np.array(values[0::2]) + 1j * np.array(values[1::2])
    return out


def test_uff58_fields_follow_the_specification():
    res = first_order_frf()
    text = uff58_block(res, response_node=7, response_dir=-2, reference_node=3,
                       reference_dir=1, function_id=5)
    lines = text.splitlines()
    assert all(len(line) <= 80 for line in lines)
    block = parse_block(lines)
    assert block['id1'].startswith('/pentapod/excitation.force.x')
    assert (block['function_type'], block['function_id']) == (4, 5)  # 4 = FRF
    assert (block['response_node'], block['response_dir']) == (7, -2)
    assert (block['reference_node'], block['reference_dir']) == (3, 1)
    assert (block['ordinate_type'], block['n_values'], block['even_spacing']) == (6, 41, 1)
    assert_allclose([block['x_min'], block['x_step']], [1.0, 0.25])
    assert block['abscissa'][0] == 18  # frequency
    assert block['numerator'][:3] == (8, 1, 0)  # displacement, length^1
    assert block['denominator'][:3] == (13, 0, 1)  # excitation force, force^1
    assert_allclose(block['data'], res.H, rtol=1e-11)


def test_uff58_file_holds_one_block_per_frf(tmp_path):
    res = first_order_frf()
    path = write_uff58(tmp_path / 'frf.uff', [res, res])
    lines = path.read_text(encoding='ascii').splitlines()
    starts = [k for k in range(len(lines) - 1)
              if lines[k] == '    -1' and lines[k + 1] == '    58']
    assert len(starts) == 2
    second = parse_block(lines[starts[1]:])
    assert second['function_id'] == 2
    assert_allclose(second['data'], res.H, rtol=1e-11)


def test_uff58_rejects_uneven_frequencies():
    res = first_order_frf()
    res.freq = res.freq ** 1.5
    with pytest.raises(BagError, match='evenly spaced'):
        uff58_block(res)


def test_csv_columns_round_trip(tmp_path):
    res = first_order_frf()
    path = write_csv(tmp_path / 'frf.csv', [res])
    with open(path, newline='', encoding='utf-8') as handle:
        rows = list(csv.reader(handle))
    assert rows[0][0] == 'freq_Hz' and rows[0][1] == 'H0[m/N]_re'
    table = np.array(rows[1:], dtype=float)
    assert_allclose(table[:, 0], res.freq)
    assert_allclose(table[:, 1] + 1j * table[:, 2], res.H)
    assert_allclose(table[:, 3], np.abs(res.H))
    assert_allclose(table[:, 4], np.angle(res.H))
    assert_allclose(table[:, 5], res.coherence)


@pytest.mark.parametrize('spec, code', [
    ('/pentapod/excitation.force.x', 1), ('/pentapod/excitation.wrench.torque.y', 5),
    ('/pentapod/tcp_state.position.tcp_z', 3), ('/pentapod/tcp_state.tcp_y.velocity', 2),
    ('/pentapod/strut_states.position.strut1_axial', 0), ('/pentapod/x.position.tcp_rz', 6)])
def test_uff_direction_codes_from_field_names(spec, code):
    from pentapod_sim.cli.analyze import uff_direction
    assert uff_direction(spec) == code
