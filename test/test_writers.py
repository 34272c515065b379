"""
One writer per topic (pentapod_sim.nodes.writers).

The rule on a scripted graph, then real spoofers on the session's domain.
"""
import os
from pathlib import Path
import subprocess
import sys
import time
from types import SimpleNamespace

from mcap.reader import make_reader
import numpy as np
import pytest
import test_stopping
from test_stopping import RATE, scenario

from pentapod_sim import exits
from pentapod_sim.errors import RunError
from pentapod_sim.nodes import writers
from pentapod_sim.nodes.recorder_node import RECORDING_RECORD
from pentapod_sim.nodes.writers import WriterCheck
from pentapod_sim.recording.run_end import NO_END

TOPIC = '/pentapod/tcp_state'
#: the runner fixture of test_stopping (a run per call, every process killed after the test)
runner_of = test_stopping.runner_of


def gid(host: int, pid: int, entity: int = 3) -> bytes:
    """A Fast DDS endpoint GUID: vendor 01.0f, host id, process id, ..., entity id."""
    return (b'\x01\x0f' + host.to_bytes(2, 'big') + pid.to_bytes(2, 'little') + bytes(6)
            + entity.to_bytes(4, 'big'))


def info(g: bytes, name: str = 'plant'):
    return SimpleNamespace(endpoint_gid=list(g), node_name=name, node_namespace='/')


class Graph:
    """A node whose graph shows ``self.pubs[topic]``; a subscription with a matched count."""

    def __init__(self):
        self.pubs: dict[str, list] = {}

    def get_publishers_info_by_topic(self, topic):
        return self.pubs.get(topic, [])


def test_a_second_writer_is_refused_naming_both_participants_and_hosts():
    graph = Graph()
    check = WriterCheck(graph)
    check.watch(TOPIC)
    graph.pubs[TOPIC] = [info(gid(0x78fd, 29691))]
    assert [w.gid for w in check.check()[TOPIC]] == [gid(0x78fd, 29691)]
    # the spoofer claims the plant's node name: it is told apart by its GUID
    graph.pubs[TOPIC].append(info(gid(0x78fd, 4242)))
    with pytest.raises(RunError) as err:
        check.check()
    text = str(err.value)
    assert f'{TOPIC} has 2 writers' in text
    assert 'process id 29691' in text and 'process id 4242' in text, text
    assert text.count('host id 78fd') == 2 and text.count('node /plant') == 2


def test_a_writer_that_replaced_the_pinned_one_is_refused():
    graph = Graph()
    check = WriterCheck(graph)
    check.watch(TOPIC)
    graph.pubs[TOPIC] = [info(gid(1, 10))]
    check.check()
    graph.pubs[TOPIC] = [info(gid(1, 11))]
    with pytest.raises(RunError, match='its writer changed between two checks'):
        check.check()


def test_shared_topics_allow_several_writers_and_record_them():
    graph = Graph()
    check = WriterCheck(graph)
    check.watch(TOPIC, shared=True)
    graph.pubs[TOPIC] = [info(gid(1, 10)), info(gid(1, 11))]
    assert len(check.check()[TOPIC]) == 2
    assert check.foreign() == {}


@pytest.fixture
def one_writer(monkeypatch):
    """(clock [s], graph, check): a check of TOPIC with one writer, on a clock the test sets."""
    now = [0.0]
    monkeypatch.setattr(writers.time, 'monotonic', lambda: now[0])
    graph = Graph()
    check = WriterCheck(graph)
    check.watch(TOPIC)
    graph.pubs[TOPIC] = [info(gid(1, 10))]
    return now, graph, check


def test_messages_are_refused_while_dds_matched_a_second_writer(one_writer):
    """Per message: two matched publishers refuse every message; the graph check then stops."""
    now, graph, check = one_writer
    check.check()
    sub = SimpleNamespace(count=1, get_publisher_count=lambda: sub.count)
    assert check.message_ok(TOPIC, sub)
    sub.count = 2                        # matched by DDS, not yet in the ROS graph
    assert not check.message_ok(TOPIC, sub) and not check.message_ok(TOPIC, sub)
    assert check.due()
    check.check()                        # within GRAPH_LAG: not yet stopped
    now[0] += writers.GRAPH_LAG + 0.01
    with pytest.raises(RunError, match=r'DDS matched a second writer \(2 message\(s\) refused'):
        check.check()


