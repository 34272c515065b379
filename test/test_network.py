"""
DDS on the loopback interface by default, and a run open to the network only when asked for.

The sockets are read from the kernel (/proc/PID/fd and /proc/PID/net/*, the same tables ``ss``
prints) of every process of a real run: plant, exciter, damper and recorder as separate
processes started by the scenario runner, as a user starts them.
"""
import os
from pathlib import Path
import socket
import subprocess
import sys
import textwrap
import time

import pytest

from pentapod_sim.errors import RunError
from pentapod_sim.scenario import network
from pentapod_sim.scenario.network import (
    check_environment,
    local_changes,
    loopback_profile,
    OPEN_VAR,
    process_sockets,
    RANGE_VAR,
    Socket,
)

ROOT = Path(__file__).resolve().parents[1]
PROFILE_VAR = 'FASTRTPS_DEFAULT_PROFILES_FILE'
#: Variables of the network set-up, removed from the session's environment where a test
#: starts from a user's bare environment.
NETWORK_VARS = (RANGE_VAR, 'ROS_LOCALHOST_ONLY', 'ROS_STATIC_PEERS', OPEN_VAR,
                *network.PROFILE_VARS)


def bare_env(**extra: str) -> dict[str, str]:
    """The session's environment without any network variable, plus ``extra``."""
    env = {k: v for k, v in os.environ.items() if k not in NETWORK_VARS}
    path = [str(ROOT)] + ([env['PYTHONPATH']] if env.get('PYTHONPATH') else [])
    env.update(extra, PYTHONPATH=os.pathsep.join(path))
    return env


def descendants(pid: int) -> list[int]:
    """``pid`` and every process below it."""
    parents = {}
    for stat in Path('/proc').glob('[0-9]*/stat'):
        try:
            parents[int(stat.parent.name)] = int(stat.read_text().rsplit(')', 1)[1].split()[1])
        except (OSError, IndexError, ValueError):
            pass
    found, todo = [], [pid]
    while todo:
        found.append(todo.pop())
        todo += [p for p, parent in parents.items() if parent == found[-1]]
    return found


def command(pid: int) -> str:
    try:
        return Path(f'/proc/{pid}/cmdline').read_bytes().decode().replace('\0', ' ')
    except OSError:
        return ''


# -- the rules ---------------------------------------------------------------------------------
@pytest.mark.parametrize(('env', 'expect'), [
    ({}, 'profile'),
    ({RANGE_VAR: 'LOCALHOST'}, 'profile'),
    ({'ROS_LOCALHOST_ONLY': '1'}, 'profile+only'),
    ({RANGE_VAR: 'OFF'}, 'profile-off'),
    ({RANGE_VAR: 'SUBNET'}, None),
    ({RANGE_VAR: 'SYSTEM_DEFAULT'}, None),
    ({RANGE_VAR: 'LOCALHOST', 'ROS_STATIC_PEERS': '192.168.1.20'}, None),
    ({PROFILE_VAR: '/home/user/my_dds.xml'}, None),
    ({'RMW_IMPLEMENTATION': 'rmw_cyclonedds_cpp'}, 'localhost'),
    ({'RMW_IMPLEMENTATION': 'rmw_cyclonedds_cpp', RANGE_VAR: 'LOCALHOST'}, None),
], ids=['unset', 'LOCALHOST', 'LOCALHOST_ONLY', 'OFF', 'SUBNET', 'SYSTEM_DEFAULT',
        'static-peers', 'own-profile', 'cyclone-unset', 'cyclone-LOCALHOST'])
def test_local_discovery_gets_the_loopback_profile(env, expect):
    profile = str(loopback_profile())
    want = {
        'profile': {PROFILE_VAR: profile, RANGE_VAR: 'SYSTEM_DEFAULT'},
        'profile+only': {PROFILE_VAR: profile, RANGE_VAR: 'SYSTEM_DEFAULT',
                         'ROS_LOCALHOST_ONLY': '0'},
        'profile-off': {PROFILE_VAR: profile},          # OFF kept
        'localhost': {RANGE_VAR: 'LOCALHOST'},
        None: {}}[expect]
    assert local_changes(env) == want
    merged = {**env, **want}
    assert local_changes(merged) == {}                          # applied once, then stable
    if expect in ('profile', 'profile+only', 'profile-off'):
        check_environment(merged)                               # confined: not refused


