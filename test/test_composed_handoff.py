"""
The in-process hand-off of a composed run (pentapod_sim/nodes/local_bus.py).

A composed run (``python -m pentapod_sim.nodes.composed``) passes the plant's per-step messages
to its in-process sources and their answers back without DDS, and publishes on DDS only what an
outside subscriber takes. The runs here count every rclpy ``Publisher.publish`` call per topic
(a wrapper installed before the composition starts, independent of the hand-off's own
counters), compare the trace with the offline closed loop bit for bit, and check that a recorder
in the same composition (which takes the per-step topics from the hand-off too and serialises
them itself) records every step of every per-step topic, with the bytes a recorder in another
process gets over DDS, and records the plant's periodic run status *during* the run (the plant
loop no longer waits in the executor, so timers and in-process DDS deliveries depend on its
drains).
"""
import json
import os
from pathlib import Path
import signal
import subprocess
import sys
import time

from diagnostic_msgs.msg import DiagnosticStatus
import numpy as np
import pytest
from rclpy.serialization import deserialize_message
import yaml

from fixtures.demo_model import demo_model
from fixtures.processes import END_WATCHER
from pentapod_damper.scenario_laws import scenario_laws
from pentapod_sim import interface
from pentapod_sim.analysis.bag.reader import open_bag
from pentapod_sim.interface import force_topic
from pentapod_sim.scenario.files import dump_params, read_scenario
from pentapod_sim.sim.closed_loop import excitation_matrix, simulate
from pentapod_sim.sim.excitation import Excitation, ExcitationSpec
from pentapod_sim.sim.multirate import MultiRatePlant

pytestmark = [pytest.mark.ros, pytest.mark.slow]

ROOT = Path(__file__).resolve().parents[1]
RATE = 2000.0
TCP = ['tcp_force_x', 'tcp_force_y', 'tcp_force_z']
EXCITER = {'kind': 'random', 'amplitude': 20.0, 'direction': [1.0, 0.5, 0.0],
           'f_start': 5.0, 'f_end': 300.0, 'duration': 2.0, 'seed': 3}
SOURCES = ['exciter', 'damper', 'pma']
STEP_TOPICS = [interface.CLOCK, *interface.STATE_TOPICS, *map(force_topic, SOURCES)]
#: Per-step topics the hand-off carries: those, and the sources' diagnostics.
BUS_TOPICS = [*STEP_TOPICS, interface.EXCITATION, interface.PMA_STATE]

#: A composed run with every rclpy publish counted per topic (JSON file, argv[2]).
COUNTING = r"""
import json, sys
from rclpy.publisher import Publisher
from pentapod_sim.nodes import composed
counts = {}
publish = Publisher.publish
def counting(self, msg):
    counts[self.topic_name] = counts.get(self.topic_name, 0) + 1
    return publish(self, msg)
Publisher.publish = counting
code = composed.main(['composed', sys.argv[1]])
open(sys.argv[2], 'w').write(json.dumps(counts))
raise SystemExit(code)
"""


def _scenario(tmp_path: Path, steps: int, record: bool, wait_for_recorder: bool = False) -> Path:
    """
    Plant + exciter + TCP/strut damper + PMA (+ recorder), status every 0.05 s.

    ``wait_for_recorder``: no recorder in the scenario, but the plant waits for a node named
    ``recorder`` (one in another process).
    """
    model_file = demo_model(6, seed=4).save(tmp_path / 'model.npz')
    doc = {'/**': {'ros__parameters': {'sample_rate': RATE}},
           'exciter': {'ros__parameters': dict(EXCITER)},
           'damper': {'ros__parameters': {'tcp_directions': ['x', 'y'], 'tcp_gain': 2000.0,
                                          'bending_struts': [1], 'bending_gain': 100.0}},
           'pma': {'ros__parameters': {'directions': ['x'], 'proof_mass': 2.0,
                                       'gain': 1000.0}},
           'plant': {'ros__parameters': {
               'model_file': str(model_file), 'steps': steps, 'sources': SOURCES,
               'output_file': str(tmp_path / 'trace.npz'), 'startup_timeout': 60.0,
               'status_period': 0.05}}}
    if record:
        doc['recorder'] = {'ros__parameters': {'output_dir': str(tmp_path / 'bags'),
                                               'bag_name': 'run'}}
    if record or wait_for_recorder:
        doc['plant']['ros__parameters']['wait_for_subscribers'] = ['recorder']
    path = tmp_path / 'scenario.yaml'
    path.write_text(dump_params(doc))
    return path


