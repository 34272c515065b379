"""
Lossless recording: a stalled recorder loses nothing and stops at the announced end of the run.

A real lockstep plant with an exciter and a recorder, each its own process on the session's
ROS domain (conftest.py). The recorder is frozen with SIGSTOP/SIGCONT while the plant runs; the
bag is then counted with the mcap library (independent of our writer's counters) and compared
with the number of steps the plant ran (its log) and the depths of pentapod_sim.interface.
"""
import os
from pathlib import Path
import re
import signal
import subprocess
import sys
import time

from mcap.reader import make_reader
import pytest
import yaml

from fixtures.processes import END_WATCHER
from pentapod_sim import interface
from pentapod_sim.errors import BagError
from pentapod_sim.recording.run_end import RunStatus, shortfalls, StepLedger
from pentapod_sim.scenario.files import read_scenario

ROOT = Path(__file__).resolve().parents[1]
OLD_FORCE_DEPTH = 100   # force history before this change: a 1.5 s stall lost messages
SCENARIO = """
/**:
  ros__parameters:
    sample_rate: 5000.0
plant:
  ros__parameters:
    position: P2
    timing: lockstep
    steps: {steps}
    sources: [exciter]
    wait_for_subscribers: [recorder]
exciter:
  ros__parameters:
    kind: random
    amplitude: 10.0
    duration: 4.0
recorder:
  ros__parameters:
    output_dir: {out}
    bag_name: bag
    flush_period: 0.2
    drain_timeout: 60.0
"""


# --- ROS-free -----------------------------------------------------------------------------

def test_history_covers_a_five_second_stall_at_every_shipped_rate():
    rates = [yaml.safe_load(p.read_text())['/**']['ros__parameters']['sample_rate']
             for p in sorted((ROOT / 'config' / 'scenarios').glob('*.yaml'))]
    rates.append(yaml.safe_load((ROOT / 'config' / 'study.yaml').read_text())['sample_rate'])
    assert max(rates) <= interface.MAX_SHIPPED_RATE
    for kind in ('state', 'force', 'info'):
        assert interface.QOS[kind].depth >= 5.0 * max(rates) + 3.0 * max(rates)
    assert interface.QOS['status'].durability == 'transient_local'


@pytest.mark.parametrize('path', sorted((ROOT / 'config' / 'scenarios').glob('*.yaml')),
                         ids=lambda p: p.stem)
def test_every_shipped_scenario_records_every_step(path):
    scenario = read_scenario(path)
    (recorder,) = scenario.of_kind('recorder')
    params = scenario.sections[recorder.name]
    assert (params['output_dir'], params['bag_name']) == ('out/bags', f'{path.stem}-{{utc}}')
    assert params.get('stop_at_run_end', True)
    (plant,) = scenario.of_kind('plant')
    assert recorder.name in scenario.sections[plant.name]['wait_for_subscribers']


def test_run_status_parsing_and_ledger():
    values = {'state': 'finished', 'steps': '3', 'dt': '0.001', 'last_stamp_ns': '2000000',
              'step_topics': '/clock,/pentapod/tcp_state,/pentapod/forces/a'}
    end = RunStatus.from_values(values)
    assert end.ended and end.steps == 3 and end.step_topics[-1] == '/pentapod/forces/a'
    ledger = StepLedger(lambda t: t != '/pentapod/tcp_state')
    topics = ledger.expected_topics(end, ['/pentapod/excitation', '/pentapod/run_status'])
    assert topics == ['/clock', '/pentapod/forces/a', '/pentapod/excitation']
    for k in range(3):
        ledger.note('/clock', k * 1_000_000)
        ledger.note('/pentapod/forces/a', k * 1_000_000)
    assert ledger.pending(end, topics) == ['/pentapod/excitation']     # not yet
    ledger.note('/pentapod/excitation', 2_000_000)  # the last step (earlier ones lost)
    assert not ledger.pending(end, topics)
    report = ledger.report(end, topics, {'/clock': 3, '/pentapod/forces/a': 3,
                                         '/pentapod/excitation': 1})
    assert shortfalls(report) == {'/pentapod/excitation': 2}
    for bad, match in (({**values, 'steps': 'x'}, 'bad number'),
                       ({**values, 'state': 'done'}, "'done'"),
                       ({k: v for k, v in values.items() if k != 'dt'}, "'dt'")):
        with pytest.raises(BagError, match=match):
            RunStatus.from_values(bad)