def test_the_final_check_refuses_a_second_matched_writer_at_once(one_writer):
    """A recorder's last check (at close) does not wait GRAPH_LAG for the graph to show it."""
    _, graph, check = one_writer
    sub = SimpleNamespace(get_publisher_count=lambda: 2)
    assert not check.message_ok(TOPIC, sub)
    assert check.check_each() == {}              # a periodic check waits for the graph
    assert 'DDS matched a second writer' in check.check_each(final=True)[TOPIC]
    graph.pubs[TOPIC].append(info(gid(2, 10)))   # the graph shows it: named by its process
    assert 'process id' in check.check_each(final=True)[TOPIC]
    # a recorder takes every message (evidence): it looks at its reader's match count at the end
    other = WriterCheck(Graph())
    other.watch(TOPIC)
    other.note_matched(TOPIC, SimpleNamespace(get_publisher_count=lambda: 1))
    assert other.check_each(final=True) == {}
    other.note_matched(TOPIC, sub)
    assert '(0 message(s) refused)' in other.check_each(final=True)[TOPIC]


# ---- real participants on the session's domain ---------------------------------------------


SPOOFER = Path(__file__).parent / 'fixtures' / 'spoofer.py'
FORGED_VELOCITY = 50.0       # m/s: the TCP damper's 2000 N s/m make 100 kN of it


def spoofer(rate: float, *mode: str) -> subprocess.Popen:
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(sys.path))
    return subprocess.Popen([sys.executable, str(SPOOFER), str(rate), str(FORGED_VELOCITY),
                             *mode], env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            text=True, start_new_session=True)


def forged_steps(trace: Path) -> int:
    """Steps of a trace whose TCP force holds the damper's answer to the forged velocity."""
    u = np.load(trace)['u']
    return int(np.count_nonzero(np.abs(u).max(axis=1) > 0.1 * 2000.0 * FORGED_VELOCITY))


@pytest.mark.ros
@pytest.mark.slow
def test_a_source_refuses_a_second_writer_on_the_state_it_reads(tmp_path):
    """No plant: two participants publish the TCP state; the damper stops naming both."""
    from fixtures.processes import NodeProcesses
    procs = NodeProcesses(tmp_path)
    first, second = spoofer(RATE, 'free'), None
    try:
        procs.start('damper', 'pentapod_damper.nodes.damper_node', 'tcp_directions:=[x, z]',
                    'tcp_gain:=2000.0', f'sample_rate:={RATE}')
        time.sleep(2.0)
        assert procs.procs['damper'].poll() is None, procs.log('damper')
        second = spoofer(RATE, 'free')
        code = procs.wait('damper', timeout=30)
    finally:
        procs.close()
        for p in (first, second):
            if p is not None:
                p.kill()
                p.wait()
    out = procs.log('damper')
    assert code == 1, out
    line = next(x for x in out.splitlines() if '/pentapod/tcp_state has 2 writers' in x)
    # two participants, told apart by DDS (both claim the node name 'plant')
    assert line.startswith('error: ') and line.count('participant 01.0f.') == 2, line
    assert str(first.pid & 0xffff) in line and str(second.pid & 0xffff) in line, line
    assert 'Traceback' not in out and 'FATAL' not in out, out


@pytest.mark.ros
def test_a_state_recorded_without_any_run_announced_names_its_writer(tmp_path):
    """
    The forger is the only writer the recorder ever saw: the bag still names it.

    In the runner's run above, the damper can refuse the forged state and the run be stopped
    before the recorder's participant has found the real plant (a two-worker suite,
    2026-12-04), so the recorder never saw two writers. The plant announces its run before its
    first step: state messages without any run announced are not the plant's.
    """
    from fixtures.processes import NodeProcesses
    procs = NodeProcesses(tmp_path)
    fake = spoofer(RATE, 'free')
    try:
        procs.start('recorder', 'pentapod_sim.nodes.recorder_node', f"output_dir:='{tmp_path}'",
                    'bag_name:=run')
        procs.wait_for('recorder', f'subscribed {TOPIC}')
        time.sleep(2.0)          # the forged states are recorded
        code = procs.stop('recorder')
    finally:
        procs.close()
        fake.kill()
        fake.wait()
    log = procs.log('recorder')
    assert code == exits.RECORDING_FAILED, log
    with open(next((tmp_path / 'run').glob('*.mcap')), 'rb') as stream:
        record = {m.name: dict(m.metadata) for m in make_reader(stream).iter_metadata()}[
            RECORDING_RECORD]
    assert record['run_state'] == NO_END, record
    assert 'no run announced' in record['foreign'], record
    assert f'process id {fake.pid & 0xffff} ' in record['foreign'], record