def _composed(tmp_path: Path, path: Path, executor: str = 'events') -> tuple[dict, dict]:
    """Run the composition; return the trace and the publish count per topic."""
    counts = tmp_path / 'counts.json'
    proc = subprocess.run([sys.executable, '-c', COUNTING, str(path), str(counts)],
                          env=dict(os.environ, PENTAPOD_EXECUTOR=executor),
                          capture_output=True, text=True, timeout=300, cwd=ROOT)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return dict(np.load(tmp_path / 'trace.npz')), json.loads(counts.read_text())


def _assert_offline_loop(path: Path, run: dict, steps: int) -> None:
    """The trace is the offline closed loop's, bit for bit."""
    plant = MultiRatePlant.from_model(demo_model(6, seed=4), RATE, 1)
    laws = scenario_laws(read_scenario(path).sections, 1 / RATE)
    exc = Excitation(ExcitationSpec(**EXCITER), 1 / RATE).series(steps)
    ref = simulate(plant, laws, excitation_matrix(plant, TCP, exc, steps))
    assert int(run['steps_run']) == steps
    for port in ('tcp_force_x', 'pma_force_x', 'strut1_bending_moment_2'):
        if port in plant.input_index:
            assert np.any(ref.u[:, plant.input_index[port]]), port
    assert np.array_equal(run['u'], ref.u)
    assert np.array_equal(run['y'], ref.y)
    assert np.array_equal(run['x_final'], plant.x)


def _periodic(counts_or_values, wall: float, period: float = 0.05) -> None:
    """At least half the run-status periods of the run's wall time fired (at least 3)."""
    assert counts_or_values >= max(3, int(0.5 * wall / period)), (counts_or_values, wall)


@pytest.mark.parametrize('executor,steps', [('events', 20000), ('single', 3000)])
def test_composed_sources_take_the_plants_messages_without_dds(tmp_path, executor, steps):
    """
    No outside subscriber: no per-step message goes through DDS, the trace is the offline one.

    Without the hand-off every step publishes /clock (the exciter), the state topics (the
    damper, the PMA), three force topics, the excitation and the PMA state on DDS: so it does
    on rclpy's SingleThreadedExecutor (``PENTAPOD_EXECUTOR=single``), where the composition
    stays on DDS. The status timer keeps
    firing although the loop no longer waits in the executor.
    """
    path = _scenario(tmp_path, steps, record=False)
    run, counts = _composed(tmp_path, path, executor)
    dds = {t: counts.get(t, 0) for t in BUS_TOPICS}
    if executor == 'events':
        assert dds == dict.fromkeys(BUS_TOPICS, 0), counts
    else:
        assert all(n >= steps for n in dds.values()), counts
    # the counter sees what does go through DDS: each source's model, the run status
    for source in SOURCES:
        assert counts[interface.controller_model_topic(source)] >= 1, counts
    _periodic(counts[interface.RUN_STATUS] - 2, float(run['wall_time']))
    if executor == 'events':
        assert run['rejected'].size == 0, run['rejected']     # one answer per step
    else:
        # over DDS on a loaded machine the plant re-publishes a step after resend_period and
        # drops the late second answers as stale or duplicate, by design; nothing else
        assert [r for r in run['rejected'] if r.split('/')[1].split('=')[0]
                not in ('stale', 'duplicate')] == [], run['rejected']
    _assert_offline_loop(path, run, steps)


