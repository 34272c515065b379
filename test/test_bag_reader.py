"""Bag reader: vectorised decoding vs mcap_ros2, stamps, truncated and corrupt files."""
import os
from pathlib import Path
import struct
import warnings

from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
import numpy as np
from numpy.testing import assert_allclose, assert_array_equal
import pytest

from fixtures.cdr import encode_joint_state, encode_wrench_stamped
from pentapod_sim.analysis.bag.reader import joint_unit, open_bag, Series
from pentapod_sim.analysis.frf.estimation import aligned
from pentapod_sim.errors import BagError
from pentapod_sim.recording import BagWriter

STATE = '/pentapod/strut_states'
WRENCH = '/pentapod/excitation'


def mixed_layout_bag(path: Path, n: int = 120) -> None:
    """JointState with changing frame ids, name sets and empty fields; several chunks."""
    rng = np.random.default_rng(3)
    with BagWriter(path, chunk_size=2048, flush_period_s=0.0) as writer:
        writer.add_topic(STATE, 'sensor_msgs/msg/JointState')
        writer.add_topic(WRENCH, 'geometry_msgs/msg/WrenchStamped')
        writer.add_topic('/pentapod/scalar', 'std_msgs/msg/Float64')
        for k in range(n):
            t_ns = k * 1_000_000
            names = ['strut1_bending_2', 'strut1_axial'] if k % 3 else ['strut1_axial']
            values = list(rng.normal(size=len(names)))
            velocity = list(rng.normal(size=len(names))) if k % 5 else []
            frame = 'f' * (k % 4)  # shifts every later offset and its alignment
            # log time deliberately different from the stamp
            writer.write(STATE, encode_joint_state(t_ns, names, values, velocity, [], frame),
                         t_ns + 777)
            writer.write(WRENCH, encode_wrench_stamped(t_ns, rng.normal(size=3),
                                                       rng.normal(size=3), frame), t_ns)
            writer.write('/pentapod/scalar', b'\x00\x01\x00\x00' + struct.pack('<d', k / 2),
                         t_ns + 5)


def decoded_reference(path: Path) -> dict:
    """Every message decoded by mcap_ros2 (independent of our CDR code)."""
    out = {}
    with open(path, 'rb') as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        for _, channel, message, msg in reader.iter_decoded_messages():
            out.setdefault(channel.topic, []).append((message.log_time, msg))
    return out


@pytest.fixture(scope='module')
def mixed(tmp_path_factory):
    path = tmp_path_factory.mktemp('bags') / 'mixed'
    mixed_layout_bag(path)
    return path, decoded_reference(path / 'mixed_0.mcap')


def test_joint_state_fields_equal_mcap_ros2(mixed):
    path, reference = mixed
    bag = open_bag(path)
    for field in ('position', 'velocity'):
        for name in ('strut1_bending_2', 'strut1_axial'):
            got = bag.series(f'{STATE}.{field}.{name}')
            expected = []
            for _, msg in reference[STATE]:
                values = getattr(msg, field)
                expected.append(values[list(msg.name).index(name)]
                                if name in msg.name and len(values) else np.nan)
            assert_allclose(got.values, expected, equal_nan=True)
    stamps = [m.header.stamp.sec * 10 ** 9 + m.header.stamp.nanosec for _, m in reference[STATE]]
    assert_array_equal(bag.series(f'{STATE}.position.strut1_axial').time_ns, stamps)


def test_wrench_fields_equal_mcap_ros2(mixed):
    path, reference = mixed
    bag = open_bag(path)
    for axis in 'xyz':
        for part in ('force', 'torque'):
            got = bag.series(f'{WRENCH}.wrench.{part}.{axis}')
            expected = [getattr(getattr(m.wrench, part), axis) for _, m in reference[WRENCH]]
            assert_allclose(got.values, expected)
            assert got.unit == ('N' if part == 'force' else 'N m')


def test_other_types_use_log_time_and_attribute_paths(mixed):
    path, _ = mixed
    series = open_bag(path).series('/pentapod/scalar.data')
    assert_allclose(series.values, np.arange(120) / 2)
    assert_array_equal(series.time_ns, np.arange(120) * 1_000_000 + 5)