# --- real nodes ----------------------------------------------------------------------------

def start(module: str, name: str, params: Path, log: Path,
          env: dict | None = None) -> subprocess.Popen:
    cmd = [sys.executable, '-m', module, '--ros-args', '-r', f'__node:={name}',
           '--params-file', str(params)]
    env = dict(os.environ if env is None else env, PYTHONPATH=str(ROOT), PYTHONUNBUFFERED='1')
    return subprocess.Popen(cmd, cwd=ROOT, env=env, stdout=open(log, 'w'),  # noqa: SIM115
                            stderr=subprocess.STDOUT)


def run_with_stalls(tmp_path: Path, steps: int, stalls, after_end: float = 0.0,
                    drain_timeout: float = 60.0, env: dict | None = None) -> tuple:
    """
    Run plant + exciter + recorder; freeze the recorder per ``stalls``.

    ``stalls`` is a list of (run time, pause) [s] after the first messages are on disk; with
    ``after_end`` the last pause lasts until the plant announced the end of the run and
    ``after_end`` s more. ``env``: the three processes' environment. Returns (plant log,
    recorder log, bag folder, plant still running at each SIGSTOP).
    """
    params = tmp_path / 'scenario.yaml'
    params.write_text(SCENARIO.format(steps=steps, out=tmp_path).replace(
        'drain_timeout: 60.0', f'drain_timeout: {drain_timeout}'))
    procs: dict = {}
    running = []
    try:
        for name, module in (('exciter', 'pentapod_sim.nodes.exciter_node'),
                             ('recorder', 'pentapod_sim.nodes.recorder_node'),
                             ('plant', 'pentapod_sim.nodes.plant_node')):
            procs[name] = start(module, name, params, tmp_path / f'{name}.log', env)
        meta = tmp_path / 'bag' / 'metadata.yaml'
        end = time.monotonic() + 120
        while not (meta.exists() and yaml.safe_load(meta.read_text())
                   ['rosbag2_bagfile_information']['message_count'] > 10):
            assert time.monotonic() < end and procs['plant'].poll() is None, 'no messages'
            time.sleep(0.05)
        for run, pause in stalls:
            time.sleep(run)
            procs['recorder'].send_signal(signal.SIGSTOP)
            running.append(procs['plant'].poll() is None)
            time.sleep(pause)
            if after_end and (run, pause) == stalls[-1]:
                subprocess.run([sys.executable, '-c', END_WATCHER], timeout=120, check=True)
                running.append(procs['plant'].poll() is None)   # waits for the recorder's acks
                time.sleep(after_end)
            procs['recorder'].send_signal(signal.SIGCONT)
        assert procs['plant'].wait(timeout=180) == 0
        assert procs['recorder'].wait(timeout=90) == 0   # stops by itself at the end
    finally:
        for proc in procs.values():
            if proc.poll() is None:
                proc.send_signal(signal.SIGCONT)
                proc.send_signal(signal.SIGINT)
                proc.wait(timeout=30)
    logs = [(tmp_path / f'{n}.log').read_text() for n in ('plant', 'recorder')]
    return logs[0], logs[1], tmp_path / 'bag', running


def mcap_counts(bag: Path) -> dict:
    """Messages per topic, counted by the mcap library."""
    counts: dict = {}
    with open(next(bag.glob('*.mcap')), 'rb') as stream:
        for _, channel, _ in make_reader(stream).iter_messages():
            counts[channel.topic] = counts.get(channel.topic, 0) + 1
    return counts