def test_a_recorder_in_the_composition_records_every_step(tmp_path):
    """
    A recorder in the composition takes the per-step topics in-process: no DDS publish of them.

    The bag holds every step of every per-step topic (stamps 0, dt, 2 dt, ... each once), its
    forces are the ones the plant applied (no copy reached the plant twice: nothing rejected),
    and the plant's periodic run status was recorded during the run, with progress between
    the messages.
    """
    steps = 4000
    path = _scenario(tmp_path, steps, record=True)
    run, counts = _composed(tmp_path, path, 'events')
    assert {t: counts.get(t, 0) for t in BUS_TOPICS} == dict.fromkeys(BUS_TOPICS, 0), counts
    assert run['rejected'].size == 0, run['rejected']
    _assert_offline_loop(path, run, steps)

    bag = open_bag(tmp_path / 'bags' / 'run')
    for topic in BUS_TOPICS:
        assert bag.topic(topic).count == steps, topic
    every_step = np.arange(steps) * round(1e9 / RATE)
    for topic in STEP_TOPICS:
        assert np.array_equal(bag.topic(topic).log_time_ns, every_step), topic
    names, inputs = list(run['output_names']), list(run['input_names'])
    assert np.array_equal(bag.series(f'{interface.TCP_STATE}.position.tcp_x').values,
                          run['y'][:, names.index('tcp_displacement_x')])
    assert np.array_equal(bag.series(f'{force_topic("pma")}.effort.pma_force_x').values,
                          run['u'][:, inputs.index('pma_force_x')])
    applied = sum(bag.series(f'{force_topic(s)}.effort.tcp_force_x').values
                  for s in ('exciter', 'damper'))
    assert np.array_equal(applied, run['u'][:, inputs.index('tcp_force_x')])

    status = [deserialize_message(p, DiagnosticStatus)
              for p in bag.topic(interface.RUN_STATUS).payloads]
    values = [{kv.key: kv.value for kv in m.values} for m in status]
    during = sorted({int(v['steps']) for v in values
                     if v['state'] == 'running' and 0 < int(v['steps']) < steps})
    _periodic(len(during), float(run['wall_time']))
    assert values[-1]['state'] == 'finished' and values[-1]['steps'] == str(steps)


def test_a_stop_signal_ends_a_composed_run_cleanly_with_everything_recorded(tmp_path):
    """
    SIGINT mid-run: the plant ends its step, saves its trace; the recorder keeps every step.

    The loop no longer waits in the executor, so the signal is seen between steps, and the
    recorder (in the composition) holds every step the plant ran on every per-step topic.
    """
    long = 2_000_000
    path = _scenario(tmp_path, long, record=True)
    log = tmp_path / 'composed.log'
    proc = subprocess.Popen([sys.executable, '-m', 'pentapod_sim.nodes.composed', str(path)],
                            stdout=open(log, 'w'), stderr=subprocess.STDOUT,
                            env=dict(os.environ, PYTHONUNBUFFERED='1', PENTAPOD_EXECUTOR='events',
                                     RCUTILS_LOGGING_BUFFERED_STREAM='0'),
                            start_new_session=True, cwd=ROOT)
    try:
        end = time.monotonic() + 120
        while 'lockstep run of' not in log.read_text():
            assert proc.poll() is None and time.monotonic() < end, log.read_text()
            time.sleep(0.1)
        time.sleep(1.5)
        proc.send_signal(signal.SIGINT)
        assert proc.wait(timeout=60) == 128 + signal.SIGINT, log.read_text()
    finally:
        if proc.poll() is None:
            proc.kill()
    out = log.read_text()
    assert 'Traceback' not in out and 'stopped by SIGINT: ran ' in out, out
    run = np.load(tmp_path / 'trace.npz')
    n = int(run['steps_run'])
    assert 0 < n < long and str(run['end']) == 'stopped by SIGINT'
    bag = open_bag(tmp_path / 'bags' / 'run')
    for topic in STEP_TOPICS:
        assert bag.topic(topic).count == n, (topic, n)


