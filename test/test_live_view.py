"""
Live view end to end, checked against the bag of the same run.

A lockstep run (plant, exciter, damper, PMA) with a recorder and the live view in real
processes, and a Foxglove WebSocket client (``websockets``) subscribed to every channel; the
client's messages, decoded with the advertised schemas, are compared with the recorded ones.
The run happens under CPU load (one busy process per core besides the nodes): the live view's
best-effort subscriptions and the WebSocket may then lose display messages, so every message
that arrived is matched against the bag exactly (by stamp), a minimum share must arrive, and
the extremes of a window are required to be the recorded ones where the window provably
arrived whole (the view lost nothing and both of its messages carry the window's first and
last recorded stamps).
"""
import contextlib
import math
import os
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
from fixtures.processes import NodeProcesses
from pentapod_sim import interface
from pentapod_sim.analysis.bag.reader import open_bag
from pentapod_sim.live.layout import build_layout, message_paths
from pentapod_sim.live.status import STATUS_NAMES
from pentapod_sim.scenario.files import dump_params

RATE = 5000.0
STEPS = 2000
DISPLAY_RATE = 200.0                      # 5 ms windows of 25 steps
SPECTRUM_N = 1024
SOURCES = ['exciter', 'damper_tcp', 'pma']
#: Live views of the run: node name -> (extra parameters, share of the display windows that
#: must arrive). The starved one polls every 0.5 s into 40-message histories, so it loses
#: messages of the per-step topics (excitation, PMA state) for sure; the plant's display
#: batches (50 steps each) fit.
VIEWS = {'live_view': ((), 0.5),
         'starved_view': (('queue_depth:=40', 'tick_period:=0.5'), 0.02)}
MIN_SHOWN = VIEWS['live_view'][1]
BURNERS = os.cpu_count() or 2             # busy processes during the run
BURN = 'import time\nend = time.monotonic() + 600\nwhile time.monotonic() < end:\n    pass\n'
DISPLAY_TOPICS = [interface.TCP_STATE, interface.STRUT_STATES, interface.PMA_MOUNT_STATE,
                  interface.EXCITATION, interface.PMA_STATE] + [interface.force_topic(s)
                                                               for s in SOURCES]


def _port(procs: NodeProcesses, name: str = 'live_view', timeout: float = 60.0) -> int:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        found = re.search(r'server on ws://127\.0\.0\.1:(\d+)', procs.log(name))
        if found:
            return int(found.group(1))
        assert procs.procs[name].poll() is None, procs.log(name)
        time.sleep(0.1)
    raise TimeoutError(procs.log(name))


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


@pytest.fixture(scope='module')
def run(tmp_path_factory):
    """One lockstep run seen by the live view (client messages) and by the recorder (bag)."""
    folder = tmp_path_factory.mktemp('live')
    model_file = demo_model(10, seed=5).save(folder / 'model.npz')
    procs = NodeProcesses(folder)
    try:
        procs.start('recorder', 'pentapod_sim.nodes.recorder_node', f'output_dir:={folder}',
                    'bag_name:=run', 'flush_period:=0.2', 'discovery_period:=0.1')
        clients = {}
        for name, (params, _) in VIEWS.items():
            procs.start(name, 'pentapod_sim.nodes.live_view_node', 'port:=0',
                        f'display_rate:={DISPLAY_RATE}', f'spectrum_samples:={SPECTRUM_N}',
                        'spectrum_period:=0.2', 'status_period:=0.2', 'discovery_period:=0.1',
                        *params)
            clients[name] = FoxgloveClient(f'ws://127.0.0.1:{_port(procs, name)}').start()
        procs.start('exciter', 'pentapod_sim.nodes.exciter_node', 'kind:=random',
                    'amplitude:=80.0', 'direction:=[1.0, 0.4, 0.2]', 'f_start:=5.0',
                    'f_end:=600.0', 'duration:=0.4', 'seed:=2', f'sample_rate:={RATE}',
                    'wait_for_subscribers:=[recorder]')
        procs.start('damper_tcp', 'pentapod_damper.nodes.damper_node',
                    "tcp_directions:=['x','y']", 'tcp_gain:=3000.0')
        procs.start('pma', 'pentapod_damper.nodes.pma_node', "directions:=['x','z']",
                    'proof_mass:=2.0', 'gain:=800.0', f'sample_rate:={RATE}',
                    'wait_for_subscribers:=[recorder]')
        for client in clients.values():
            client.wait_for_topics(DISPLAY_TOPICS, timeout=60.0)
        burners = [subprocess.Popen([sys.executable, '-c', BURN]) for _ in range(BURNERS)]
        try:
            plant = procs.start('plant', 'pentapod_sim.nodes.plant_node',
                                f'model_file:={model_file}', f'steps:={STEPS}',
                                f'sample_rate:={RATE}', 'sources:=[' + ','.join(SOURCES) + ']',
                                'startup_timeout:=60.0',
                                'wait_for_subscribers:=[recorder, ' + ', '.join(VIEWS) + ']')
            assert plant.wait(timeout=300) == 0, procs.log('plant')
        finally:
            for burner in burners:
                burner.kill()
                burner.wait()
        time.sleep(2.0)                       # idle flush of the last windows, last status
        stopped = 128 + signal.SIGINT              # a clean stop on SIGINT (shutdown.py)
        for name, client in clients.items():
            client.stop()
            assert procs.stop(name) == stopped, procs.log(name)
        # the recorder ends by itself once it drained a finished run, else on the signal
        assert procs.stop('recorder') in (0, stopped), procs.log('recorder')
    finally:
        procs.close()
    views = {}
    for name, client in clients.items():
        channels = {c['topic']: c for c in client.channels.values()}
        decoded = {}
        for topic, channel in channels.items():
            decode = decoder(channel)
            decoded[topic] = [(t, decode(payload)) for t, payload in client.of_topic(topic)]
        final = dict(zip(STATUS_NAMES, decoded[interface.LIVE_STATUS][-1][1].position))
        views[name] = {'client': client, 'channels': channels, 'live': decoded,
                       'status': final, 'min_shown': VIEWS[name][1]}
    bag = open_bag(folder / 'run')
    return {'bag': bag, **views['live_view'], 'views': views}


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


