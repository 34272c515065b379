"""
Recorder node end to end: a real rclpy publisher process -> recorder process -> bag files.

DDS runs on localhost on the ROS_DOMAIN_ID the test session reserved (conftest.py). The bag
is read back by rosbags (AnyReader, independent of our code) and by our reader.
"""
import os
from pathlib import Path
import signal
import subprocess
import sys
import time
import warnings

import numpy as np
from numpy.testing import assert_allclose
import pytest
import yaml

from pentapod_sim.analysis.bag.reader import open_bag

N_STEPS = 300
DT_NS = 1_000_000  # 1 ms sim-time step

PUBLISHER = r"""
import sys, time
import rclpy
from rclpy.qos import QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from geometry_msgs.msg import WrenchStamped
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
from pentapod_sim.nodes.common import qos as testbed_qos
from pentapod_sim.nodes.run_status import status_values
n, dt = int(sys.argv[1]), int(sys.argv[2])
rclpy.init()
node = rclpy.create_node('test_publisher')
# a run announced before its first step, as the plant does (else the states are foreign)
status = node.create_publisher(DiagnosticStatus, '/pentapod/run_status', testbed_qos('status'))
status.publish(DiagnosticStatus(name='/test_publisher', message='running', values=[
    KeyValue(key=k, value=v) for k, v in status_values('running', 0, dt * 1e-9, [], 0.0, 0,
                                                       0).items()]))
qos = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
pubs = [node.create_publisher(JointState, '/pentapod/tcp_state', qos),
        node.create_publisher(WrenchStamped, '/pentapod/excitation', qos),
        node.create_publisher(Clock, '/clock', qos),
        node.create_publisher(JointState, '/other/ignored', qos),
        node.create_publisher(JointState, '/pentapod/forces/best_effort',
                              qos_profile_sensor_data)]
deadline = time.monotonic() + 30
while any(p.get_subscription_count() == 0 for p in pubs[:3] + pubs[4:]):
    if time.monotonic() > deadline:
        sys.exit('recorder did not subscribe')
    rclpy.spin_once(node, timeout_sec=0.05)
time.sleep(0.3)
for k in range(n):
    t = k * dt
    js = JointState()
    js.header.stamp.sec, js.header.stamp.nanosec = divmod(t, 10**9)
    js.name = ['tcp_x', 'tcp_y', 'tcp_z']
    js.position = [1e-6 * k, -2e-6 * k, 0.5]
    js.velocity = [float(k), 0.0, -1.0]
    w = WrenchStamped()
    w.header.stamp = js.header.stamp
    w.wrench.force.x = 3.0 * k
    c = Clock()
    c.clock = js.header.stamp
    pubs[2].publish(c)
    pubs[0].publish(js)
    pubs[1].publish(w)
    pubs[3].publish(js)
    pubs[4].publish(js)
    time.sleep(0.002)
time.sleep(0.5)
node.destroy_node()
rclpy.shutdown()
"""


@pytest.fixture()
def ros_env():
    env = dict(os.environ)
    env['ROS_DOMAIN_ID'] = os.environ['ROS_DOMAIN_ID']   # the session's (conftest.py)
    env['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    return env


def start_recorder(env, out_dir: Path, name: str) -> subprocess.Popen:
    cmd = [sys.executable, '-m', 'pentapod_sim.nodes.recorder_node', '--ros-args',
           '-p', f'output_dir:={out_dir}', '-p', f'bag_name:={name}',
           '-p', 'discovery_period:=0.2', '-p', 'flush_period:=0.3',
           '-p', "run_info:='{model_hash: 0123abcd, scenario: random}'"]
    return subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            text=True)


def publish(env) -> None:
    done = subprocess.run([sys.executable, '-c', PUBLISHER, str(N_STEPS), str(DT_NS)],
                          env=env, capture_output=True, text=True, timeout=90)
    assert done.returncode == 0, done.stderr + done.stdout


