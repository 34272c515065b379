"""
Live view end to end, checked against the bag of the same run.

A lockstep run (plant, exciter, damper, PMA) with a recorder and the live view in real
processes, and a Foxglove WebSocket client (``websockets``) subscribed to every channel; the
client's messages, decoded with the advertised schemas, are compared with the recorded ones.
"""
import math
import os
from pathlib import Path
import re
import signal
import subprocess
import sys
import time

import numpy as np
from numpy.testing import assert_allclose
import pytest

from fixtures.demo_model import demo_model
from fixtures.foxglove_client import decoder, FoxgloveClient
from pentapod_sim import interface
from pentapod_sim.analysis.bag_reader import open_bag
from pentapod_sim.live.layout import build_layout, message_paths
from pentapod_sim.live.status import STATUS_NAMES

RATE = 5000.0
STEPS = 2000
DISPLAY_RATE = 200.0                      # 5 ms windows of 25 steps
SPECTRUM_N = 1024
SOURCES = ['exciter', 'damper_tcp', 'pma']
DISPLAY_TOPICS = [interface.TCP_STATE, interface.STRUT_STATES, interface.PMA_MOUNT_STATE,
                  interface.EXCITATION, interface.PMA_STATE] + [interface.force_topic(s)
                                                               for s in SOURCES]


class Procs:
    """Node processes with logs; all stopped at the end."""

    def __init__(self, folder: Path):
        self.folder, self.procs = folder, {}
        self.env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST')

    def start(self, name: str, module: str, *params: str) -> subprocess.Popen:
        cmd = [sys.executable, '-m', module, '--ros-args', '-r', f'__node:={name}']
        for p in params:
            cmd += ['-p', p]
        log = open(self.folder / f'{name}.log', 'w')
        self.procs[name] = subprocess.Popen(cmd, env=self.env, stdout=log,
                                            stderr=subprocess.STDOUT)
        return self.procs[name]

    def log(self, name: str) -> str:
        return (self.folder / f'{name}.log').read_text()

    def stop(self, name: str) -> int:
        proc = self.procs[name]
        if proc.poll() is None:
            proc.send_signal(signal.SIGINT)
        try:
            return proc.wait(timeout=20)
        except subprocess.TimeoutExpired:
            proc.kill()
            return proc.wait()

    def close(self):
        for name in self.procs:
            self.stop(name)


def _port(procs: Procs, timeout: float = 60.0) -> int:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        found = re.search(r'server on ws://127\.0\.0\.1:(\d+)', procs.log('live_view'))
        if found:
            return int(found.group(1))
        assert procs.procs['live_view'].poll() is None, procs.log('live_view')
        time.sleep(0.1)
    raise TimeoutError(procs.log('live_view'))


def resolve(msg, path: str):
    """Value of a Foxglove message path below the topic (``.a.b[2]``, ``.data[:]``)."""
    value = msg
    for name, index in re.findall(r'\.(\w+)(?:\[([^\]]*)\])?', path):
        value = getattr(value, name)          # AttributeError: no such field
        if index == ':':
            value = list(value)
        elif index:
            value = value[int(index)] if int(index) < len(value) else None
    return value


def flat(msg) -> tuple[int, np.ndarray]:
    """(header stamp [ns], values) of a JointState (position, velocity, effort) or wrench."""
    stamp = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
    if hasattr(msg, 'wrench'):
        w = msg.wrench
        return stamp, np.array([w.force.x, w.force.y, w.force.z,
                                w.torque.x, w.torque.y, w.torque.z])
    return stamp, np.concatenate([np.asarray(msg.position, float),
                                  np.asarray(msg.velocity, float),
                                  np.asarray(msg.effort, float)])


def same(a, b) -> np.ndarray:
    return (a == b) | (np.isnan(a) & np.isnan(b))


