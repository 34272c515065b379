"""
A user's own controller class, in a module outside the package, runs in a scenario file.

The module is written to a temporary folder (on ``PYTHONPATH`` only, never in the package),
defines its own parameter class next to its node class, and a scenario names it with
``node_class: module:Class``. The same file runs as separate processes (the runner starts the
class with ``python -m pentapod_sim.nodes.component``) and composed (one process, its checked
values handed over as parameter overrides); both runs apply ``u = -gain v_x`` exactly and give
the same trace bit for bit.
"""
import os
from pathlib import Path
import subprocess
import sys

import numpy as np
import pytest

from fixtures import user_docs
from fixtures.demo_model import demo_model

RATE = 5000.0
GAIN = 300.0

#: The controller module of docs/nodes.md, "Writing your own controller", as the page shows it.
CONTROLLER = user_docs.files()['my_lab/controllers.py']


@pytest.fixture
def lab(tmp_path):
    """The user's package folder (outside this checkout) and a scenario that uses its class."""
    package = tmp_path / 'lab_code' / 'my_lab'
    package.mkdir(parents=True)
    (package / '__init__.py').write_text('')
    (package / 'controllers.py').write_text(CONTROLLER)
    model_file = demo_model(4).save(tmp_path / 'model.npz')
    scenario = tmp_path / 'lab.yaml'
    scenario.write_text(f"""
/**:
  ros__parameters:
    sample_rate: {RATE}
plant:
  ros__parameters:
    model_file: {model_file}
    steps: 300
    sources: [exciter, lab]
    source_ports:
      lab: [tcp_force_x]
    startup_timeout: 60.0
exciter:
  ros__parameters:
    kind: impulse
    amplitude: 20.0
lab:
  ros__parameters:
    node_class: my_lab.controllers:LabDamper
    gain: {GAIN}
""")
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(
        [str(package.parent), str(Path(__file__).resolve().parents[1]),
         os.environ.get('PYTHONPATH', '')]))
    return scenario, env


def _run(scenario, env, tmp_path, *args, timeout=180):
    return subprocess.run([sys.executable, '-m', 'pentapod_sim.scenario.runner', str(scenario),
                           *args], env=env, capture_output=True, text=True, timeout=timeout,
                          cwd=tmp_path)


def test_a_users_class_runs_in_separate_processes_and_composed(lab, tmp_path):
    scenario, env = lab
    listed = _run(scenario, env, tmp_path, '--list')
    assert listed.returncode == 0, listed.stderr
    assert 'lab: component (my_lab.controllers:LabDamper)' in listed.stdout
    traces = []
    for mode in ([], ['--composed']):
        trace = tmp_path / f'trace{len(traces)}.npz'
        proc = _run(scenario, env, tmp_path, '--output-file', str(trace), *mode)
        assert proc.returncode == 0, proc.stdout + proc.stderr
        traces.append(np.load(trace))
    run = traces[0]
    names = list(run['output_names'])
    v_x = run['y'][:, names.index('tcp_velocity_x')]
    x = list(run['input_names']).index('tcp_force_x')
    assert run['u'][0, x] == 20.0 - GAIN * v_x[0]
    assert np.array_equal(run['u'][1:, x], -GAIN * v_x[1:])   # the impulse is one sample
    assert np.abs(v_x).max() > 0
    for key in ('y', 'u'):
        assert np.array_equal(traces[0][key], traces[1][key]), key


def test_a_users_class_is_checked_before_any_node_starts(lab, tmp_path):
    scenario, env = lab
    scenario.write_text(scenario.read_text().replace(f'gain: {GAIN}', 'gain: -1.0'))
    proc = _run(scenario, env, tmp_path, '--timeout', '60')
    assert proc.returncode == 1
    assert proc.stderr.strip().splitlines() == [
        f"error: {scenario}: node 'lab' (my_lab.controllers:LabDamper): parameter gain = -1.0 "
        'N s/m: must lie in [0, 1e+06]'], proc.stderr


def test_the_component_host_prints_a_users_parameters(lab, tmp_path):
    _, env = lab
    proc = subprocess.run([sys.executable, '-m', 'pentapod_sim.nodes.component',
                           'my_lab.controllers:LabDamper', '--help'], env=env,
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.startswith('usage: ros2 run pentapod_testbed component '
                                  'my_lab.controllers:LabDamper ')
    assert "The lab's TCP damper in x: u = -gain * v_x." in proc.stdout
    assert '  gain (double; default 100.0; unit N s/m; [0, 1e+06]; read-only)' in proc.stdout
