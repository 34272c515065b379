"""
Isolation of runs: localhost discovery and a free ROS domain that no concurrent run shares.

The allocation races are made to happen: threads and processes allocate at the same instant
(a barrier, a start file). The runner's nodes are inspected as processes (/proc/<pid>/environ)
while they run.
"""
import os
from pathlib import Path
import signal
import subprocess
import sys
import threading
import time

import pytest

from fixtures.demo_model import demo_model
from pentapod_sim.errors import ConfigError, RunError
from pentapod_sim.scenario.domain import (
    allocate,
    domain_in_use,
    DOMAINS,
    isolated_env,
    isolation,
)
from pentapod_sim.scenario.network import loopback_profile

ROOT = Path(__file__).resolve().parents[1]
#: Domains this test file may use for its own participants and races (none of its locks
#: leave the test's temporary lock folder).
OWN = range(155, 161)


def test_concurrent_allocations_in_threads_never_share_a_domain(tmp_path):
    """8 threads released by one barrier compete for 4 domains, 25 times."""
    domains, n = OWN[:4], 8
    for _ in range(25):
        barrier, results = threading.Barrier(n), [None] * n

        def work(i):
            barrier.wait()
            try:
                results[i] = allocate(domains, tmp_path)
            except RunError as err:
                results[i] = err

        threads = [threading.Thread(target=work, args=(i,)) for i in range(n)]
        for thread in threads:
            thread.start()
        for thread in threads:
            thread.join()
        leases = [r for r in results if not isinstance(r, RunError)]
        try:
            got = [lease.domain for lease in leases]
            assert len(set(got)) == len(got), got
            assert set(got) <= set(domains) and 1 <= len(got) <= len(domains)
            assert all('no free ROS domain in 155-158' in str(r) for r in results
                       if isinstance(r, RunError))
        finally:
            for lease in leases:
                lease.release()


ALLOCATOR = """
import sys, time
from pathlib import Path
from pentapod_sim.errors import RunError
from pentapod_sim.scenario.domain import allocate
go = Path(sys.argv[1])
print('ready', flush=True)
while not go.exists():
    time.sleep(0.001)
try:
    lease = allocate(range(155, 158))
    print(lease.domain, flush=True)
except RunError:
    print('none', flush=True)
sys.stdin.read()          # hold the lease until the parent closes stdin
"""