def test_the_exported_profile_with_localhost_becomes_system_default():
    """tools/env.sh exported the profile, a later LOCALHOST would add the RMW's transport."""
    env = {PROFILE_VAR: str(loopback_profile()), RANGE_VAR: 'LOCALHOST'}
    assert 'LOCALHOST' in network.exposure(env)
    assert local_changes(env) == {RANGE_VAR: 'SYSTEM_DEFAULT'}


@pytest.mark.parametrize('env', [
    {RANGE_VAR: 'SUBNET'}, {RANGE_VAR: 'SYSTEM_DEFAULT'},
    {RANGE_VAR: 'LOCALHOST', 'ROS_STATIC_PEERS': '192.168.1.20'},
    {PROFILE_VAR: '/home/user/my_dds.xml', RANGE_VAR: 'SYSTEM_DEFAULT'},
    {PROFILE_VAR: 'LOOPBACK', RANGE_VAR: 'LOCALHOST'}])
def test_an_open_run_is_refused_unless_opened_explicitly(env):
    env = {k: (str(loopback_profile()) if v == 'LOOPBACK' else v) for k, v in env.items()}
    with pytest.raises(RunError, match=f'open to the network.*{OPEN_VAR}=1') as err:
        check_environment(env)
    assert '\n' not in str(err.value)
    check_environment({**env, OPEN_VAR: '1'})
    check_environment({**env, 'ROS_SECURITY_ENABLE': 'true', 'ROS_SECURITY_STRATEGY': 'Enforce'})
    with pytest.raises(RunError):          # Permissive runs unsecured when files are missing
        check_environment({**env, 'ROS_SECURITY_ENABLE': 'true',
                           'ROS_SECURITY_STRATEGY': 'Permissive'})


def test_process_sockets_reads_addresses_like_ss():
    """Sockets bound here are found with their address; only 127/8 and ::1 count as loopback."""
    made = []
    for family, host in ((socket.AF_INET, '0.0.0.0'), (socket.AF_INET, '127.0.0.2'),
                         (socket.AF_INET6, '::1')):
        sock = socket.socket(family, socket.SOCK_DGRAM)
        sock.bind((host, 0))
        made.append(sock)
    listener = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    listener.bind(('127.0.0.1', 0))
    listener.listen()
    made.append(listener)
    try:
        found = {(s.protocol, s.address, s.port): s.loopback for s in process_sockets()}
        want = {('udp', '0.0.0.0', made[0].getsockname()[1]): False,
                ('udp', '127.0.0.2', made[1].getsockname()[1]): True,
                ('udp6', '::1', made[2].getsockname()[1]): True,
                ('tcp', '127.0.0.1', made[3].getsockname()[1]): True}
        assert {k: found.get(k) for k in want} == want
    finally:
        for sock in made:
            sock.close()
    assert not Socket('udp6', '::', 1, 0).loopback
    assert Socket('udp6', '::ffff:127.0.0.1', 1, 0).loopback
    assert not Socket('udp', '239.255.0.1', 7400, 0).loopback


# -- real processes ----------------------------------------------------------------------------
PROBE = textwrap.dedent("""
    import rclpy
    from pentapod_sim.errors import RunError
    from pentapod_sim.scenario import network
    rclpy.init()
    node = rclpy.create_node('socket_probe')
    node.create_subscription(__import__('std_msgs.msg').msg.String, '/probe', print, 1)
    try:
        network.check_sockets()
        print('ACCEPTED')
    except RunError as err:
        print('REFUSED', err)
    node.destroy_node()
    rclpy.shutdown()
""")


