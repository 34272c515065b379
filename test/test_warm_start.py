"""
Composed runs forked warm (:mod:`pentapod_sim.scenario.warm_start`) behave as fresh ones.

The same scenario started fresh (``python -m pentapod_sim.nodes.composed``) and forked from
the forkserver must give the same trace and the same recorded bytes; the forked run must take
its own environment before rclpy starts, stop on a signal like a fresh one, and report a bad
parameter in one line.
"""
import os
from pathlib import Path
import signal
import subprocess
import sys
import time

from mcap.reader import make_reader
import numpy as np
import pytest
from test_stopping import alive, metadata_counts, random_scenario, scenario
import yaml

from pentapod_sim.interface import RUN_STATUS
from pentapod_sim.scenario.domain import isolated_env
from pentapod_sim.scenario.files import dump_params
from pentapod_sim.scenario.runner import run_scenario
from pentapod_sim.scenario.warm_start import WarmStarter

pytestmark = [pytest.mark.ros]


def _messages(bag: Path) -> dict[str, list[bytes]]:
    """Serialised messages of a bag per topic, in the order they were written."""
    out: dict[str, list[bytes]] = {}
    for path in sorted(bag.glob('*.mcap')):
        with open(path, 'rb') as stream:
            for _, channel, message in make_reader(stream).iter_messages(log_time_order=False):
                out.setdefault(channel.topic, []).append(bytes(message.data))
    return out


def test_a_warm_run_equals_a_fresh_one_bit_for_bit(tmp_path):
    warm = WarmStarter()
    folders = {}
    for mode in ('fresh', 'warm'):
        folder = folders[mode] = tmp_path / mode
        folder.mkdir()
        path = random_scenario(folder, 600)
        env = dict(os.environ, ROS_LOG_DIR=str(folder / 'ros_log'))
        code = run_scenario(path, {}, 180.0, env, log_dir=folder / 'logs', composed=True,
                            warm=warm if mode == 'warm' else None)
        assert code == 0, (folder / 'logs' / 'composition.log').read_text()
        # the run's own environment reached rclpy: its log file is in the run's folder
        assert list((folder / 'ros_log').glob('*.log')), mode
    fresh, forked = (np.load(folders[m] / 'trace.npz') for m in ('fresh', 'warm'))
    assert int(forked['steps_run']) == 600
    assert np.array_equal(fresh['y'], forked['y']) and np.array_equal(fresh['u'], forked['u'])
    bags = [folders[m] / 'bags' / 'run' for m in ('fresh', 'warm')]
    assert metadata_counts(bags[1])['/pentapod/tcp_state'] == 600
    # per topic (topics sent once, the controllers' models, arrive in either order); the run
    # status holds wall-clock figures (step rate)
    fresh_msgs, warm_msgs = (_messages(bag) for bag in bags)
    assert fresh_msgs.pop(RUN_STATUS) and warm_msgs.pop(RUN_STATUS)
    assert fresh_msgs == warm_msgs and len(fresh_msgs) >= 4


def _start(warm: WarmStarter, path: Path, folder: Path, env: dict):
    log = folder / 'composition.log'
    return warm.start(['-m', 'pentapod_sim.nodes.composed', str(path)], env, log), log


def test_a_stop_signal_ends_a_warm_run_cleanly(tmp_path):
    path = scenario(tmp_path)
    with isolated_env(dict(os.environ)) as env:
        run, log = _start(WarmStarter(), path, tmp_path, env)
        try:
            end = time.monotonic() + 90
            while 'lockstep run of' not in log.read_text():
                assert run.poll() is None and time.monotonic() < end, log.read_text()
                time.sleep(0.05)
            time.sleep(0.5)
            run.send_signal(signal.SIGINT)
            assert run.wait(timeout=30) == 130, log.read_text()
        finally:
            if run.poll() is None:
                run.kill()
    assert 'stopped by SIGINT' in log.read_text()
    trace = np.load(tmp_path / 'trace.npz')
    steps = int(trace['steps_run'])
    assert steps > 0 and str(trace['end']) == 'stopped by SIGINT'
    counts = metadata_counts(tmp_path / 'bags' / 'run')      # closed: metadata written
    assert counts['/pentapod/tcp_state'] >= steps


def test_a_bad_parameter_ends_a_warm_run_with_one_error_line(tmp_path):
    path = scenario(tmp_path, steps=100, record=False)
    doc = yaml.safe_load(path.read_text())
    doc['plant']['ros__parameters']['sample_rat'] = 1000.0
    path.write_text(dump_params(doc))
    with isolated_env(dict(os.environ)) as env:
        run, log = _start(WarmStarter(), path, tmp_path, env)
        assert run.wait(timeout=60) == 1
    text = log.read_text()
    errors = [line for line in text.splitlines() if line.startswith('error:')]
    assert len(errors) == 1 and "'sample_rat'" in errors[0], text
    assert 'Traceback' not in text


STARTER = r"""
import sys, time
from pentapod_sim.scenario.warm_start import WarmStarter
if __name__ == '__main__':
    run = WarmStarter().start(['-m', 'pentapod_sim.nodes.composed', sys.argv[1]],
                              dict(__import__('os').environ), sys.argv[2])
    print(run.pid, flush=True)
    time.sleep(600)
"""


def test_a_warm_run_stops_when_the_process_that_started_it_is_killed(tmp_path):
    """SIGKILL to the starter: its run stops cleanly (the forkserver would keep it alive)."""
    path = scenario(tmp_path)                                   # an endless run
    log = tmp_path / 'composition.log'
    with isolated_env(dict(os.environ)) as env:
        starter = subprocess.Popen([sys.executable, '-c', STARTER, str(path), str(log)],
                                   env=env, stdout=subprocess.PIPE, text=True)
        pid = int(starter.stdout.readline())
        try:
            end = time.monotonic() + 90
            while 'lockstep run of' not in log.read_text():
                assert time.monotonic() < end, log.read_text()
                time.sleep(0.05)
            starter.kill()
            starter.wait()
            end = time.monotonic() + 20
            while alive(pid):
                assert time.monotonic() < end, f'the run outlived its starter:\n{log.read_text()}'
                time.sleep(0.1)
        finally:
            if alive(pid):
                os.kill(pid, signal.SIGKILL)
    assert 'stopped by SIGTERM' in log.read_text()
    assert metadata_counts(tmp_path / 'bags' / 'run')['/pentapod/tcp_state'] > 0