@pytest.mark.ros
@pytest.mark.slow
@pytest.mark.parametrize('when', ['before', 'during'])
def test_a_forged_plant_state_stops_the_run_and_no_forged_force_is_applied(
        tmp_path, runner_of, when):
    """
    The issue's attack: a participant forging /pentapod/tcp_state one step ahead.

    Before the fix the damper answered the forged step and re-sent that answer for the real
    one (100 kN on most steps, exit 0). Now the run stops naming both writers, and no step of
    the trace carries a force computed from the forged state.
    """
    run_file = scenario(tmp_path)
    fake = spoofer(RATE, 'free') if when == 'before' else None
    try:
        if when == 'before':
            time.sleep(1.0)
        run = runner_of(run_file)
        if when == 'during':
            run.wait_for('lockstep run of')
            time.sleep(1.0)
            fake = spoofer(RATE)
        code = run.proc.wait(timeout=90)
    finally:
        if fake is not None:
            fake.kill()
            forged = fake.communicate()[0]
    out = run.text()
    # 1, the damper's error: before the run the plant, still waiting for its sources, had to
    # be stopped, which the runner once reported as its own timeout (5)
    assert code == exits.ERROR, out
    assert '/pentapod/tcp_state has 2 writers' in out, out
    assert 'Traceback' not in out, out
    # the attack did happen: the spoofer's participant (its process id) is the one named; it
    # may be refused before it forged a single message (its writer was matched first)
    line = next(x for x in out.splitlines() if '/pentapod/tcp_state has 2 writers' in x)
    assert f'process id {fake.pid & 0xffff} ' in line, (line, forged)
    trace = tmp_path / 'trace.npz'
    if trace.exists():
        assert forged_steps(trace) == 0
        assert str(np.load(trace)['end']).startswith('error: ')
    # the bag, whatever it holds of the forgery, says so (even if the plant never ran)
    with open(next((tmp_path / 'bags' / 'run').glob('*.mcap')), 'rb') as stream:
        record = {m.name: dict(m.metadata) for m in make_reader(stream).iter_metadata()}[
            RECORDING_RECORD]
    assert TOPIC in record['foreign'] and str(fake.pid & 0xffff) in record['foreign'], record
    if not trace.exists():
        assert record['run_state'] == NO_END, record


@pytest.mark.ros
@pytest.mark.slow
@pytest.mark.parametrize('mode', ['empty', 'partial', 'force'])
def test_a_forged_force_answer_at_the_right_stamp_is_never_applied(tmp_path, runner_of, mode):
    """
    The issue's answers on /pentapod/forces/damper, stamped with each real step, mid-run.

    ``empty`` (no port) and ``partial`` (tcp_force_x only, 100 kN) once displaced the real
    answer; ``force`` (both ports, 100 kN) is the second force writer applied for 26-60 steps.
    The plant refuses the writer (exit 1, naming the spoofer's participant), no step carries
    its force, and the recorder's failed report (it saw the writer too) does not hide the
    plant's error behind a recording failure (3).
    """
    run = runner_of(scenario(tmp_path))
    run.wait_for('lockstep run of')
    time.sleep(1.0)
    fake = spoofer(RATE, mode)
    try:
        code = run.proc.wait(timeout=120)
    finally:
        fake.kill()
        forged = fake.communicate()[0]
    out = run.text()
    assert code == exits.ERROR, out
    line = next(x for x in out.splitlines()
                if x.startswith('error: /pentapod/forces/damper has 2 writers'))
    assert f'process id {fake.pid & 0xffff} ' in line, (line, forged)
    trace = np.load(tmp_path / 'trace.npz')
    assert str(trace['end']).startswith('error: /pentapod/forces/damper has 2 writers')
    assert int(trace['steps_run']) > 0 and forged_steps(tmp_path / 'trace.npz') == 0
    assert 'Traceback' not in out, out
