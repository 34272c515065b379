"""
docs/nodes.md, "Writing your own controller", run from a folder outside the package.

The page's controller module, its parameter table, its scenario and its commands run as a new
user would run them.

The files and commands are read from the page (:mod:`fixtures.user_docs`), written to a
temporary folder that is only on ``PYTHONPATH``, and run. Two additions keep the cost within
CI's budget: the scenario run and the judge use a small plant (``--model-file``, and
``--steps``), and the judge a short battery (``--config``: 1 s multisine period, one
direction, no reference law). What the page shows must then hold:

* ``--help`` prints the parameter table as the page shows it;
* the scenario run records a bag in which every answer is ``u_k = -gain v_x,k`` with the
  scenario's gain and the recorded TCP velocity of the same step;
* ``judge`` passes it, the damping of each dominant mode agrees with the sampled loop's
  eigenvalues (plant matrices and the gain, numpy only) within 3 %, and the black-box loop
  check agrees with the exact one on the model the controller publishes.
"""
import csv
import os
from pathlib import Path
import subprocess
import sys

import numpy as np
import pytest
import test_judge
import yaml

from fixtures import user_docs
from fixtures.demo_model import demo_model
from pentapod_sim.analysis.bag.reader import Bag
from pentapod_sim.interface import force_topic, port_location
from pentapod_sim.registry import executables

pytestmark = [pytest.mark.ros, pytest.mark.slow]
ROOT = Path(__file__).resolve().parents[1]
RATE = test_judge.RATE

#: test_judge's short battery (a small plant settles within one period), with a lower bar
#: for the best peak reduction: the page's controller damps x only, at a modest gain.
_battery = yaml.safe_load(test_judge.SETTINGS)
_battery['thresholds']['best_peak_reduction_min'] = 1.0
SETTINGS = yaml.safe_dump(_battery, sort_keys=False)


def _argv(words):
    """A command of the page as this interpreter runs it (an executable: its module)."""
    if words[0] == 'python':
        return [sys.executable, *words[1:]]
    module = executables()[words[0]].split(':')[0]
    return [sys.executable, '-m', module, *words[1:]]


def _command(name):
    found = [w for w in user_docs.commands() if name in (w[0], w[-1])]
    assert len(found) == 1, user_docs.commands()
    return found[0]


@pytest.fixture(scope='module')
def lab(tmp_path_factory):
    tmp = tmp_path_factory.mktemp('docs_controller')
    paths = user_docs.write(tmp)
    assert set(paths) == {'my_lab/controllers.py', 'lab.yaml'}
    plant = demo_model(4, f_min=40.0, f_max=160.0, zeta=0.02)
    plant.save(tmp / 'small.npz')
    (tmp / 'judge.yaml').write_text(SETTINGS)
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(
        [str(tmp), str(ROOT), os.environ.get('PYTHONPATH', '')]))
    return tmp, env, plant


def _run(lab, argv, timeout=600):
    tmp, env, _ = lab
    proc = subprocess.run(argv, env=env, capture_output=True, text=True, timeout=timeout,
                          cwd=tmp)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return proc


def test_the_page_shows_the_parameter_table_help_prints(lab):
    proc = _run(lab, _argv(_command('--help')), timeout=120)
    shown = user_docs.blocks('text')
    assert shown
    for line in shown[0].splitlines():
        assert line in proc.stdout.splitlines(), (line, proc.stdout)


def test_the_pages_scenario_runs_the_pages_controller(lab):
    """The recorded answers are -gain times the recorded TCP velocity, step by step."""
    tmp, _, _ = lab
    gain = yaml.safe_load((tmp / 'lab.yaml').read_text())['lab']['ros__parameters']['gain']
    _run(lab, _argv(_command('scenario')) + ['--model-file', str(tmp / 'small.npz'),
                                             '--steps', '400'])
    bags = list((tmp / 'out' / 'bags').glob('lab-*'))
    assert len(bags) == 1
    bag = Bag(bags[0])
    topic, joint, field = port_location('tcp_velocity_x')
    v_x = bag.series(f'{topic}.{field}.{joint}')
    u_x = bag.series(f'{force_topic("lab")}.effort.tcp_force_x')
    assert len(u_x.values) == len(v_x.values) == 400
    assert np.array_equal(u_x.time_ns, v_x.time_ns)
    assert np.abs(v_x.values).max() > 0
    assert np.allclose(u_x.values, -gain * v_x.values, rtol=1e-12, atol=0.0)


def _loop_damping(plant, gain, f_hz):
    """Damping ratio of the sampled loop u_k = -gain v_x,k pole nearest f_hz (numpy only)."""
    a, b, c, d = plant.discrete_matrices(1.0 / RATE)
    i, j = plant.input_names.index('tcp_force_x'), plant.output_names.index('tcp_velocity_x')
    assert d[j, i] == 0.0
    s = np.log(np.linalg.eigvals(a - gain * np.outer(b[:, i], c[j]))) * RATE
    s = s[s.imag > 0]
    near = s[np.argmin(np.abs(s.imag / (2 * np.pi) - f_hz))]
    return -near.real / abs(near)


def test_the_pages_judge_command_passes_the_controller(lab):
    tmp, _, plant = lab
    gain = yaml.safe_load((tmp / 'lab.yaml').read_text())['lab']['ros__parameters']['gain']
    proc = _run(lab, _argv(_command('judge')) + [
        '--config', str(tmp / 'judge.yaml'), '--model-file', str(tmp / 'small.npz'),
        '--out', str(tmp / 'out' / 'judge')])
    assert 'lab: pass' in proc.stdout, proc.stdout
    page = tmp / 'out' / 'judge' / 'lab'
    assert (page / 'report.md').stat().st_size > 0 and (page / 'report.html').is_file()
    with open(page / 'numbers.csv', newline='') as f:
        numbers = list(csv.DictReader(f))
    damping = [r for r in numbers if r['table'].endswith('damping per mode')]
    f_meas = [float(r['value']) for r in damping if r['column'] == 'f lab']
    z_meas = [float(r['value']) for r in damping if r['column'] == 'zeta lab']
    assert f_meas and len(f_meas) == len(z_meas)
    for f, z in zip(f_meas, z_meas):
        assert z == pytest.approx(_loop_damping(plant, gain, f), rel=0.03), (f, z)
    agree = [r for r in numbers if r['table'] == 'summary' and r['column'] == 'criterion'
             and r['value'].startswith('black box and exact check agree')]
    assert agree, 'the published model was not checked'