def stop(proc: subprocess.Popen, sig: int) -> str:
    proc.send_signal(sig)
    out, _ = proc.communicate(timeout=30)
    return out


@pytest.mark.parametrize('sig', [signal.SIGINT, signal.SIGTERM])
def test_recorded_bag_is_read_by_rosbags_with_all_messages(tmp_path, ros_env, sig):
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import get_typestore, Stores
    recorder = start_recorder(ros_env, tmp_path, 'run')
    try:
        publish(ros_env)
    finally:
        log = stop(recorder, sig)
    assert recorder.returncode == 128 + sig, log   # pentapod_sim.shutdown: stopped by sig
    bag_dir = tmp_path / 'run'
    with AnyReader([bag_dir], default_typestore=get_typestore(Stores.ROS2_JAZZY)) as reader:
        types = {c.topic: c.msgtype for c in reader.connections}
        assert types == {'/pentapod/run_status': 'diagnostic_msgs/msg/DiagnosticStatus',
                         '/pentapod/tcp_state': 'sensor_msgs/msg/JointState',
                         '/pentapod/excitation': 'geometry_msgs/msg/WrenchStamped',
                         '/clock': 'rosgraph_msgs/msg/Clock',
                         '/pentapod/forces/best_effort': 'sensor_msgs/msg/JointState'}
        qos = {c.topic: c.ext.offered_qos_profiles[0].reliability.name
               for c in reader.connections}
        assert qos['/pentapod/forces/best_effort'] == 'BEST_EFFORT'
        assert qos['/pentapod/tcp_state'] == 'RELIABLE'
        seen = {topic: [] for topic in types}
        for conn, log_time, raw in reader.messages():
            seen[conn.topic].append((log_time, reader.deserialize(raw, conn.msgtype)))
    counts = {t: len(v) for t, v in seen.items()}
    assert 0 < counts.pop('/pentapod/forces/best_effort') <= N_STEPS  # best effort may drop
    assert counts.pop('/pentapod/run_status') == 1
    assert counts == {t: N_STEPS for t in types
                      if t not in ('/pentapod/forces/best_effort', '/pentapod/run_status')}
    states = sorted(seen['/pentapod/tcp_state'], key=lambda item: item[0])
    k = np.arange(N_STEPS)
    assert_allclose([s.position[0] for _, s in states], 1e-6 * k)
    assert_allclose([s.velocity[0] for _, s in states], k)
    assert [list(s.name) for _, s in states[:1]] == [['tcp_x', 'tcp_y', 'tcp_z']]
    # log time = header stamp (sim time), not the receive time
    assert [t for t, _ in states] == list(k * DT_NS)
    wrenches = sorted(seen['/pentapod/excitation'], key=lambda item: item[0])
    assert_allclose([w.wrench.force.x for _, w in wrenches], 3.0 * k)
    bag = open_bag(bag_dir)
    assert bag.custom_data['model_hash'] == '0123abcd'
    assert not bag.truncated


def test_sigkill_leaves_a_readable_bag(tmp_path, ros_env):
    recorder = start_recorder(ros_env, tmp_path, 'crash')
    try:
        publish(ros_env)
        time.sleep(1.0)  # > flush period: everything received is on disk
    finally:
        stop(recorder, signal.SIGKILL)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter('always')
        bag = open_bag(tmp_path / 'crash')
    assert bag.truncated
    assert any('ends early' in str(w.message) for w in caught)
    series = bag.series('/pentapod/tcp_state.position.tcp_y')
    assert len(series.values) == N_STEPS
    assert_allclose(series.values, -2e-6 * np.arange(N_STEPS))
    assert_allclose(series.time, np.arange(N_STEPS) * DT_NS * 1e-9)
    meta = yaml.safe_load((tmp_path / 'crash' / 'metadata.yaml').read_text())
    counts = {t['topic_metadata']['name']: t['message_count']
              for t in meta['rosbag2_bagfile_information']['topics_with_message_count']}
    assert counts['/pentapod/tcp_state'] == counts['/clock'] == N_STEPS  # last flush