def check_bag(bag: Path, steps: int) -> dict:
    """Every per-step topic holds every step; metadata.yaml agrees with the MCAP."""
    counts = mcap_counts(bag)
    per_step = {t: c for t, c in counts.items() if interface.is_step_topic(t)}
    assert set(per_step) >= {interface.CLOCK, interface.TCP_STATE, interface.EXCITATION,
                             interface.force_topic('exciter')}
    assert per_step == dict.fromkeys(per_step, steps)
    assert counts[interface.RUN_STATUS] >= 2     # running (start, every status_period), end
    info = yaml.safe_load((bag / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    topics = {t['topic_metadata']['name']: t for t in info['topics_with_message_count']}
    assert {t: v['message_count'] for t, v in topics.items()} == counts
    assert info['message_count'] == sum(counts.values())
    custom = info['custom_data']
    assert yaml.safe_load(custom['pentapod_recording.recorded']) == per_step
    assert yaml.safe_load(custom['pentapod_recording.expected']) == dict.fromkeys(per_step, steps)
    assert custom['pentapod_recording.steps'] == str(steps)
    for topic, entry in topics.items():    # the publishers' QoS, not the recorder's
        (offered,) = entry['topic_metadata']['offered_qos_profiles']
        spec = interface.QOS[interface.qos_class(topic)]
        assert (offered['depth'], offered['reliability'], offered['durability']) == (
            spec.depth, spec.reliability, spec.durability), topic
    return per_step


def ran(plant_log: str) -> tuple[int, float]:
    """Steps and wall time [s] from the plant's summary line."""
    match = re.search(r'ran (\d+) (?:of \d+ )?steps in ([\d.]+) s wall', plant_log)
    assert match, plant_log
    return int(match.group(1)), float(match.group(2))


@pytest.mark.ros
@pytest.mark.slow
def test_recorder_paused_three_times_keeps_every_step(tmp_path):
    steps = 12000
    plant_log, recorder_log, bag, running = run_with_stalls(
        tmp_path, steps, [(0.5, 1.5), (1.0, 1.5), (1.0, 1.5)])
    n, wall = ran(plant_log)
    assert n == steps
    # the race happened: the plant ran during the pauses, faster than the old force history
    assert running == [True, True, True], plant_log
    assert 1.5 * n / wall > OLD_FORCE_DEPTH, wall
    per_step = check_bag(bag, steps)
    assert 'none missing' in recorder_log
    for topic in per_step:
        assert f'{topic} {steps}/{steps}' in recorder_log


@pytest.mark.ros
@pytest.mark.slow
def test_recorder_stalled_past_the_last_message_does_not_close_early(tmp_path):
    """The recorder stays frozen until 2.5 s after the plant's end; it still drains all."""
    steps = 1500
    plant_log, recorder_log, bag, running = run_with_stalls(
        tmp_path, steps, [(0.0, 0.0)], after_end=2.5)
    n, _ = ran(plant_log)
    assert running == [True, True] and n == steps
    check_bag(bag, steps)
    assert 'none missing' in recorder_log


def fast_repair_profile(folder: Path) -> Path:
    """
    The package's Fast DDS profile with an 8 MB receive buffer.

    The package's profile already has a 0.1 s writer heartbeat (with Fast DDS's 3 s a frozen
    recorder's lost datagrams come back in rounds 3 s apart, so a recorder with a short
    ``drain_timeout`` would also close between two repair rounds); with the larger buffer
    the recorder's own pace is the only slow part.
    """
    text = (ROOT / 'config' / 'dds' / 'loopback.xml').read_text()
    assert '<heartbeatPeriod><sec>0</sec><nanosec>100000000</nanosec></heartbeatPeriod>' in text
    text = text.replace('<type>UDPv4</type>',
                        '<type>UDPv4</type><receiveBufferSize>8388608</receiveBufferSize>')
    path = folder / 'fast_repair.xml'
    path.write_text(text)
    return path


@pytest.mark.ros
@pytest.mark.slow
def test_a_recorder_behind_the_run_takes_every_step_after_its_drain_timeout(tmp_path):
    """
    ``drain_timeout`` counts from the last step taken, not from the end announcement.

    The recorder is frozen for the whole run and continued after the plant announced its end:
    it then holds 5000 steps of several topics in its readers and takes the announcement
    first (one message among few). A composed run on a loaded machine did this by itself: the
    recorder took steps for 35 s after the end and closed at 30 s with the rest missing.
    Here taking the backlog lasts longer than the 1 s ``drain_timeout``, which the test checks
    from the bag's receive times.
    """
    steps, drain = 5000, 1.0
    # a profile other than the package's is refused unless opened on purpose: this one is the
    # package's loopback profile with the larger buffer
    env = dict(os.environ, FASTRTPS_DEFAULT_PROFILES_FILE=str(fast_repair_profile(tmp_path)),
               PENTAPOD_OPEN_NETWORK='1')
    plant_log, recorder_log, bag, running = run_with_stalls(
        tmp_path, steps, [(0.0, 0.0)], after_end=0.2, drain_timeout=drain, env=env)
    assert running == [True, True] and ran(plant_log)[0] == steps
    check_bag(bag, steps)
    assert 'none missing' in recorder_log
    # the race happened: steps were still taken more than drain_timeout after the announcement
    announced = _log_time(recorder_log, f'run finished after {steps} steps')
    with open(next(bag.glob('*.mcap')), 'rb') as stream:
        last = max(message.publish_time for _, channel, message in
                   make_reader(stream).iter_messages() if interface.is_step_topic(channel.topic))
    assert last / 1e9 - announced > drain, (last / 1e9 - announced, recorder_log)


def _log_time(log: str, text: str) -> float:
    """ROS log time [s] of the first line of ``log`` containing ``text``."""
    match = re.search(r'\[(\d+\.\d+)\] \[\w+\]: ' + re.escape(text), log)
    assert match, (text, log)
    return float(match.group(1))


@pytest.mark.ros
@pytest.mark.slow
def test_a_recorder_that_matches_a_writer_late_still_gets_every_step(tmp_path):
    """
    The recorder finds a per-step topic only at the end of the run: all of it is in.

    A recorder subscribes at once to the known topics and to the forces of the sources the
    plant announces; a per-step topic of any other node (here an exciter the plant does not
    wait for: it answers every state, and nobody names its topic) only when discovery finds it,
    and DDS discovery is not symmetric either: a writer can match a reader seconds before the
    reader matches it. The per-step writers keep their history for such a reader (transient
    local), so the bag still holds the first steps; with volatile writers it lacked them (a CI
    run lost 2,156). Here the recorder looks for topics only at its start and at the end of the
    run (``discovery_period`` of an hour), so every force was published before its reader
    existed.
    """
    steps = 6000
    params = tmp_path / 'scenario.yaml'
    params.write_text(SCENARIO.format(steps=steps, out=tmp_path).replace(
        'flush_period: 0.2', 'flush_period: 0.2\n    discovery_period: 3600.0').replace(
        '    sources: [exciter]\n', ''))
    procs = {'recorder': start('pentapod_sim.nodes.recorder_node', 'recorder', params,
                               tmp_path / 'recorder.log')}
    try:
        end = time.monotonic() + 60
        while 'recording to' not in (tmp_path / 'recorder.log').read_text():
            assert time.monotonic() < end and procs['recorder'].poll() is None
            time.sleep(0.05)
        for name, module in (('exciter', 'pentapod_sim.nodes.exciter_node'),
                             ('plant', 'pentapod_sim.nodes.plant_node')):
            procs[name] = start(module, name, params, tmp_path / f'{name}.log')
        assert procs['plant'].wait(timeout=180) == 0
        assert procs['recorder'].wait(timeout=90) == 0
    finally:
        for proc in procs.values():
            if proc.poll() is None:
                proc.send_signal(signal.SIGINT)
                proc.wait(timeout=30)
    plant_log, recorder_log = ((tmp_path / f'{n}.log').read_text() for n in ('plant', 'recorder'))
    # the race happened: the forces were subscribed only after the end of the run
    forces = interface.force_topic('exciter')
    assert (recorder_log.index(f'subscribed {forces}')
            > recorder_log.index(f'run finished after {steps} steps')), recorder_log
    assert ran(plant_log)[0] == steps
    check_bag(tmp_path / 'bag', steps)
    assert 'none missing' in recorder_log
