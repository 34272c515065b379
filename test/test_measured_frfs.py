"""Measured data files: UFF 55 mode shapes out and back, CSV FRFs, labels, unit conversion."""
import numpy as np
from numpy.testing import assert_allclose
import pytest

from pentapod_sim.analysis.measured.frf_files import (
    MeasuredFrfs,
    read_csv,
    read_uff58,
    to_receptance,
    write_csv,
    write_uff58,
)
from pentapod_sim.analysis.measured.labels import parse_label
from pentapod_sim.analysis.measured.model_dofs import label_row
from pentapod_sim.analysis.measured.shapes55 import (
    model_shapes,
    read_uff55,
    write_port_values,
    write_uff55,
)
from pentapod_sim.errors import BagError, ConfigError
from pentapod_sim.fe.assembly import build_model
from pentapod_sim.fe.machine_data import load_machine
from pentapod_sim.modes.solver import solve_modes
from pentapod_sim.plant.ports import port


@pytest.fixture(scope='module')
def model():
    fe = build_model(load_machine(), 'P1')
    return fe, solve_modes(fe.K, fe.M, n_modes=12)


def test_uff55_round_trips_shapes_names_and_coordinates(model, tmp_path):
    fe, modes = model
    names = ['tcp', 'strut1_wp_end', 'bp_ring2', f'node:{fe.dofs.nodes[0]}']
    data = model_shapes(fe, modes.frequencies, modes.shapes, names)
    assert_allclose(data.shapes[0], np.asarray(fe.point('tcp') @ modes.shapes))
    back = read_uff55(write_uff55(tmp_path / 'modes.uff', data, zeta=0.001))
    assert back.names == names
    assert_allclose(back.frequencies_hz, modes.frequencies, rtol=1e-5)    # E13.5 fields
    scale = np.abs(data.shapes).max()
    assert np.abs(back.shapes - data.shapes).max() < 1e-5 * scale
    assert_allclose(back.positions, data.positions, rtol=1e-5, atol=1e-6)


def test_port_values_are_the_port_vectors_on_the_shapes(model, tmp_path):
    fe, modes = model
    path = write_port_values(tmp_path / 'ports.csv', fe, modes.frequencies, modes.shapes,
                             ['tcp_displacement_y', 'strut1_bending_2'])
    table = np.genfromtxt(path, delimiter=',', names=True)
    v = port(fe.points, fe.strut_frames, 'strut1_bending_2').vector @ modes.shapes
    assert_allclose(table['strut1_bending_2'], v, rtol=1e-12)


def test_csv_frfs_round_trip_and_mobility_becomes_receptance(tmp_path):
    freq = np.linspace(1.0, 50.0, 50)
    h = 1e-6 / (1 - (freq / 20) ** 2 + 0.02j * freq / 20)
    data = MeasuredFrfs(freq, np.stack([[h, 2 * h], [3 * h, 4 * h]]),
                        [parse_label('tcp:y'), parse_label('7:-z')],
                        [parse_label('tcp:y'), parse_label('tcp_force_x')])
    back = read_csv(write_csv(tmp_path / 'frf.csv', data))
    assert_allclose(back.H, data.H, rtol=0)
    assert [str(r) for r in back.responses] == ['tcp:+y', '7:-z']
    assert str(back.references[1]) == 'tcp_force_x'
    mobility = 1j * 2 * np.pi * freq * h
    assert_allclose(to_receptance(freq, mobility, 'velocity'), h, rtol=1e-12)
    accel = -(2 * np.pi * freq) ** 2 * h
    assert_allclose(to_receptance(freq, accel, 'acceleration'), h, rtol=1e-12)


def test_uff58_reader_needs_a_full_matrix_and_names_nodes(tmp_path):
    freq = np.arange(1.0, 3.0, 0.5)
    data = MeasuredFrfs(freq, np.ones((2, 2, 4), dtype=complex),
                        [parse_label('a:x'), parse_label('b:-y')],
                        [parse_label('a:x'), parse_label('a:y')])
    path = write_uff58(tmp_path / 'm.uff', data, {'a': 1, 'b': 2})
    back = read_uff58(path, {1: 'tcp'})
    assert [str(r) for r in back.responses] == ['tcp:+x', '2:-y']
    text = path.read_text().split('    -1\n    58\n')
    (tmp_path / 'part.uff').write_text('    -1\n    58\n'.join(text[:4]))
    with pytest.raises(BagError, match='missing'):
        read_uff58(tmp_path / 'part.uff')


def test_labels_map_to_points_nodes_and_ports(model):
    fe, _ = model
    row = label_row(fe, parse_label('tcp:-y')).toarray()[0]
    assert_allclose(row, -fe.point('tcp').toarray()[1])
    node = int(fe.dofs.nodes[10])
    comp = int(fe.dofs.components[10])
    row = label_row(fe, parse_label(f'{node}:{comp + 1}')).toarray()[0]
    assert row[10] == 1.0 and np.count_nonzero(row) == 1
    for bad, match in (('tpc:y', "no point 'tpc'"), ('tcp:w', 'not one of x, y, z'),
                       ('nonsense', 'not a port')):
        with pytest.raises(ConfigError, match=match):
            label_row(fe, parse_label(bad))
