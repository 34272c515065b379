"""
The recorder node killed mid-run (SIGKILL): its bag is refused by rosbags, recovered, then read.

A lockstep run (plant, exciter, recorder as separate processes, DDS on localhost on the
session's domain) is recorded; the recorder is killed while the run goes on. rosbags refuses
the bag it leaves (no footer), ``recover_bag`` rewrites it, and rosbags and the mcap library
read the result: every message the recorder had flushed (metadata.yaml counts them at each
flush) is there, byte-identical to what the project's own reader recovers from the damaged
file, and the per-step topics hold every step up to the end of what was written.
"""
import signal
import time
import warnings

from mcap.reader import make_reader
import numpy as np
import pytest
import yaml

from fixtures.demo_model import demo_model
from fixtures.processes import NodeProcesses
from pentapod_sim.analysis.bag.reader import open_bag
from pentapod_sim.interface import CLOCK, EXCITATION, TCP_STATE
from pentapod_sim.recording.recover import recover_bag

pytestmark = [pytest.mark.ros]


def _listed(bag) -> dict:
    meta = yaml.safe_load((bag / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    return {e['topic_metadata']['name']: int(e['message_count'])
            for e in meta['topics_with_message_count']}


def _listed_or_empty(bag) -> dict:
    """The counts of metadata.yaml, or {} before the recorder wrote it (or mid-write)."""
    try:
        return _listed(bag)
    except (OSError, TypeError, KeyError, yaml.YAMLError):
        return {}


def test_a_killed_recorder_leaves_a_bag_that_recovery_makes_readable(tmp_path):
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import get_typestore, Stores
    model_file = demo_model(6, seed=3).save(tmp_path / 'model.npz')
    procs = NodeProcesses(tmp_path)
    try:
        recorder = procs.start('recorder', 'pentapod_sim.nodes.recorder_node',
                               f"output_dir:='{tmp_path}'", 'bag_name:=run',
                               'flush_period:=0.2')
        procs.start('exciter', 'pentapod_sim.nodes.exciter_node', 'kind:=random',
                    'amplitude:=20.0', 'duration:=1000.0', 'sample_rate:=2000.0')
        procs.start('plant', 'pentapod_sim.nodes.plant_node', f'model_file:={model_file}',
                    'steps:=2000000', 'sample_rate:=2000.0', 'sources:=[exciter]',
                    'wait_for_subscribers:=[recorder]', 'startup_timeout:=60.0')
        procs.wait_for('plant', 'lockstep run of')
        # a few flushes of the recorder, the last holding every per-step topic: under load
        # the recorder may discover the exciter's topic only after the run began
        end = time.monotonic() + 30
        while not (bag_listed := _listed_or_empty(tmp_path / 'run')).get(EXCITATION):
            assert time.monotonic() < end, bag_listed
            time.sleep(0.2)
        time.sleep(1.0)
        recorder.send_signal(signal.SIGKILL)       # mid-run, mid-chunk most likely
        assert procs.wait('recorder', 10) == -signal.SIGKILL
        time.sleep(0.5)
    finally:
        procs.close()
    bag = tmp_path / 'run'
    listed = _listed(bag)                          # the recorder's last flush
    assert listed[TCP_STATE] > 100, listed
    store = get_typestore(Stores.ROS2_JAZZY)
    with pytest.raises(Exception, match='magic'):  # the failure of issue 25
        with AnyReader([bag], default_typestore=store) as reader:
            list(reader.messages())
    with warnings.catch_warnings():
        warnings.simplefilter('ignore')
        damaged = open_bag(bag)                    # the project's reader tolerates the cut

    recovery = recover_bag(bag)
    out = recovery.output
    assert not recovery.intact and recovery.run is not None and recovery.run.state == 'running'
    with open(next(out.glob('*.mcap')), 'rb') as stream:
        reader = make_reader(stream)
        summary = reader.get_summary()
        got: dict = {}
        for _, channel, message in reader.iter_messages(log_time_order=False):
            got.setdefault(channel.topic, []).append((message.log_time, message.data))
    assert summary.statistics.message_count == sum(len(v) for v in got.values())
    with AnyReader([out], default_typestore=store) as reader:
        seen: dict = {}
        for connection, _, raw in reader.messages():
            seen[connection.topic] = seen.get(connection.topic, 0) + 1
            reader.deserialize(raw, connection.msgtype)
    assert seen == {t: len(v) for t, v in got.items()}
    for topic, count in listed.items():            # nothing flushed is lost
        assert len(got.get(topic, [])) >= count, (topic, recovery.describe())
    for topic in (TCP_STATE, CLOCK, EXCITATION):
        ours = damaged.topic(topic)
        assert [d for _, d in got[topic][:ours.count]] == [bytes(p) for p in ours.payloads]
        stamps = np.array([t for t, _ in got[topic]])
        assert np.all(np.diff(stamps) == 500_000), topic        # every step, 2 kHz, in order
        steps = recovery.topics[topic].steps
        assert steps is not None and not steps.exact
        assert all(gap[1] == steps.expected - 1 for gap in steps.gaps), steps  # only the end
    print(recovery.describe())