@pytest.mark.parametrize('view', VIEWS)
@pytest.mark.parametrize('topic', DISPLAY_TOPICS)
def test_envelopes_are_the_recorded_extremes(run, topic, view):
    seen = run['views'][view]
    bag = [flat(m) for m in bag_messages(run['bag'], topic)]
    t_bag = np.array([t for t, _ in bag])
    v_bag = np.array([v for _, v in bag])
    assert len(t_bag) == STEPS and np.all(np.diff(t_bag) > 0)
    row_of = {int(t): k for k, t in enumerate(t_bag)}
    live = [(t, flat(m)) for t, m in seen['live'][topic]]
    assert all(log_time == stamp for log_time, (stamp, _) in live)  # log time = sim time
    assert all(stamp in row_of for _, (stamp, _) in live)           # every stamp a recorded step
    period = int(1e9 / DISPLAY_RATE)
    windows: dict[int, list] = {}
    for _, (stamp, values) in live:
        windows.setdefault(stamp // period, []).append((stamp, values))
    recorded_windows = set((t_bag // period).tolist())
    assert set(windows) <= recorded_windows
    assert len(windows) >= seen['min_shown'] * len(recorded_windows), \
        (len(windows), seen['status'])
    assert len(live) <= 2 * len(windows) + 4 < len(t_bag) / 5
    whole = 0
    for w, shown in windows.items():
        stamps = [s for s, _ in shown]
        rows = np.array([v for _, v in shown])
        span = (t_bag >= min(stamps)) & (t_bag <= max(stamps))
        in_window = np.flatnonzero(t_bag // period == w)
        arrived_whole = (seen['status']['dropped_by_live_view'] == 0 and len(shown) == 2
                         and stamps == [t_bag[in_window[0]], t_bag[in_window[-1]]])
        whole += arrived_whole
        for col in range(v_bag.shape[1]):
            recorded = v_bag[span, col]
            if np.all(np.isnan(recorded)):
                assert np.all(np.isnan(rows[:, col]))
                continue
            # every value shown is a value recorded between the window's shown stamps
            assert set(rows[:, col].tolist()) <= set(recorded.tolist()), (topic, col)
            if arrived_whole:
                low, high = np.nanmin(recorded), np.nanmax(recorded)
                assert sorted(rows[:, col]) == [low, high], (topic, col)
    if seen['status']['dropped_by_live_view'] == 0:
        assert whole >= seen['min_shown'] * len(recorded_windows), (whole, len(recorded_windows))
    first_live = seen['live'][topic][0][1]
    first_bag = bag_messages(run['bag'], topic)[0]
    assert getattr(first_live, 'name', None) == getattr(first_bag, 'name', None)
    assert first_live.header.frame_id == first_bag.header.frame_id


def recorded_spectrum(bag, t_end: int) -> np.ndarray:
    """Amplitude spectrum of the SPECTRUM_N recorded TCP x samples up to ``t_end``."""
    series = bag.series(f'{interface.TCP_STATE}.position.tcp_x')
    upto = series.time_ns <= t_end
    x = series.values[upto][-SPECTRUM_N:]
    assert series.time_ns[upto][-1] == t_end and len(x) == SPECTRUM_N
    w = 0.5 - 0.5 * np.cos(2 * np.pi * np.arange(SPECTRUM_N) / SPECTRUM_N)   # periodic Hann
    amplitude = 2 * np.abs(np.fft.rfft(w * (x - x.mean()))) / w.sum()
    amplitude[[0, -1]] /= 2
    return amplitude


@pytest.mark.parametrize('view', VIEWS)
def test_spectrum_equals_the_recorded_tcp_response(run, view):
    seen = run['views'][view]
    frequency = seen['live'][interface.tcp_spectrum_topic('frequency')]
    x_live = seen['live'][interface.tcp_spectrum_topic('tcp_x')]
    assert frequency and x_live
    for _, f in frequency:
        assert_allclose(f.data, np.fft.rfftfreq(SPECTRUM_N, 1 / RATE))
    equal = []
    for t_end, spectrum in x_live:
        assert spectrum.layout.dim[0].label == 'tcp_x_position_amplitude'
        expected = recorded_spectrum(run['bag'], t_end)
        equal.append(np.allclose(spectrum.data, expected, rtol=1e-7,
                                 atol=1e-9 * expected.max()))
    # a spectrum may differ only where the view lost samples (it interpolates them)
    if seen['status']['dropped_by_live_view'] == 0:
        assert all(equal), (equal, seen['status'])


@pytest.mark.parametrize('view', VIEWS)
def test_run_status_passes_the_plant_status_through(run, view):
    seen = run['views'][view]
    status = [m for _, m in seen['live'][interface.LIVE_STATUS]]
    assert list(status[-1].name) == list(STATUS_NAMES)
    final = seen['status']
    recorded = bag_messages(run['bag'], interface.RUN_STATUS)
    last = {kv.key: kv.value for kv in recorded[-1].values}
    assert last['state'] == 'finished' and int(last['steps']) == STEPS
    assert final['step'] == STEPS - 1
    assert final['sim_time'] == pytest.approx((STEPS - 1) / RATE)
    assert final['steps_per_second'] == float(last['step_rate'])
    assert final['deadline_misses'] == 0 == int(last['deadline_misses'])    # lockstep
    # passed through; under the test's CPU load the plant may reject stale copies of answers
    # to a re-published step (by design), so the count need not be 0
    assert final['rejected_messages'] == int(last['rejected_messages'])
    # the plant's run-status messages are forwarded as they were recorded, byte for byte
    forwarded = [payload for _, payload in seen['client'].of_topic(interface.RUN_STATUS)]
    in_bag = {bytes(p) for p in run['bag'].topic(interface.RUN_STATUS).payloads}
    assert forwarded and set(forwarded) <= in_bag
    assert forwarded[-1] == bytes(run['bag'].topic(interface.RUN_STATUS).payloads[-1])
    if view == 'starved_view':
        assert final['dropped_by_live_view'] > 0          # the losses the test is about
    print(f'{view} under load: status {final}')


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


@contextlib.contextmanager
def _status_and_view(tmp_path, values: dict):
    """
    A fake plant that has published one run status with ``values``, and a live view.

    Yields ``(publish, url)``: ``publish()`` sends the same status again; ``url`` is the view's
    Foxglove server. Everything is shut down on leaving.
    """
    from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
    import rclpy
    from rclpy.node import Node

    from pentapod_sim.nodes.common import qos
    procs = NodeProcesses(tmp_path)
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=int(os.environ['ROS_DOMAIN_ID']))
    node = Node('fake_plant', context=ctx)
    try:
        pub = node.create_publisher(DiagnosticStatus, interface.RUN_STATUS, qos('status'))
        status = DiagnosticStatus(name='/plant', message=values['state'], values=[
            KeyValue(key=k, value=v) for k, v in values.items()])
        pub.publish(status)
        procs.start('live_view', 'pentapod_sim.nodes.live_view_node', 'port:=0',
                    'status_period:=0.1')
        yield (lambda: pub.publish(status)), f'ws://127.0.0.1:{_port(procs)}'
    finally:
        procs.close()
        node.destroy_node()
        rclpy.try_shutdown(context=ctx)


def _shows_misses(client, misses: int) -> bool:
    """True once the client got a live status with ``misses`` deadline misses."""
    return any(dict(zip(STATUS_NAMES, m.position))['deadline_misses'] == misses
               for m in _decoded(client, interface.LIVE_STATUS))


def test_run_status_figures_of_a_published_status(tmp_path):
    """A run-status message (no plant, no state topics) reaches the status channel as is."""
    values = {'state': 'running', 'steps': '1234', 'dt': '0.0002', 'last_stamp_ns': '246600000',
              'step_topics': '/clock', 'step_rate': '567.5', 'deadline_misses': '7',
              'rejected_messages': '3'}
    with _status_and_view(tmp_path, values) as (publish, url):
        client = FoxgloveClient(url).start()
        client.wait_for_topics([interface.RUN_STATUS, interface.LIVE_STATUS], timeout=60.0)
        end = time.monotonic() + 60.0
        while time.monotonic() < end and not (
                client.of_topic(interface.RUN_STATUS) and _shows_misses(client, 7)):
            publish()                    # as a plant does every status_period
            time.sleep(0.5)
        client.stop()
    forwarded = _decoded(client, interface.RUN_STATUS)
    assert {kv.key: kv.value for kv in forwarded[-1].values} == values
    assert client.of_topic(interface.RUN_STATUS)[-1][0] == 246600000       # log time
    shown = [dict(zip(STATUS_NAMES, m.position)) for m in _decoded(client, interface.LIVE_STATUS)]
    last = shown[-1]
    assert (last['step'], last['steps_per_second']) == (1233, 567.5)
    assert (last['deadline_misses'], last['rejected_messages']) == (7, 3)
    assert math.isnan(last['sim_time']) and last['dropped_by_live_view'] == 0


def test_a_client_that_comes_after_the_last_run_status_still_gets_it(tmp_path):
    """
    The run status is kept for late clients, as foxglove_bridge does for transient-local topics.

    A finished run publishes its last status once. The race is made to happen: a first
    client waits until the view has taken that status in (the live status shows its
    figures) and leaves; a second client connects afterwards and must still get the status.
    """
    values = {'state': 'finished', 'steps': '4000', 'dt': '0.0002',
              'last_stamp_ns': '799800000', 'step_topics': '/clock', 'step_rate': '812.0',
              'deadline_misses': '11', 'rejected_messages': '0'}
    with _status_and_view(tmp_path, values) as (_, url):     # published once
        first = FoxgloveClient(url).start()
        end = time.monotonic() + 60.0
        while time.monotonic() < end and not _shows_misses(first, 11):
            time.sleep(0.1)
        first.stop()
        assert _shows_misses(first, 11), 'status never taken in'
        time.sleep(0.5)                       # the view's passes see nobody watching
        late = FoxgloveClient(url).start()
        late.wait_for_topics([interface.RUN_STATUS], timeout=60.0)
        end = time.monotonic() + 30.0
        while time.monotonic() < end and not late.of_topic(interface.RUN_STATUS):
            time.sleep(0.1)
        late.stop()
    forwarded = _decoded(late, interface.RUN_STATUS)
    assert forwarded, 'the late client got no run status'
    assert {kv.key: kv.value for kv in forwarded[-1].values} == values
    assert late.of_topic(interface.RUN_STATUS)[-1][0] == 799800000       # same log time


def _decoded(client, topic: str) -> list:
    if topic not in client.topic_ids():
        return []
    decode = decoder(client.channels[client.topic_ids()[topic]])
    return [decode(payload) for _, payload in client.of_topic(topic)]


def test_a_composed_run_serves_the_live_view(tmp_path):
    """A live_view section of a composed run starts its server and streams the run."""
    model_file = demo_model(6, seed=5).save(tmp_path / 'model.npz')
    path = tmp_path / 'scenario.yaml'
    path.write_text(dump_params({
        '/**': {'ros__parameters': {'sample_rate': 1000.0}},
        'plant': {'ros__parameters': {'model_file': str(model_file), 'steps': 2_000_000,
                                      'sources': ['exciter'], 'loop_check': 'off'}},
        'exciter': {'ros__parameters': {'kind': 'sine', 'amplitude': 10.0, 'frequency': 7.0}},
        'live_view': {'ros__parameters': {'port': 0, 'discovery_period': 0.1}}}))
    log = tmp_path / 'composed.log'
    proc = subprocess.Popen([sys.executable, '-m', 'pentapod_sim.nodes.composed', str(path)],
                            stdout=open(log, 'w'), stderr=subprocess.STDOUT)
    try:
        end = time.monotonic() + 60.0
        while not (found := re.search(r'server on ws://127\.0\.0\.1:(\d+)', log.read_text())):
            assert proc.poll() is None and time.monotonic() < end, log.read_text()
            time.sleep(0.1)
        client = FoxgloveClient(f'ws://127.0.0.1:{found.group(1)}').start()
        client.wait_for_topics([interface.TCP_STATE], timeout=60.0)
        end = time.monotonic() + 60.0
        while len(client.of_topic(interface.TCP_STATE)) < 3 and time.monotonic() < end:
            time.sleep(0.1)
        client.stop()
        assert len(client.of_topic(interface.TCP_STATE)) >= 3
        proc.send_signal(signal.SIGINT)
        assert proc.wait(timeout=60) == 130, log.read_text()
        assert 'Traceback' not in log.read_text()
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