def test_concurrent_allocations_in_processes_never_share_a_domain(tmp_path):
    """6 processes started by one file compete for 3 domains through the shared lock folder."""
    env = dict(os.environ, PENTAPOD_DOMAIN_LOCK_DIR=str(tmp_path / 'locks'))
    go = tmp_path / 'go'
    procs = [subprocess.Popen([sys.executable, '-c', ALLOCATOR, str(go)], env=env,
                              stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
             for _ in range(6)]
    try:
        assert [p.stdout.readline().strip() for p in procs] == ['ready'] * 6
        go.touch()
        answers = [p.stdout.readline().strip() for p in procs]
        got = [int(a) for a in answers if a != 'none']
        assert len(set(got)) == len(got), answers
        assert set(got) <= {155, 156, 157} and 1 <= len(got) <= 3, answers
    finally:
        for proc in procs:
            proc.stdin.close()
        for proc in procs:
            assert proc.wait(timeout=30) == 0


def test_lease_is_released_when_its_holder_is_killed(tmp_path):
    """Flock belongs to the open file: SIGKILL of the holder frees the domain."""
    env = dict(os.environ, PENTAPOD_DOMAIN_LOCK_DIR=str(tmp_path))
    holder = subprocess.Popen(
        [sys.executable, '-c', 'from pentapod_sim.scenario.domain import allocate; '
         'lease = allocate([159]); print(lease.domain, flush=True); input()'],
        env=env, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == '159'
        with pytest.raises(RunError, match=str(tmp_path)):
            allocate([159], tmp_path)
    finally:
        holder.send_signal(signal.SIGKILL)
        holder.wait(timeout=30)
    with allocate([159], tmp_path) as lease:
        assert lease.domain == 159 and lease.held
    assert not lease.held


@pytest.mark.ros
def test_a_domain_used_by_a_participant_without_a_lock_is_skipped(tmp_path):
    """A DDS participant started by hand (no lock) makes its domain unavailable."""
    import rclpy
    domain = OWN[-1]
    assert not domain_in_use(domain)
    ctx = rclpy.context.Context()
    rclpy.init(context=ctx, domain_id=domain)
    node = rclpy.create_node('someone_else', context=ctx)
    try:
        assert domain_in_use(domain)
        with allocate([domain, domain - 1], tmp_path) as lease:
            assert lease.domain == domain - 1
    finally:
        node.destroy_node()
        rclpy.shutdown(context=ctx)


def test_isolation_sets_loopback_dds_and_a_reserved_domain_unless_the_user_did(tmp_path,
                                                                               monkeypatch):
    monkeypatch.setenv('PENTAPOD_DOMAIN_LOCK_DIR', str(tmp_path))
    local = {'FASTRTPS_DEFAULT_PROFILES_FILE': str(loopback_profile()),
             'ROS_AUTOMATIC_DISCOVERY_RANGE': 'SYSTEM_DEFAULT'}     # test_network.py
    with allocate(DOMAINS, tmp_path) as other:        # a concurrent run's domain
        changes, lease = isolation({})
        try:
            assert {k: changes[k] for k in local} == local
            assert int(changes['ROS_DOMAIN_ID']) == lease.domain != other.domain
            assert lease.domain in DOMAINS and lease.held
        finally:
            lease.release()
    user = {'ROS_DOMAIN_ID': '42', 'ROS_AUTOMATIC_DISCOVERY_RANGE': 'SUBNET',
            'PENTAPOD_OPEN_NETWORK': '1'}
    changes, lease = isolation(user)
    assert changes == {} and lease.domain == 42       # kept, and locked while free
    lease.release()
    with pytest.raises(RunError, match='open to the network'):     # not opened explicitly
        isolation({'ROS_DOMAIN_ID': '42', 'ROS_AUTOMATIC_DISCOVERY_RANGE': 'SUBNET'})
    assert isolation({'ROS_LOCALHOST_ONLY': '1', 'ROS_DOMAIN_ID': '7'})[0] == {
        **local, 'ROS_LOCALHOST_ONLY': '0'}
    changes, _ = isolation(user, domain_id=43)        # --domain-id wins over the environment
    assert changes == {'ROS_DOMAIN_ID': '43'}
    with isolated_env({'PATH': '/bin', 'ROS_DOMAIN_ID': '44'}) as env:
        assert env == {'PATH': '/bin', 'ROS_DOMAIN_ID': '44', **local}


@pytest.mark.parametrize('value', ['abc', '233', '-1', '1.5'])
def test_a_bad_domain_is_refused_naming_it(value):
    with pytest.raises(ConfigError, match=f"ROS_DOMAIN_ID='{value}'.*0-232"):
        isolation({'ROS_DOMAIN_ID': value})


def _children(pid: int) -> list[int]:
    kids = []
    for stat in Path('/proc').glob('[0-9]*/stat'):
        try:
            if int(stat.read_text().rsplit(')', 1)[1].split()[1]) == pid:
                kids.append(int(stat.parent.name))
        except (OSError, IndexError, ValueError):
            pass
    return kids


def _running_node_env(runner: subprocess.Popen, module: str, timeout: float = 120.0) -> dict:
    """Environment of the runner's child that runs ``python -m module`` (read while alive)."""
    end = time.monotonic() + timeout
    while time.monotonic() < end and runner.poll() is None:
        for kid in _children(runner.pid):
            try:
                if module.encode() in Path(f'/proc/{kid}/cmdline').read_bytes().split(b'\0'):
                    raw = Path(f'/proc/{kid}/environ').read_bytes().decode()
                    return dict(item.split('=', 1) for item in raw.split('\0') if '=' in item)
            except OSError:
                pass
        time.sleep(0.01)
    raise AssertionError(f'no {module} child of the runner seen; exit {runner.poll()}')


@pytest.mark.ros
@pytest.mark.slow
@pytest.mark.parametrize(('env_set', 'args', 'expect'), [
    ({}, [], None),
    ({'ROS_DOMAIN_ID': '156', 'ROS_AUTOMATIC_DISCOVERY_RANGE': 'OFF'}, [],
     {'ROS_DOMAIN_ID': '156', 'ROS_AUTOMATIC_DISCOVERY_RANGE': 'OFF'}),
    ({'ROS_DOMAIN_ID': '156'}, ['--domain-id', '157'],
     {'ROS_DOMAIN_ID': '157', 'ROS_AUTOMATIC_DISCOVERY_RANGE': 'SYSTEM_DEFAULT'}),
], ids=['free-domain', 'user-environment', 'domain-id-option'])
def test_runner_nodes_run_isolated(tmp_path, env_set, args, expect):
    """
    The runner's nodes get loopback DDS and a domain no concurrent run holds, reserved meanwhile.

    The concurrent run is this test, holding the first free domain. User-set values and
    --domain-id are kept as given.
    """
    model = demo_model(4).save(tmp_path / 'model.npz')
    scenario = tmp_path / 'alone.yaml'
    scenario.write_text(f"""
plant:
  ros__parameters:
    model_file: {model}
    sample_rate: 1000.0
    steps: 2000
    sources: ['']
""")
    # a profile the caller's environment names (tools/env.sh of another checkout) would be
    # kept by the runner as the user's choice; this test is about the default
    env = {k: v for k, v in os.environ.items()
           if k not in ('ROS_DOMAIN_ID', 'ROS_AUTOMATIC_DISCOVERY_RANGE', 'ROS_LOCALHOST_ONLY',
                        'FASTRTPS_DEFAULT_PROFILES_FILE')}
    path = [str(ROOT)] + ([env['PYTHONPATH']] if env.get('PYTHONPATH') else [])
    env.update(env_set, ROS_LOG_DIR=str(tmp_path / 'ros_log'),
               PYTHONPATH=os.pathsep.join(path))          # the code of this checkout
    with allocate() as other_run:           # a concurrent run holds the first free domain
        runner = subprocess.Popen([sys.executable, '-m', 'pentapod_sim.scenario.runner',
                                   str(scenario), '--timeout', '120', *args], env=env,
                                  cwd=tmp_path, stdout=subprocess.PIPE,
                                  stderr=subprocess.STDOUT, text=True)
        try:
            node_env = _running_node_env(runner, 'pentapod_sim.nodes.plant_node')
            domain = int(node_env['ROS_DOMAIN_ID'])
            if expect is None:
                assert node_env['ROS_AUTOMATIC_DISCOVERY_RANGE'] == 'SYSTEM_DEFAULT'
                assert node_env['FASTRTPS_DEFAULT_PROFILES_FILE'] == str(loopback_profile())
                assert domain in DOMAINS and domain != other_run.domain
                with pytest.raises(RunError):           # reserved by the runner meanwhile
                    allocate([domain])
            else:
                assert {k: node_env.get(k) for k in expect} == expect
            out, _ = runner.communicate(timeout=180)
        finally:
            if runner.poll() is None:
                runner.kill()
                runner.wait()
    assert runner.returncode == 0, out
    assert f'ROS_DOMAIN_ID={domain},' in out
