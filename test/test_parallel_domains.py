"""
A parallel test session (``pytest -n``, tools/test.sh) gives each worker a ROS domain of its own.

xdist starts its workers from the controller, which reserved a domain and exported it; a worker
that kept it would share it with the other worker, and one test's spoofer or plant would be a
foreign writer in the other's run. Here two workers each run two tests that report their
domain and who holds it, at the same time (each waits until the other worker has reported).
"""
import os
from pathlib import Path
import subprocess
import sys

ROOT = Path(__file__).resolve().parents[1]

PROBE = """
import os, time
from pathlib import Path


def _report(name):
    out = Path(os.environ['PROBE_DIR'])
    (out / f"{os.environ['PYTEST_XDIST_WORKER']}_{name}").write_text(os.environ['ROS_DOMAIN_ID'])
    end = time.monotonic() + 60
    while len(list(out.iterdir())) < 2 and time.monotonic() < end:   # both workers alive
        time.sleep(0.05)


def test_a():
    _report('a')


def test_b():
    _report('b')
"""


def test_each_worker_of_a_parallel_session_has_its_own_domain(tmp_path):
    (tmp_path / 'test_probe.py').write_text(PROBE)
    out = tmp_path / 'out'
    out.mkdir()
    env = {k: v for k, v in os.environ.items()
           if k not in ('ROS_DOMAIN_ID', 'PENTAPOD_TEST_SESSION_DOMAIN', 'PYTEST_XDIST_WORKER')}
    env.update(PROBE_DIR=str(out), PYTHONPATH=str(ROOT))
    proc = subprocess.run([sys.executable, '-m', 'pytest', '-q', '-p', 'no:cacheprovider',
                           '-p', 'conftest', '-n', '2', '--dist', 'load', 'test_probe.py'],
                          cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    domains = {p.name: p.read_text() for p in out.iterdir()}
    workers = {name.split('_')[0] for name in domains}
    assert workers == {'gw0', 'gw1'}, domains
    per_worker = {w: {d for n, d in domains.items() if n.startswith(w)} for w in workers}
    assert all(len(d) == 1 for d in per_worker.values()), per_worker
    assert per_worker['gw0'] != per_worker['gw1'], per_worker