@pytest.mark.ros
@pytest.mark.parametrize(('extra', 'verdict'), [
    ('isolated', 'ACCEPTED'),
    ({RANGE_VAR: 'LOCALHOST'}, 'REFUSED'),
    ({RANGE_VAR: 'LOCALHOST', OPEN_VAR: '1'}, 'ACCEPTED'),
], ids=['loopback-profile', 'localhost-without-profile', 'opened'])
def test_the_socket_check_sees_what_dds_really_bound(extra, verdict):
    """
    A participant with LOCALHOST discovery alone binds 0.0.0.0 and the host's addresses.

    The check reads the process's own sockets, so a profile that does not take effect (or an
    RMW that adds transports, as rmw_fastrtps does for LOCALHOST) cannot pass unnoticed.
    """
    env = dict(os.environ) if extra == 'isolated' else bare_env(**extra)
    out = subprocess.run([sys.executable, '-c', PROBE], env=env, capture_output=True,
                         text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split()[0] == verdict, out.stdout
    if verdict == 'REFUSED':
        assert '0.0.0.0:' in out.stdout and 'loopback' in out.stdout


@pytest.mark.ros
@pytest.mark.slow
def test_a_default_run_binds_nothing_outside_the_loopback(tmp_path):
    """
    Plant, exciter, damper and recorder as separate processes: every socket on 127.0.0.0/8.

    Read mid-run (the plant is stepping and the recorder writing), over the runner and every
    process below it; ``ss -uanp`` and ``ss -tanp`` lines of those processes go to the log.
    """
    from test_stopping import scenario
    path = scenario(tmp_path, steps=2_000_000)
    log = tmp_path / 'run.log'
    env = dict(os.environ, TMPDIR=str(tmp_path), PYTHONUNBUFFERED='1',
               RCUTILS_LOGGING_BUFFERED_STREAM='0')
    for name in NETWORK_VARS:          # a user's bare shell: the runner's defaults apply
        env.pop(name, None)
    with open(log, 'w') as out:
        runner = subprocess.Popen([sys.executable, '-m', 'pentapod_sim.scenario.runner',
                                   str(path), '--timeout', '300'], stdout=out,
                                  stderr=subprocess.STDOUT, env=env, start_new_session=True)
    try:
        end = time.monotonic() + 120
        while 'lockstep run of' not in log.read_text():
            assert runner.poll() is None and time.monotonic() < end, log.read_text()
            time.sleep(0.2)
        time.sleep(2.0)                # steps and recording under way
        pids = descendants(runner.pid)
        names = {p: command(p) for p in pids}
        nodes = {p: name for p, name in names.items() if '.nodes.' in name}
        assert len(nodes) == 4, nodes
        sockets = {p: process_sockets(p) for p in pids}
        listing = subprocess.run(['ss', '-uanp'], capture_output=True, text=True).stdout + \
            subprocess.run(['ss', '-tanp'], capture_output=True, text=True).stdout
        print('\n'.join(line for line in listing.splitlines()
                        if any(f'pid={p},' in line for p in pids)))
    finally:
        runner.terminate()
        runner.wait(timeout=60)
    for pid in nodes:      # each node has its DDS sockets (the listing is not empty)
        assert any(s.protocol == 'udp' for s in sockets[pid]), (nodes[pid], sockets[pid])
    outside = {names[p]: [str(s) for s in found if not s.loopback]
               for p, found in sockets.items()}
    assert {k: v for k, v in outside.items() if v} == {}


@pytest.mark.ros
@pytest.mark.parametrize('module', ['pentapod_sim.scenario.runner',
                                    'pentapod_sim.nodes.plant_node'])
def test_an_open_run_stops_before_any_node_with_one_line(tmp_path, module):
    """SUBNET discovery without the flag: the runner (or a node run alone) names the way out."""
    from fixtures.demo_model import demo_model
    model = demo_model(4).save(tmp_path / 'model.npz')
    path = tmp_path / 'alone.yaml'
    path.write_text(f"plant:\n  ros__parameters:\n    model_file: {model}\n    steps: 10\n"
                    "    sources: ['']\n")
    args = [str(path)] if module.endswith('runner') else ['--ros-args', '--params-file', str(path)]
    out = subprocess.run([sys.executable, '-m', module, *args], cwd=tmp_path, timeout=120,
                         env=bare_env(**{RANGE_VAR: 'SUBNET'}), capture_output=True, text=True)
    assert out.returncode == 1, out.stdout + out.stderr
    lines = [line for line in out.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith('error: DDS would be open to the network: '
                                                   'ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET'), lines
    assert f'{OPEN_VAR}=1' in lines[0] and 'Traceback' not in out.stdout + out.stderr
    assert 'lockstep run of' not in out.stdout + out.stderr