@pytest.fixture(scope='module')
def run(tmp_path_factory):
    """One lockstep run seen by the live view (client messages) and by the recorder (bag)."""
    folder = tmp_path_factory.mktemp('live')
    model_file = demo_model(10, seed=5).save(folder / 'model.npz')
    procs = Procs(folder)
    try:
        procs.start('recorder', 'pentapod_sim.nodes.recorder_node', f'output_dir:={folder}',
                    'bag_name:=run', 'flush_period:=0.2', 'discovery_period:=0.1')
        procs.start('live_view', 'pentapod_sim.nodes.live_view_node', 'port:=0',
                    f'display_rate:={DISPLAY_RATE}', f'spectrum_samples:={SPECTRUM_N}',
                    'spectrum_period:=0.2', 'status_period:=0.2', 'discovery_period:=0.1')
        client = FoxgloveClient(f'ws://127.0.0.1:{_port(procs)}').start()
        procs.start('exciter', 'pentapod_sim.nodes.exciter_node', 'kind:=random',
                    'amplitude:=80.0', 'direction:=[1.0, 0.4, 0.2]', 'f_start:=5.0',
                    'f_end:=600.0', 'duration:=0.4', 'seed:=2', f'sample_rate:={RATE}',
                    'wait_for_subscribers:=[recorder]')
        procs.start('damper_tcp', 'pentapod_damper.nodes.damper_node',
                    "tcp_directions:=['x','y']", 'tcp_gain:=3000.0')
        procs.start('pma', 'pentapod_damper.nodes.pma_node', "directions:=['x','z']",
                    'proof_mass:=2.0', 'gain:=800.0', f'sample_rate:={RATE}',
                    'wait_for_subscribers:=[recorder]')
        client.wait_for_topics(DISPLAY_TOPICS, timeout=60.0)
        plant = procs.start('plant', 'pentapod_sim.nodes.plant_node',
                            f'model_file:={model_file}', f'steps:={STEPS}',
                            f'sample_rate:={RATE}', 'sources:=[' + ','.join(SOURCES) + ']',
                            'startup_timeout:=60.0',
                            'wait_for_subscribers:=[recorder, live_view]')
        assert plant.wait(timeout=180) == 0, procs.log('plant')
        time.sleep(2.0)                       # idle flush of the last windows, last status
        client.stop()
        stopped = 128 + signal.SIGINT              # a clean stop on SIGINT (shutdown.py)
        assert procs.stop('live_view') == stopped, procs.log('live_view')
        # the recorder ends by itself once it drained a finished run, else on the signal
        assert procs.stop('recorder') in (0, stopped), procs.log('recorder')
    finally:
        procs.close()
    channels = {c['topic']: c for c in client.channels.values()}
    decoded = {}
    for topic, channel in channels.items():
        decode = decoder(channel)
        decoded[topic] = [(t, decode(payload)) for t, payload in client.of_topic(topic)]
    return {'client': client, 'channels': channels, 'live': decoded,
            'bag': open_bag(folder / 'run'), 'log': procs.log('live_view')}


def bag_messages(bag, topic: str) -> list:
    data = bag.topic(topic)
    decode = decoder({'encoding': 'cdr', 'schemaEncoding': 'ros2msg',
                      'schemaName': data.msg_type, 'schema': data.schema_text})
    return [decode(p) for p in data.payloads]


def test_channels_carry_ros2msg_schemas_and_cdr(run):
    from pentapod_sim.recording.msgdefs import message_definition
    for topic in DISPLAY_TOPICS:
        channel = run['channels'][topic]
        assert channel['encoding'] == 'cdr' and channel['schemaEncoding'] == 'ros2msg'
        assert channel['schemaName'] == run['bag'].topic(topic).msg_type
        assert channel['schema'] == message_definition(channel['schemaName'])
    assert run['client'].server_info['capabilities'] == ['time']
    assert run['client'].times and max(run['client'].times) == (STEPS - 1) * 200_000


