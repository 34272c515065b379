"""Bag writer: CDR encoders, ros2msg schemas, rosbag2 metadata, independent readers."""
from pathlib import Path
import shutil
import warnings

from mcap.reader import make_reader
import numpy as np
from numpy.testing import assert_allclose
import pytest
import yaml

from fixtures.cdr import encode_clock, encode_joint_state, encode_wrench_stamped
from pentapod_sim.analysis.bag.cdr_arrays import joint_state_arrays, joint_state_layout
from pentapod_sim.analysis.bag.reader import open_bag
from pentapod_sim.errors import BagError
from pentapod_sim.recording import BagWriter, message_definition, QOS_BEST_EFFORT
from pentapod_sim.recording.msgdefs import has_header_stamp

TYPES = ['sensor_msgs/msg/JointState', 'geometry_msgs/msg/WrenchStamped',
         'rosgraph_msgs/msg/Clock', 'std_msgs/msg/Float64MultiArray']
RUN_INFO = {'model_hash': 'sha256:0f0e', 'pose_m': '[0.0, 0.0, 1.2]', 'scenario': 'random'}


@pytest.mark.parametrize('frame_id', ['', 'a', 'tcp', 'world_frame'])
@pytest.mark.parametrize('names, position, velocity, effort', [
    (['tcp_x'], [1.5], [], []),
    (['a', 'bb', 'ccc'], [1.0, 2.0, 3.0], [4.0, 5.0, 6.0], [7.0, 8.0, 9.0]),
    (['strut1_axial', 'x'], [], [], [0.25, -0.5]),
    ([], [], [], []),
])
def test_joint_state_cdr_matches_rclpy(frame_id, names, position, velocity, effort):
    from rclpy.serialization import deserialize_message, serialize_message
    from sensor_msgs.msg import JointState
    ours = encode_joint_state(1_234_000_567_891, names, position, velocity, effort, frame_id)
    msg = deserialize_message(ours, JointState)
    assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == (1234, 567_891)
    assert msg.header.frame_id == frame_id and list(msg.name) == names
    assert list(msg.position) == position and list(msg.velocity) == velocity
    assert list(msg.effort) == effort
    theirs = serialize_message(msg)
    # rclpy leaves alignment padding uninitialised, so compare decoded content: our vectorised
    # decoder must read rclpy's bytes, and rclpy's bytes must agree with ours outside padding
    decoded_names, values = joint_state_arrays([theirs])
    assert decoded_names == names
    for field, expected in (('position', position), ('velocity', velocity),
                            ('effort', effort)):
        got = values[field][0]
        if expected:
            assert_allclose(got, expected)
        else:
            assert np.all(np.isnan(got))
    layout = joint_state_layout(ours)
    meaningful = list(layout.structure) + [k for off, n in layout.arrays.values()
                                           for k in range(off, off + 8 * n)]
    assert bytes(theirs[k] for k in meaningful) == bytes(ours[k] for k in meaningful)
    assert len(theirs) >= len(ours)


@pytest.mark.parametrize('frame_id', ['', 'ab', 'tcp_frame'])
def test_wrench_and_clock_cdr_match_rclpy(frame_id):
    from geometry_msgs.msg import WrenchStamped
    from rclpy.serialization import deserialize_message
    from rosgraph_msgs.msg import Clock
    ours = encode_wrench_stamped(5_000_000_001, [1.0, -2.0, 3.5], [0.1, 0.2, -0.3], frame_id)
    msg = deserialize_message(ours, WrenchStamped)
    assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == (5, 1)
    assert msg.header.frame_id == frame_id
    force, torque = msg.wrench.force, msg.wrench.torque
    assert [force.x, force.y, force.z, torque.x, torque.y, torque.z] == [
        1.0, -2.0, 3.5, 0.1, 0.2, -0.3]
    clock = deserialize_message(encode_clock(7_000_000_008), Clock)
    assert (clock.clock.sec, clock.clock.nanosec) == (7, 8)


@pytest.mark.parametrize('msg_type', TYPES)
def test_message_definition_parses_like_the_rosbags_typestore(msg_type):
    from rosbags.typesys import get_types_from_msg, get_typestore, Stores
    store = get_typestore(Stores.ROS2_JAZZY)
    parsed = get_types_from_msg(message_definition(msg_type), msg_type)
    assert msg_type in parsed
    for name, definition in parsed.items():  # the type and every dependency
        assert definition == store.fielddefs[name], name
    # every dependency appears exactly once, after the top-level text
    text = message_definition(msg_type)
    assert len(parsed) == 1 + text.count('\nMSG: ')


def test_header_stamp_detection():
    assert has_header_stamp('sensor_msgs/msg/JointState')
    assert has_header_stamp('rosgraph_msgs/msg/Clock')
    assert not has_header_stamp('std_msgs/msg/Float64MultiArray')
    with pytest.raises(BagError, match='no_such_pkg'):
        message_definition('no_such_pkg/msg/Nothing')


def write_example(path: Path, n: int = 50) -> None:
    with BagWriter(path, run_info=RUN_INFO, flush_period_s=0.0) as writer:
        writer.add_topic('/pentapod/tcp_state', 'sensor_msgs/msg/JointState')
        writer.add_topic('/pentapod/excitation', 'geometry_msgs/msg/WrenchStamped',
                         [QOS_BEST_EFFORT])
        for k in range(n):
            t_ns = 10_000_000_000 + k * 2_000_000
            writer.write('/pentapod/tcp_state',
                         encode_joint_state(t_ns, ['tcp_x'], [k * 1e-6], [k * 1e-3]), t_ns)
            writer.write('/pentapod/excitation', encode_wrench_stamped(t_ns, [k, 0, 0]), t_ns)


