"""What a sweep worker imports, and how the local workers are started."""
import json
from pathlib import Path
import subprocess
import sys

import numpy as np

from pentapod_damper.sweep import runner
from pentapod_damper.sweep.compute import compute_batch
from pentapod_damper.sweep.settings import make_settings
from pentapod_damper.sweep.warm import WORKER_MODULE

ROOT = Path(__file__).resolve().parents[1]

#: Packages a worker must not import for a pose: ROS, plotting, the client's store, progress
#: bar and cluster code. matplotlib is allowed only where python-control itself imports it
#: (control.timeplot imports matplotlib.pyplot; the sweep cannot avoid that).
FORBIDDEN = ('rclpy', 'rosidl_runtime_py', 'matplotlib', 'pyarrow', 'pandas', 'tqdm', 'dask',
             'distributed', 'gmsh')
OWN_FORBIDDEN = ('pentapod_damper.sweep.sweep_plot', 'pentapod_damper.sweep.store',
                 'pentapod_damper.sweep.runner', 'pentapod_damper.nodes', 'pentapod_sim.nodes')

#: Run in a fresh interpreter: every import statement naming a forbidden package is recorded
#: with the file that wrote it (exec'd code counts as the file that ran it), unless it is
#: matplotlib imported from python-control or from matplotlib itself (with its mpl_toolkits);
#: then the forbidden modules that ended up loaded by any route.
SCRIPT = """
import builtins, json, os, sys
sys.path.insert(0, {root!r})
FORBIDDEN = {forbidden!r}
ALLOWED = tuple(os.sep + p + os.sep for p in ('control', 'matplotlib', 'mpl_toolkits'))
real_import, hits = builtins.__import__, []

def spy(name, globals=None, locals=None, fromlist=(), level=0):
    if level == 0 and name.split('.')[0] in FORBIDDEN:
        frame = sys._getframe(1)   # the import statement's file: skip exec'd code
        while frame.f_back is not None and frame.f_code.co_filename.startswith('<'):
            frame = frame.f_back
        caller = frame.f_code.co_filename
        if not (name.split('.')[0] == 'matplotlib' and any(a in caller for a in ALLOWED)):
            hits.append([name, caller])
    return real_import(name, globals, locals, fromlist, level)

builtins.__import__ = spy
import {module}
loaded = sorted(m for m in sys.modules
                if m.split('.')[0] in FORBIDDEN and m.split('.')[0] != 'matplotlib'
                or m.startswith({own!r}))
print(json.dumps({{'hits': hits, 'loaded': loaded}}))
"""


def test_worker_entry_point_imports_no_ros_plotting_or_client_code():
    """A fresh `import pentapod_damper.sweep.compute` pulls in none of the forbidden packages."""
    script = SCRIPT.format(root=str(ROOT), forbidden=FORBIDDEN, module=WORKER_MODULE,
                           own=OWN_FORBIDDEN)
    out = subprocess.run([sys.executable, '-c', script], capture_output=True, text=True,
                         cwd=ROOT, check=True, timeout=300)
    found = json.loads(out.stdout.strip().splitlines()[-1])
    assert found['hits'] == [], found['hits']
    assert found['loaded'] == [], found['loaded']


def test_local_workers_are_forked_only_with_single_threaded_blas(monkeypatch):
    """Fork on Linux with OPENBLAS/OMP_NUM_THREADS=1 at import, else spawn."""
    monkeypatch.setattr(runner, 'BLAS_SINGLE_THREADED', True)
    assert runner.start_method() == ('fork' if sys.platform.startswith('linux') else 'spawn')
    monkeypatch.setattr(runner, 'BLAS_SINGLE_THREADED', False)
    assert runner.start_method() == 'spawn'


def test_forked_workers_do_not_import_again_and_every_phase_is_timed(tmp_path):
    """
    A 2-worker run from this (tools/env.sh) process forks, and each phase is timed.

    Its workers find the pose code loaded (a fresh import takes over 0.5 s).
    """
    settings = make_settings(['strut_damping_12'], [1.0], n_points=200)
    poses = np.array([[0.0, 0.0, 0.85, 0.0, 0.0], [0.05, 0.0, 0.85, 0.0, 0.0]])
    report = runner.run_sweep(poses, settings, tmp_path, n_workers=2, progress=False,
                              compute=compute_batch)
    assert report.counts == {'ok': 2} and report.workers == 2
    timings = report.timings
    assert timings['start method'] == 'fork'
    assert 0.0 <= timings['worker imports'] < 0.05
    for phase in ('cluster start', 'scatter', 'tasks', 'store', 'progress', 'close'):
        assert 0.0 <= timings[phase] <= report.seconds, phase