@pytest.mark.parametrize('topic', DISPLAY_TOPICS)
def test_envelopes_equal_the_recorded_extremes(run, topic):
    bag = [flat(m) for m in bag_messages(run['bag'], topic)]
    t_bag = np.array([t for t, _ in bag])
    v_bag = np.array([v for _, v in bag])
    assert len(t_bag) == STEPS and np.all(np.diff(t_bag) > 0)
    live = [(t, flat(m)) for t, m in run['live'][topic]]
    assert all(log_time == stamp for log_time, (stamp, _) in live)  # log time = sim time
    period = int(1e9 / DISPLAY_RATE)
    windows: dict[int, list] = {}
    for _, (stamp, values) in live:
        windows.setdefault(stamp // period, []).append((stamp, values))
    assert sorted(windows) == sorted(set(t_bag // period))   # every window shown
    assert len(live) <= 2 * len(windows) + 4 < len(t_bag) / 5
    for shown in windows.values():
        stamps = [s for s, _ in shown]
        rows = np.array([v for _, v in shown])
        inside = (t_bag >= min(stamps)) & (t_bag <= max(stamps))
        assert set(stamps) <= set(t_bag[inside].tolist())
        for col in range(v_bag.shape[1]):
            recorded = v_bag[inside, col]
            if np.all(np.isnan(recorded)):
                assert np.all(np.isnan(rows[:, col]))
                continue
            low, high = np.nanmin(recorded), np.nanmax(recorded)
            assert low in rows[:, col] and high in rows[:, col], (topic, col)
            assert np.all((rows[:, col] >= low) & (rows[:, col] <= high))
    first_live = run['live'][topic][0][1]
    first_bag = bag_messages(run['bag'], topic)[0]
    assert getattr(first_live, 'name', None) == getattr(first_bag, 'name', None)
    assert first_live.header.frame_id == first_bag.header.frame_id


def test_spectrum_equals_the_recorded_tcp_response(run):
    frequency = run['live'][interface.tcp_spectrum_topic('frequency')]
    x_live = run['live'][interface.tcp_spectrum_topic('tcp_x')]
    assert frequency and x_live
    t_end, last = x_live[-1]
    dt = 1 / RATE
    assert_allclose(frequency[-1][1].data, np.fft.rfftfreq(SPECTRUM_N, dt))
    series = run['bag'].series(f'{interface.TCP_STATE}.position.tcp_x')
    upto = series.time_ns <= t_end
    x = series.values[upto][-SPECTRUM_N:]
    assert series.time_ns[upto][-1] == t_end and len(x) == SPECTRUM_N
    w = 0.5 - 0.5 * np.cos(2 * np.pi * np.arange(SPECTRUM_N) / SPECTRUM_N)   # periodic Hann
    amplitude = 2 * np.abs(np.fft.rfft(w * (x - x.mean()))) / w.sum()
    amplitude[[0, -1]] /= 2
    assert_allclose(last.data, amplitude, rtol=1e-7, atol=1e-9 * amplitude.max())
    assert last.layout.dim[0].label == 'tcp_x_position_amplitude'


def test_run_status_follows_the_plant(run):
    status = [m for _, m in run['live'][interface.LIVE_STATUS]]
    assert list(status[-1].name) == list(STATUS_NAMES)
    final = dict(zip(STATUS_NAMES, status[-1].position))
    assert final['step'] == STEPS - 1
    assert final['sim_time'] == pytest.approx((STEPS - 1) / RATE)
    assert math.isnan(final['deadline_misses']) and math.isnan(final['rejected_messages'])
    assert final['dropped_by_live_view'] == 0
    rates = [dict(zip(STATUS_NAMES, m.position))['steps_per_second'] for m in status]
    assert any(r > 0 for r in rates if not math.isnan(r))


def test_layout_paths_resolve_live_and_in_the_bag(run):
    checked = 0
    for path in message_paths(build_layout()):
        topic, _, fields = path.partition('.')
        live = run['live'].get(topic)
        in_bag = topic in run['bag'].topics
        if not live and not in_bag:
            assert topic.startswith(interface.FORCE_PREFIX), path   # a source not in this run
            continue
        assert live, f'{path}: nothing served live'
        value = resolve(live[-1][1], '.' + fields if fields else '')
        if in_bag:
            recorded = resolve(bag_messages(run['bag'], topic)[-1], '.' + fields if fields
                               else '')
            assert (value is None) == (recorded is None), path
        checked += 1
    assert checked >= 20