def _bag_bytes(folder: Path) -> dict:
    """Per topic: channel type, schema, and the CDR bytes of each message by log time."""
    bag = open_bag(folder)
    out = {}
    for name, data in bag.topics.items():
        order = np.argsort(data.log_time_ns, kind='stable')
        payloads = [bytes(p) for p in data.payloads]
        out[name] = (data.msg_type, data.schema_text, [payloads[i] for i in order],
                     data.log_time_ns[order].tolist())
    return out


def test_the_in_process_recorder_writes_the_bytes_dds_delivers(tmp_path):
    """
    The bag of the in-process recorder equals that of a recorder in another process (DDS).

    The same composed run is recorded twice: once by a recorder in the composition (bus path,
    nothing published on DDS), once without it by a recorder process (the plant's outlets
    then publish on DDS). Per topic the type, schema, message bytes and log times are the
    same, step by step, and every per-step topic holds every step.
    """
    steps = 3000
    inside = tmp_path / 'inside'
    outside = tmp_path / 'outside'
    inside.mkdir()
    outside.mkdir()
    _, counts = _composed(inside, _scenario(inside, steps, record=True), 'events')
    assert {t: counts.get(t, 0) for t in BUS_TOPICS} == dict.fromkeys(BUS_TOPICS, 0)

    recorder = subprocess.Popen(
        [sys.executable, '-m', 'pentapod_sim.nodes.recorder_node', '--ros-args',
         '-p', f'output_dir:={outside / "bags"}', '-p', 'bag_name:=run',
         '-p', 'discovery_period:=0.1'],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, cwd=ROOT)
    try:
        _, counts = _composed(outside, _scenario(outside, steps, record=False,
                                                 wait_for_recorder=True), 'events')
        out, _ = recorder.communicate(timeout=120)
    finally:
        if recorder.poll() is None:
            recorder.kill()
    assert recorder.returncode == 0, out
    assert 'none missing' in out, out
    assert all(counts[t] >= steps for t in BUS_TOPICS), counts      # DDS carried them

    dds, bus = _bag_bytes(outside / 'bags' / 'run'), _bag_bytes(inside / 'bags' / 'run')
    stamps = (np.arange(steps) * round(1e9 / RATE)).tolist()
    for topic in BUS_TOPICS:
        assert bus[topic][3] == stamps, topic
        assert bus[topic][:2] == dds[topic][:2], topic
        assert len(bus[topic][2]) == len(dds[topic][2]) == steps, topic
        differ = [k for k, (a, b) in enumerate(zip(bus[topic][2], dds[topic][2])) if a != b]
        assert not differ, (topic, differ[:5])
    # the forces in the bag are the DDS bytes of what the plant applied: not all zero
    assert len(set(bus[force_topic('damper')][2])) > steps // 2


#: A DDS subscriber of one topic in its own process (a live view, ``ros2 topic echo``).
ECHO = r"""
import sys
import rclpy
from sensor_msgs.msg import JointState
from pentapod_sim.nodes.common import STATE_QOS
rclpy.init()
node = rclpy.create_node('echo')
node.create_subscription(JointState, sys.argv[1], lambda msg: None, STATE_QOS)
print('ready', flush=True)
try:
    rclpy.spin(node)
except BaseException as err:
    print('ended', repr(err), flush=True)
"""


