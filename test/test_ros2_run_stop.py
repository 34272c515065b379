"""
SIGTERM to ``ros2 run`` stops its node too (issue 25, item 3).

ros2run (Jazzy) runs the node with ``subprocess.Popen`` and waits; it forwards Ctrl-C but not
SIGTERM, which ends ros2run alone. The ros2 CLI is not a wheel, so a stand-in named ``ros2``
does what ros2run's ``run_executable`` does (Popen, wait); the node recognises its parent by
the command line ``ros2 run ...``, as it recognises the real one.
"""
import os
import signal
import subprocess
import sys
import time

import pytest

pytestmark = [pytest.mark.ros, pytest.mark.slow]

ROS2 = """
import subprocess, sys
proc = subprocess.Popen([sys.executable, '-m', 'pentapod_damper.nodes.damper_node',
                         '--ros-args', '-p', 'tcp_directions:=[x]'],
                        stdout=open(sys.argv[-1], 'w'), stderr=subprocess.STDOUT)
print(proc.pid, flush=True)
sys.exit(proc.wait())
"""


def alive(pid: int) -> bool:
    try:
        stat = open(f'/proc/{pid}/stat').read()
    except OSError:
        return False
    return stat.rsplit(')', 1)[1].split()[0] != 'Z'


def test_sigterm_to_ros2_run_leaves_no_node_behind(tmp_path):
    (tmp_path / 'ros2').write_text(ROS2)
    log = tmp_path / 'damper.log'
    ros2 = subprocess.Popen([sys.executable, str(tmp_path / 'ros2'), 'run', 'pentapod_testbed',
                             'damper', str(log)], stdout=subprocess.PIPE, text=True,
                            start_new_session=True)
    node = int(ros2.stdout.readline())
    try:
        end = time.monotonic() + 60.0
        while 'dampers on' not in log.read_text() and time.monotonic() < end:
            time.sleep(0.1)
        assert alive(node), log.read_text()
        os.kill(ros2.pid, signal.SIGTERM)          # a supervisor stops ros2 run alone
        assert ros2.wait(timeout=10) == -signal.SIGTERM
        end = time.monotonic() + 10.0
        while alive(node) and time.monotonic() < end:
            time.sleep(0.1)
        assert not alive(node), 'the node outlived ros2 run'
        assert 'Traceback' not in log.read_text()
    finally:
        if alive(node):
            os.kill(node, signal.SIGKILL)