def test_field_errors_list_what_exists(mixed):
    path, _ = mixed
    bag = open_bag(path)
    with pytest.raises(BagError, match='position.strut1_axial'):
        bag.series(f'{STATE}.position.tcp_x')
    with pytest.raises(BagError, match='/pentapod/excitation'):
        bag.series('/pentapod/missing.force.x')
    with pytest.raises(BagError, match='force.x'):
        bag.series(f'{WRENCH}.force.w')
    with pytest.raises(BagError, match='no effort'):
        bag.series(f'{STATE}.effort.strut1_axial')


@pytest.mark.parametrize('fraction', [0.3, 0.6, 0.95])
def test_truncated_bag_gives_readable_prefix_with_warning(mixed, tmp_path, fraction):
    path, reference = mixed
    data = (path / 'mixed_0.mcap').read_bytes()
    cut = tmp_path / 'cut.mcap'
    cut.write_bytes(data[:int(fraction * len(data))])
    with pytest.warns(UserWarning, match='ends early'):
        bag = open_bag(cut)
    assert bag.truncated
    wrench = bag.series(f'{WRENCH}.force.x')
    n = len(wrench.values)
    assert 0 < n <= 120  # a cut inside the summary section loses no message
    if fraction < 0.8:
        assert n < 120
    expected = [m.wrench.force.x for _, m in reference[WRENCH][:n]]
    assert_allclose(wrench.values, expected)  # an exact prefix, nothing garbled


def test_garbage_and_missing_files_raise_bag_error(tmp_path):
    junk = tmp_path / 'junk.mcap'
    junk.write_bytes(os.urandom(4096))
    with pytest.raises(BagError, match='junk.mcap'):
        open_bag(junk)
    empty = tmp_path / 'empty_bag'
    empty.mkdir()
    with pytest.raises(BagError, match='empty_bag'):
        open_bag(empty)
    with pytest.raises(BagError, match='nowhere'):
        open_bag(tmp_path / 'nowhere')
    header_only = tmp_path / 'header_only.mcap'
    header_only.write_bytes(b'\x89MCAP0\r\n' + b'\x01' + b'\xff' * 20)
    with pytest.raises(BagError, match='header_only.mcap'):
        open_bag(header_only)


def test_folder_without_metadata_yaml_and_bare_file(mixed, tmp_path):
    path, _ = mixed
    copy = tmp_path / 'nometa'
    copy.mkdir()
    (copy / 'x.mcap').write_bytes((path / 'mixed_0.mcap').read_bytes())
    with warnings.catch_warnings():
        warnings.simplefilter('error')
        assert open_bag(copy).message_count == 360
        assert open_bag(copy / 'x.mcap').message_count == 360


def test_alignment_on_common_stamps():
    t_u = np.arange(100) * 1_000_000
    t_y = np.delete(t_u, [10, 50])  # the response lost two samples
    u = Series(t_u * 1e-9, np.arange(100.0), 'N', 'u', t_u)
    y = Series(t_y * 1e-9, 2.0 * np.delete(np.arange(100.0), [10, 50]), 'm', 'y', t_y)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter('always')
        u_val, y_val, fs = aligned(u, y)
    messages = ' '.join(str(w.message) for w in caught)
    assert 'no partner' in messages and '2 irregular time steps' in messages
    assert_allclose(y_val, 2 * u_val)
    assert len(u_val) == 98
    assert fs == pytest.approx(1000.0)


def test_units_follow_port_naming():
    assert joint_unit('position', 'tcp_x') == 'm'
    assert joint_unit('velocity', 'strut2_bending_3') == 'rad/s'
    assert joint_unit('effort', 'strut2_bending_moment_3') == 'N m'
    assert joint_unit('effort', 'pma_force_x') == 'N'


def test_topic_selection_loads_only_those_messages(mixed):
    path, reference = mixed
    bag = open_bag(path, topics=[WRENCH])
    assert bag.topics[STATE].count == 0 and bag.topics[WRENCH].count == 120
    expected = [m.wrench.torque.z for _, m in reference[WRENCH]]
    assert_allclose(bag.series(f'{WRENCH}.torque.z').values, expected)