def test_metadata_yaml_and_mcap_agree(tmp_path):
    bag = tmp_path / 'run1'
    write_example(bag)
    info = yaml.safe_load((bag / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    assert info['version'] == 9 and info['storage_identifier'] == 'mcap'
    assert info['relative_file_paths'] == ['run1_0.mcap']
    assert info['message_count'] == 100
    assert info['starting_time']['nanoseconds_since_epoch'] == 10_000_000_000
    assert info['duration']['nanoseconds'] == 49 * 2_000_000
    assert info['custom_data']['model_hash'] == RUN_INFO['model_hash']
    assert info['custom_data']['package_version']
    topics = {t['topic_metadata']['name']: t for t in info['topics_with_message_count']}
    assert {name: t['message_count'] for name, t in topics.items()} == {
        '/pentapod/tcp_state': 50, '/pentapod/excitation': 50}
    with open(bag / 'run1_0.mcap', 'rb') as stream:
        reader = make_reader(stream)
        assert reader.get_header().profile == 'ros2'
        summary = reader.get_summary()
        records = {m.name: m.metadata for m in reader.iter_metadata()}
    for channel in summary.channels.values():
        meta = topics[channel.topic]['topic_metadata']
        assert channel.message_encoding == 'cdr'
        assert summary.schemas[channel.schema_id].encoding == 'ros2msg'
        assert summary.schemas[channel.schema_id].name == meta['type']
        # the QoS trap: both places must parse equal
        assert yaml.safe_load(channel.metadata['offered_qos_profiles']) == \
            meta['offered_qos_profiles']
    assert topics['/pentapod/excitation']['topic_metadata']['offered_qos_profiles'][0][
        'reliability'] == 'best_effort'
    assert records['pentapod_run']['scenario'] == 'random'
    assert yaml.safe_load(records['rosbag2']['serialized_metadata'])['message_count'] == 100


def test_rosbags_and_mcap_ros2_read_our_bag(tmp_path):
    from mcap_ros2.decoder import DecoderFactory
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import get_typestore, Stores
    bag = tmp_path / 'run2'
    write_example(bag)
    with AnyReader([bag], default_typestore=get_typestore(Stores.ROS2_JAZZY)) as reader:
        rows = [(c.topic, t, reader.deserialize(raw, c.msgtype))
                for c, t, raw in reader.messages()]
    assert len(rows) == 100
    forces = [m.wrench.force.x for topic, _, m in rows if topic == '/pentapod/excitation']
    assert forces == [float(k) for k in range(50)]
    with open(bag / 'run2_0.mcap', 'rb') as stream:
        decoded = [(ch.topic, msg) for _, ch, _, msg in make_reader(
            stream, decoder_factories=[DecoderFactory()]).iter_decoded_messages()]
    positions = [m.position[0] for topic, m in decoded if topic == '/pentapod/tcp_state']
    assert_allclose(positions, np.arange(50) * 1e-6)


def test_flushed_but_unclosed_bag_is_readable(tmp_path):
    bag = tmp_path / 'live'
    writer = BagWriter(bag, flush_period_s=0.0)
    writer.add_topic('/clock', 'rosgraph_msgs/msg/Clock')
    for k in range(30):
        writer.write('/clock', encode_clock(k * 1000), k * 1000)
    writer.flush()
    snapshot = tmp_path / 'snapshot'  # what a SIGKILL right now would leave
    shutil.copytree(bag, snapshot)
    writer.close()
    with pytest.warns(UserWarning, match='ends early'):
        loaded = open_bag(snapshot)
    assert_allclose(loaded.series('/clock.clock').values, np.arange(30) * 1e-6)
    info = yaml.safe_load((snapshot / 'metadata.yaml').read_text())
    assert info['rosbag2_bagfile_information']['message_count'] == 30


def test_writer_errors_name_the_problem(tmp_path):
    (tmp_path / 'full').mkdir()
    (tmp_path / 'full' / 'x').write_text('x')
    with pytest.raises(BagError, match='not empty'):
        BagWriter(tmp_path / 'full')
    with BagWriter(tmp_path / 'ok') as writer:
        writer.add_topic('/a', 'rosgraph_msgs/msg/Clock')
        with pytest.raises(BagError, match="'/b'"):
            writer.write('/b', encode_clock(0), 0)
        with pytest.raises(BagError, match='already registered'):
            writer.add_topic('/a', 'sensor_msgs/msg/JointState')
    with pytest.raises(BagError, match='compression'):
        BagWriter(tmp_path / 'c', compression='gzip')


@pytest.mark.parametrize('compression', ['zstd', 'lz4'])
def test_compressed_chunks_round_trip(tmp_path, compression):
    with BagWriter(tmp_path / 'z', compression=compression) as writer:
        writer.add_topic('/pentapod/excitation', 'geometry_msgs/msg/WrenchStamped')
        for k in range(200):
            writer.write('/pentapod/excitation', encode_wrench_stamped(k, [0, 0, k]), k)
    with warnings.catch_warnings():
        warnings.simplefilter('error')
        values = open_bag(tmp_path / 'z').series('/pentapod/excitation.force.z').values
    assert_allclose(values, np.arange(200))
