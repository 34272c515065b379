"""
The excitation stored in the bag: written by mcap_ros2 (ROS-free) and by a real lockstep run.

The ROS tests run real processes on the session's isolated domain (conftest.py): a scenario
run with a recorder, and a recorder started only after the exciter has published its spec
(the spec topic is transient local, so the late recorder must still get it).
"""
import os
from pathlib import Path
import signal
import subprocess
import sys
import time

from mcap_ros2.writer import Writer
import numpy as np
from numpy.testing import assert_allclose
import pytest

from fixtures.demo_model import demo_model
from pentapod_sim.analysis.bag.excitation_record import excitation_of, excitations_of
from pentapod_sim.analysis.bag.reader import open_bag
from pentapod_sim.errors import BagError
from pentapod_sim.interface import excitation_spec_topic
from pentapod_sim.scenario.files import dump_params
from pentapod_sim.sim.excitation import Excitation, ExcitationSpec
from pentapod_sim.sim.excitation_spec import spec_message

RATE = 2000.0


def write_mcap(path: Path, messages: dict) -> Path:
    """An MCAP of std_msgs/String messages {topic: [text, ...]} written by mcap_ros2."""
    with open(path, 'wb') as stream:
        writer = Writer(stream)
        schema = writer.register_msgdef('std_msgs/msg/String', 'string data')
        t = 0
        for topic, texts in messages.items():
            for text in texts:
                t += 1
                writer.write_message(topic, schema, {'data': text}, log_time=t, publish_time=t)
        writer.finish()
    return path


def test_excitation_of_reads_what_mcap_ros2_wrote(tmp_path):
    old = ExcitationSpec('sine', 1.0)
    spec = ExcitationSpec('multisine', 12.0, [0, 0, 1], period=0.5, f_start=2.0, f_end=80.0,
                          phases='random', seed=7, settle_periods=3)
    other = ExcitationSpec('stepped_sine', frequencies=[10.0, 20.0], settle_time=0.5)
    one = write_mcap(tmp_path / 'one.mcap', {excitation_spec_topic('exc'): [
        spec_message(old, RATE, 'exc'), spec_message(spec, RATE, 'exc')]})
    assert excitation_of(one) == (spec, 1 / RATE)          # the last message counts
    assert excitation_of(open_bag(one)) == (spec, 1 / RATE)
    two = write_mcap(tmp_path / 'two.mcap', {
        excitation_spec_topic('exc'): [spec_message(spec, RATE, 'exc')],
        excitation_spec_topic('second'): [spec_message(other, 4000.0, 'second')]})
    assert excitations_of(two) == {'exc': (spec, 1 / RATE), 'second': (other, 1 / 4000.0)}
    assert excitation_of(two, source='second') == (other, 1 / 4000.0)
    with pytest.raises(BagError, match='several sources'):
        excitation_of(two)
    none = write_mcap(tmp_path / 'none.mcap', {'/pentapod/other': ['x']})
    assert excitation_of(none) is None
    bad = write_mcap(tmp_path / 'bad.mcap', {excitation_spec_topic('exc'): [
        spec_message(ExcitationSpec('multisine', period=0.0123), RATE, 'exc')]})
    with pytest.raises(BagError, match='0.0123'):
        excitation_of(bad)


@pytest.fixture
def ros_env():
    """The session's isolated environment (conftest.py reserves its ROS domain)."""
    env = dict(os.environ, RCUTILS_LOGGING_BUFFERED_STREAM='0', PYTHONUNBUFFERED='1')
    assert env.get('ROS_DOMAIN_ID') and env.get('ROS_AUTOMATIC_DISCOVERY_RANGE')
    return env


@pytest.mark.ros
@pytest.mark.slow
def test_lockstep_run_stores_the_excitation_in_the_bag(ros_env, tmp_path):
    """Scenario runner: plant + multisine exciter + recorder; the bag gives the spec back."""
    steps = 600
    exciter = {'kind': 'multisine', 'amplitude': 20.0, 'period': 0.1, 'f_start': 10.0,
               'f_end': 400.0, 'settle_periods': 2, 'start_delay': 0.01,
               'direction': [0.0, 1.0, 0.0]}
    doc = {'/**': {'ros__parameters': {'sample_rate': RATE}},
           'exciter': {'ros__parameters': exciter},
           'plant': {'ros__parameters': {
               'model_file': str(demo_model(4).save(tmp_path / 'model.npz')), 'steps': steps,
               'sources': ['exciter'], 'startup_timeout': 60.0,
               'wait_for_subscribers': ['recorder']}},
           'recorder': {'ros__parameters': {'output_dir': str(tmp_path / 'bags'),
                                            'bag_name': 'run'}}}
    path = tmp_path / 'scenario.yaml'
    path.write_text(dump_params(doc))
    proc = subprocess.run([sys.executable, '-m', 'pentapod_sim.scenario.runner', str(path),
                           '--timeout', '120'], env=ros_env, capture_output=True, text=True,
                          timeout=180)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert 'crest factor' in proc.stdout + proc.stderr
    spec, dt = excitation_of(tmp_path / 'bags' / 'run')
    assert dt == 1 / RATE
    assert spec == ExcitationSpec(**exciter)
    signal_ = Excitation(spec, dt)
    assert signal_.period_steps == 200 and signal_.settle_periods == 2
    recorded = open_bag(tmp_path / 'bags' / 'run').series('/pentapod/excitation.force.y')
    assert_allclose(recorded.values, signal_.series(steps)[:, 1], rtol=0, atol=1e-12)


def wait_for(log: Path, needle: str, proc: subprocess.Popen, timeout: float = 60.0) -> None:
    end = time.monotonic() + timeout
    while needle not in log.read_text():
        assert proc.poll() is None, log.read_text()
        assert time.monotonic() < end, f'{needle!r} not in {log}: {log.read_text()}'
        time.sleep(0.1)


@pytest.mark.ros
@pytest.mark.slow
def test_a_recorder_started_after_the_exciter_still_records_its_spec(ros_env, tmp_path):
    procs = {}
    try:
        for name, module, params in (
                ('exciter', 'pentapod_sim.nodes.exciter_node',
                 ['kind:=periodic_chirp', 'period:=0.05', 'f_start:=5.0', 'f_end:=300.0',
                  f'sample_rate:={RATE}']),
                ('recorder', 'pentapod_sim.nodes.recorder_node',
                 [f'output_dir:={tmp_path}', 'bag_name:=late', 'stop_at_run_end:=false',
                  'discovery_period:=0.1'])):
            log = tmp_path / f'{name}.log'
            cmd = [sys.executable, '-m', module, '--ros-args']
            for p in params:
                cmd += ['-p', p]
            procs[name] = subprocess.Popen(cmd, env=ros_env, stdout=open(log, 'w'),
                                           stderr=subprocess.STDOUT)
            # the exciter has published before the recorder process even starts
            wait_for(log, 'periodic_chirp excitation' if name == 'exciter' else
                     f'subscribed {excitation_spec_topic("exciter")}', procs[name])
        time.sleep(1.0)                 # the transient-local sample arrives after matching
        procs['recorder'].send_signal(signal.SIGINT)
        assert procs['recorder'].wait(timeout=30) == 128 + signal.SIGINT
    finally:
        for proc in procs.values():
            if proc.poll() is None:
                proc.send_signal(signal.SIGINT)
                proc.wait(timeout=30)
    spec, dt = excitation_of(tmp_path / 'late')
    assert (spec, dt) == (ExcitationSpec('periodic_chirp', period=0.05, f_start=5.0,
                                         f_end=300.0), 1 / RATE)
    assert np.isinf(spec.duration)