def test_an_outside_subscriber_still_gets_its_topic_over_dds(tmp_path):
    """
    Another process subscribed to one state topic gets it over DDS, the other topics stay off.

    The recorder in the composition does not count as a DDS subscriber of the topics it takes
    from the bus; it ignores the DDS copies it also receives and records every step once.
    """
    steps = 3000
    echo = subprocess.Popen([sys.executable, '-c', ECHO, interface.TCP_STATE],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            cwd=ROOT)
    try:
        assert echo.stdout.readline().strip() == 'ready'
        path = _scenario(tmp_path, steps, record=True)
        doc = yaml.safe_load(path.read_text())
        doc['plant']['ros__parameters']['wait_for_subscribers'].append('echo')  # discovered
        path.write_text(dump_params(doc))
        _, counts = _composed(tmp_path, path, 'events')
    finally:
        echo.kill()
        echo.wait()
    assert counts.get(interface.TCP_STATE, 0) > 0, counts
    others = [t for t in STEP_TOPICS if t != interface.TCP_STATE]
    assert {t: counts.get(t, 0) for t in others} == dict.fromkeys(others, 0), counts
    bag = open_bag(tmp_path / 'bags' / 'run')
    every_step = np.arange(steps) * round(1e9 / RATE)
    for topic in STEP_TOPICS:
        assert np.array_equal(bag.topic(topic).log_time_ns, every_step), topic


#: Counts the messages of one force topic (reliable, as a recorder), then prints the count once
#: none came for 3 s.
COUNTER = r"""
import sys, time
import rclpy
from sensor_msgs.msg import JointState
from pentapod_sim.nodes.common import FORCE_QOS
rclpy.init()
node = rclpy.create_node('echo')
got = []
node.create_subscription(JointState, sys.argv[1], lambda msg: got.append(time.monotonic()),
                         FORCE_QOS)
print('ready', flush=True)
while not got or time.monotonic() - got[-1] < 3.0:
    rclpy.spin_once(node, timeout_sec=0.1)
print(len(got), flush=True)
"""


def test_a_composition_ends_once_its_sources_messages_are_acknowledged(tmp_path):
    """
    A subscriber outside a composition that only takes a source's topic gets every step.

    The composition's sources publish on DDS while someone outside subscribes, and their
    messages, like the plant's, must be acknowledged before the process ends: a recorder
    behind the run repairs what it lost from the writers' histories, which end with the
    process. The subscriber here takes only the PMA's forces and is frozen for the whole run
    (its socket holds far fewer than the run's 3000 messages); it is continued after the plant
    finished. Without the wait the composition ended as soon as the plant's own topics were
    acknowledged (none has a subscriber outside), and the subscriber lacked most steps.
    """
    steps = 3000
    counter = subprocess.Popen([sys.executable, '-c', COUNTER, force_topic('pma')],
                               stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                               cwd=ROOT)
    composed = None
    try:
        assert counter.stdout.readline().strip() == 'ready'
        path = _scenario(tmp_path, steps, record=False)
        doc = yaml.safe_load(path.read_text())
        doc['plant']['ros__parameters']['wait_for_subscribers'] = ['echo']
        path.write_text(dump_params(doc))
        log = tmp_path / 'composed.log'
        composed = subprocess.Popen(
            [sys.executable, '-m', 'pentapod_sim.nodes.composed', str(path)], cwd=ROOT,
            stdout=open(log, 'w'), stderr=subprocess.STDOUT)  # noqa: SIM115
        end = time.monotonic() + 120
        while 'lockstep run of' not in log.read_text():
            assert time.monotonic() < end and composed.poll() is None, log.read_text()
            time.sleep(0.01)
        counter.send_signal(signal.SIGSTOP)
        # the plant announced the end (it logs its summary only after the acknowledgements)
        subprocess.run([sys.executable, '-c', END_WATCHER], timeout=120, check=True, cwd=ROOT)
        time.sleep(1.0)
        # the race is on: the run is over and the subscriber has taken (almost) nothing
        assert composed.poll() is None, ('the composition ended before the subscriber '
                                         'acknowledged its messages', log.read_text())
        counter.send_signal(signal.SIGCONT)
        out, _ = counter.communicate(timeout=120)
        assert composed.wait(timeout=60) == 0, log.read_text()
    finally:
        for proc in (counter, composed):
            if proc is not None and proc.poll() is None:
                proc.send_signal(signal.SIGCONT)
                proc.kill()
                proc.wait()
    assert int(out.split()[-1]) == steps, out
