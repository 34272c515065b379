"""
``judge`` on a user's controller: a plain rclpy node in a package outside this checkout.

The user's module is written to a temporary folder (on ``PYTHONPATH`` only): a plain
:class:`rclpy.node.Node` subclass, no testbed base class, publishing no linear model, that
answers ``u_k = -gain * y_{k - delay}`` on one port from one sensor. The judge runs it composed
with a small plant in recorded lockstep runs and writes its verdict; the figures it rests on
are checked against computations that share nothing with the judge:

* the damping ratio of the dominant TCP mode against the eigenvalues of the sampled loop
  (plant matrices and the gain, numpy only);
* the return-difference margin of the black-box loop check against python-control's
  ``stability_margins`` of the same loop;
* a strut damper stable on the reduced plant only thanks to truncation (the spectral radius
  on the check model, :func:`pentapod_sim.sim.stability.check_loop`) must fail, and so must a
  TCP damper that answers three samples late (eigenvalues of the delayed loop).
"""
import csv
import dataclasses
import os
from pathlib import Path
import signal
import subprocess
import sys

import control
import numpy as np
import pytest
from statespace_fixtures import small_model

from fixtures.demo_model import demo_model
from pentapod_damper.study.analytic import SampledPairFrf
from pentapod_sim.plant.build import load_reduction_config, plant_from_fe
from pentapod_sim.plant.check_model import check_model_from_fe
from pentapod_sim.plant.frf_peaks import maximise_near_poles
from pentapod_sim.sim.controllers import DiscreteController
from pentapod_sim.sim.stability import check_loop, STABLE, TRUNCATION

RATE = 2000.0
DT = 1.0 / RATE
ROOT = Path(__file__).resolve().parents[1]

CONTROLLER = '''
"""A lab's own damper: a plain rclpy node, not part of the testbed package."""
from collections import deque

from rclpy.node import Node
from sensor_msgs.msg import JointState

from pentapod_sim.interface import force_topic, port_location
from pentapod_sim.nodes.common import FORCE_QOS, STATE_SUB_QOS


class PlainDamper(Node):
    """u_k = -gain * y_(k - delay) on one input port from one plant output."""

    def __init__(self, **kwargs):
        super().__init__('plain_damper', **kwargs)
        self.gain = self.declare_parameter('gain', 100.0).value
        delay = self.declare_parameter('delay', 0).value
        self.port = self.declare_parameter('port', 'tcp_force_x').value
        sensor = self.declare_parameter('sensor', 'tcp_velocity_x').value
        source = self.declare_parameter('source_name', 'lab').value
        topic, self.joint, self.field = port_location(sensor)
        self.pub = self.create_publisher(JointState, force_topic(source), FORCE_QOS)
        self.create_subscription(JointState, topic, self.on_state, STATE_SUB_QOS)
        self.past = deque([0.0] * delay)
        self.last = None

    def on_state(self, msg):
        stamp = (msg.header.stamp.sec, msg.header.stamp.nanosec)
        if self.last is not None and self.last[0] == stamp:   # re-sent step: same answer
            self.pub.publish(self.last[1])
            return
        self.past.append(getattr(msg, self.field)[msg.name.index(self.joint)])
        answer = JointState(name=[self.port], effort=[-self.gain * self.past.popleft()])
        answer.header.stamp = msg.header.stamp
        self.pub.publish(answer)
        self.last = (stamp, answer)
'''

SETTINGS = f"""
positions: [P1]
sample_rate: {RATE}
reference: ''
directions: [x]
operation: aluminium_half_down
multisine:
  band: [10.0, 400.0]
  period: 1.0
  amplitude: 10.0
  periods: 2
  time_constants: 3.0
  settle_modes: 2
identification:
  modes: 2
  max_order: 40
  pair_tolerance: 0.05
robustness:
  amplitude: 10.0
  duration: 2.0
  nperseg: 512
  check_f_min: 500.0
thresholds:
  damping_min_gain: 0.95
  peak_reduction_min: 0.95
  rms_reduction_min: 0.95
  best_peak_reduction_min: 1.5
  stable_depth_gain_min: 1.0
  force_limit: 1000.0
  force_limit_share_max: 0.001
  margin_min: 0.05
  coherence_min: 0.95
  stable_with_delay: false
  rejected_max: 0
  missing_max: 0
"""

TCP_GAIN = 2.0e4
#: Stable at once (spectral radius 0.9968), unstable three samples late (1.0703).
LATE_GAIN = 1.0e5


@pytest.fixture(scope='module')
def lab(tmp_path_factory):
    """The user's package (outside this checkout), the judge's settings, the models."""
    tmp = tmp_path_factory.mktemp('judge')
    package = tmp / 'lab_code' / 'my_lab'
    package.mkdir(parents=True)
    (package / '__init__.py').write_text('')
    (package / 'plain.py').write_text(CONTROLLER)
    (tmp / 'judge.yaml').write_text(SETTINGS)
    (tmp / 'judge_1k.yaml').write_text(SETTINGS.replace(f'sample_rate: {RATE}',
                                                        'sample_rate: 1000.0'))
    demo = demo_model(4, f_min=40.0, f_max=160.0, zeta=0.02)
    demo.save(tmp / 'demo.npz')
    fe = small_model()
    cfg = load_reduction_config()
    plant, _ = plant_from_fe(fe, dataclasses.replace(cfg, modes_f_max=200.0))
    check = check_model_from_fe(fe, cfg, 2000.0).select(plant.input_names, plant.output_names)
    plant.save(tmp / 'struts.npz')
    check.save(tmp / 'struts_check.npz')
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(
        [str(package.parent), str(ROOT), os.environ.get('PYTHONPATH', '')]))
    return tmp, env, {'demo': demo, 'struts': plant, 'struts_check': check}


def _judge(lab, name, params, *args, model='demo', config='judge.yaml'):
    tmp, env, _ = lab
    (tmp / f'{name}.yaml').write_text(''.join(f'{k}: {v}\n' for k, v in params.items()))
    proc = subprocess.run(
        [sys.executable, '-m', 'pentapod_damper.judge', 'my_lab.plain:PlainDamper',
         '--params', str(tmp / f'{name}.yaml'), '--source', 'lab',
         '--config', str(tmp / config), '--model-file', str(tmp / f'{model}.npz'),
         '--out', str(tmp / name), *args],
        env=env, capture_output=True, text=True, timeout=600, cwd=tmp)
    page = tmp / name / 'PlainDamper'
    numbers = []
    if (page / 'numbers.csv').exists():
        with open(page / 'numbers.csv', newline='') as f:
            numbers = list(csv.DictReader(f))
    return proc, page, numbers


def _summary(numbers, start):
    """The summary row whose criterion starts with ``start``: {column: value}."""
    out, current = [], {}
    for r in numbers:
        if r['table'] != 'summary':
            continue
        if r['column'] == 'criterion' and current:
            out.append(current)
            current = {}
        current[r['column']] = r['value']
        current['position'] = r['row']
    out.append(current)
    found = [row for row in out if row.get('criterion', '').startswith(start)]
    assert found, [row.get('criterion') for row in out]
    return found[0]


def _loop_eigenvalues(plant, sensor, port, gain, delay=0):
    """Eigenvalues of the sampled loop u_k = -gain y_(k - delay) (numpy only)."""
    a, b, c, d = plant.discrete_matrices(DT)
    i, j = plant.input_names.index(port), plant.output_names.index(sensor)
    assert d[j, i] == 0.0
    n = a.shape[0]
    # state (x, y_(k-1), ..., y_(k-delay)); u_k = -gain * (oldest, or c x if no delay)
    size = n + delay
    big = np.zeros((size, size))
    big[:n, :n] = a
    if delay == 0:
        big[:n, :n] -= gain * np.outer(b[:, i], c[j])
    else:
        big[:n, size - 1] = -gain * b[:, i]
        big[n, :n] = c[j]
        for k in range(1, delay):
            big[n + k, n + k - 1] = 1.0
    return np.linalg.eigvals(big)


def test_a_plain_node_outside_the_package_is_judged_from_its_recordings(lab):
    """A TCP velocity damper: verdict pass, damping and margin as computed independently."""
    _, _, models = lab
    proc, page, numbers = _judge(lab, 'tcp', {'gain': TCP_GAIN, 'port': 'tcp_force_x',
                                              'sensor': 'tcp_velocity_x'})
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert 'runs left' in proc.stdout and 'PlainDamper: pass' in proc.stdout
    for name in ('report.md', 'report.html', 'numbers.csv'):
        assert (page / name).stat().st_size > 0
    html = (page / 'report.html').read_text()
    assert 'data:image/png;base64,' in html and '<img src="figures' not in html
    # damping of the dominant TCP x mode: the loop's eigenvalue nearest the measured frequency
    plant = models['demo']
    s = np.log(_loop_eigenvalues(plant, 'tcp_velocity_x', 'tcp_force_x', TCP_GAIN)) / DT
    s = s[s.imag > 0]
    damping = [r for r in numbers if r['table'].endswith('damping per mode')]
    f_meas = [float(r['value']) for r in damping if r['column'] == 'f PlainDamper']
    z_meas = [float(r['value']) for r in damping if r['column'] == 'zeta PlainDamper']
    z_open = [float(r['value']) for r in damping if r['column'] == 'zeta baseline']
    assert f_meas and len(f_meas) == len(z_meas)
    for f, z in zip(f_meas, z_meas):
        near = s[np.argmin(np.abs(s.imag / (2 * np.pi) - f))]
        assert z == pytest.approx(-near.real / abs(near), rel=0.03), (f, z)
    assert max(z / z0 for z, z0 in zip(z_meas, z_open)) > 1.3     # it does damp
    # margin of the black-box loop: min |1 + gain P(z)| on the unit circle (python-control)
    a, b, c, _ = plant.discrete_matrices(DT)
    i, j = plant.input_names.index('tcp_force_x'), plant.output_names.index('tcp_velocity_x')
    loop = control.ss(a, b[:, [i]], c[[j]], [[0.0]], DT) * TCP_GAIN
    stability_margin = control.stability_margins(loop)[2]
    row = _summary(numbers, 'return-difference margin')
    assert float(row['PlainDamper'].split()[0]) == pytest.approx(stability_margin, rel=0.02)
    assert _summary(numbers, 'sampled loop with the identified')['PlainDamper'].startswith(
        'stable')


def test_a_controller_answering_five_samples_late_is_judged_failing(lab):
    """A slowly diverging delayed loop: Nyquist counts its eigenvalues outside the circle."""
    tmp, _, models = lab
    lam = _loop_eigenvalues(models['demo'], 'tcp_velocity_x', 'tcp_force_x', TCP_GAIN, 5)
    assert np.abs(_loop_eigenvalues(models['demo'], 'tcp_velocity_x', 'tcp_force_x',
                                    TCP_GAIN)).max() < 1.0
    outside = int(np.sum(np.abs(lam) > 1.0))
    assert outside > 0 and np.abs(lam).max() < 1.01     # grows slowly: the short run ends
    settings = (tmp / 'judge.yaml').read_text().replace('duration: 2.0', 'duration: 0.5')
    (tmp / 'judge_short.yaml').write_text(settings.replace('nperseg: 512', 'nperseg: 256'))
    proc, _, numbers = _judge(lab, 'late', {'gain': TCP_GAIN, 'delay': 5},
                              '--sections', 'robustness', '--ports', 'tcp_force_x',
                              config='judge_short.yaml')
    assert proc.returncode == 3, proc.stdout + proc.stderr
    assert 'PlainDamper: FAIL' in proc.stdout
    row = _summary(numbers, 'sampled loop with the identified')
    assert row['PlainDamper'] == 'unstable' and row['verdict'] == 'FAIL'
    poles = [r for r in numbers if r['table'].endswith('loop checks')
             and r['row'] == 'PlainDamper, plant (4 modes)' and r['column'] == 'unstable poles']
    assert [int(r['value']) for r in poles] == [outside]


def test_a_controller_whose_loop_diverges_is_judged_failing_not_an_error(lab):
    """Three samples late at a high gain: the plant refuses its efforts; FAIL with the reason."""
    _, _, models = lab
    for delay, stable in ((0, True), (3, False)):
        lam = _loop_eigenvalues(models['demo'], 'tcp_velocity_x', 'tcp_force_x', LATE_GAIN,
                                delay)
        assert (np.abs(lam).max() < 1.0) == stable, delay
    proc, _, numbers = _judge(lab, 'diverging', {'gain': LATE_GAIN, 'delay': 3},
                              '--sections', 'robustness', '--ports', 'tcp_force_x')
    assert proc.returncode == 3, proc.stdout + proc.stderr
    assert 'PlainDamper: FAIL' in proc.stdout
    ended = _summary(numbers, 'run demo_PlainDamper_robustness ended early')
    assert ended['verdict'] == 'FAIL'
    rejected = _summary(numbers, 'answers the plant rejected')
    assert int(rejected['PlainDamper']) > 0 and rejected['verdict'] == 'FAIL'


def test_a_strut_damper_stable_only_thanks_to_truncation_fails(lab):
    """High-gain collocated strut bending damper: stable on the plant, not on the check model."""
    tmp, _, models = lab
    gain = 3000.0
    ctrl = DiscreteController.static(['strut1_bending_rate_2'], ['strut1_bending_moment_2'],
                                     [[-gain]])
    exact = check_loop(models['struts'], models['struts_check'], [ctrl], 1e-3, policy='warn')
    assert exact.verdict == TRUNCATION
    proc, _, numbers = _judge(lab, 'strut', {'gain': gain, 'port': 'strut1_bending_moment_2',
                                             'sensor': 'strut1_bending_rate_2'},
                              '--sections', 'robustness', '--ports', 'strut1_bending_moment_2',
                              '--check-model', str(tmp / 'struts_check.npz'),
                              model='struts', config='judge_1k.yaml')
    assert proc.returncode == 3, proc.stdout + proc.stderr
    row = _summary(numbers, 'sampled loop with the identified')
    assert row['PlainDamper'] == TRUNCATION and row['verdict'] == 'FAIL'
    # the same damper at low gain passes the same check
    exact = check_loop(models['struts'], models['struts_check'],
                       [DiscreteController.static(['strut1_bending_rate_2'],
                                                  ['strut1_bending_moment_2'], [[-10.0]])],
                       1e-3, policy='warn')
    assert exact.verdict == STABLE
    proc, _, numbers = _judge(lab, 'strut_low', {'gain': 10.0,
                                                 'port': 'strut1_bending_moment_2',
                                                 'sensor': 'strut1_bending_rate_2'},
                              '--sections', 'robustness', '--ports', 'strut1_bending_moment_2',
                              '--check-model', str(tmp / 'struts_check.npz'),
                              model='struts', config='judge_1k.yaml')
    row = _summary(numbers, 'sampled loop with the identified')
    assert row['PlainDamper'] == STABLE and row['verdict'] == 'pass', proc.stdout + proc.stderr


def test_a_built_in_law_gets_the_black_box_and_the_exact_check_and_they_agree(lab):
    """The damper node publishes its model: identified and exact verdicts and margins agree."""
    from pentapod_damper.laws import strut_bending_damper
    from pentapod_sim.sim.stability import controller_of
    tmp, env, models = lab
    gain = 3000.0
    law = controller_of(strut_bending_damper([1], gain))
    exact = check_loop(models['struts'], models['struts_check'], [law], 1e-3, policy='warn')
    (tmp / 'damper.yaml').write_text(f'bending_struts: [1]\nbending_gain: {gain}\n')
    proc = subprocess.run(
        [sys.executable, '-m', 'pentapod_damper.judge', 'damper', '--params',
         str(tmp / 'damper.yaml'), '--config', str(tmp / 'judge_1k.yaml'), '--sections',
         'robustness,buildable', '--model-file', str(tmp / 'struts.npz'), '--check-model',
         str(tmp / 'struts_check.npz'), '--out', str(tmp / 'damper')],
        env=env, capture_output=True, text=True, timeout=600, cwd=tmp)
    assert (tmp / 'damper' / 'damper' / 'numbers.csv').exists(), proc.stdout + proc.stderr
    with open(tmp / 'damper' / 'damper' / 'numbers.csv', newline='') as f:
        numbers = list(csv.DictReader(f))
    assert proc.returncode == (0 if exact.verdict == STABLE else 3), proc.stdout + proc.stderr
    assert 'white noise on ' + ', '.join(law.actuator_ports) + ' (' in (
        tmp / 'damper' / 'damper' / 'report.md').read_text()   # its ports, known without a run
    assert _summary(numbers, 'black box and exact check agree')['verdict'] == 'pass'
    assert _summary(numbers, 'sampled loop with the identified')['damper'] == exact.verdict
    loops = {(r['row'], r['column']): r['value'] for r in numbers
             if r['table'].endswith('loop checks')}
    for name in (f'damper, plant ({models["struts"].n_modes} modes)',
                 f'damper, check ({models["struts_check"].n_modes} modes)'):
        assert float(loops[(name, 'margin')]) == pytest.approx(
            float(loops[(name, 'model margin')]), rel=0.05, abs=0.01), name
    # its row of the buildable-damper table: the check margin is 1 - the exact check's
    # spectral radius, the peak reduction that of the exact peaks of the sampled loop
    built = {r['column']: r['value'] for r in numbers
             if r['table'].endswith('as a buildable damper')}
    assert built.pop('stroke unit') == 'rad/N'          # a bending moment pair's rotation
    built = {k: float(v) for k, v in built.items() if v}
    assert built['check margin'] == pytest.approx(1.0 - exact.check_radius, abs=1e-9)
    peaks = []
    for laws in ([], [strut_bending_damper([1], gain)]):
        frf = SampledPairFrf(models['struts'], laws, 1e-3, 'tcp_displacement_x', 'tcp_force_x')
        peaks.append(maximise_near_poles(lambda f, h=frf: np.abs(h(f)), frf.poles,
                                         10.0, 400.0).value)
    assert built['peak reduction'] == pytest.approx(peaks[0] / peaks[1], rel=1e-6)


def test_compare_judges_two_controllers_side_by_side(lab):
    """``--compare A B``: one page each, the other in its reference column."""
    tmp, env, _ = lab
    proc = subprocess.run(
        [sys.executable, '-m', 'pentapod_damper.judge', '--compare', 'my_lab.plain:PlainDamper',
         'example_controller', '--config', str(tmp / 'judge.yaml'), '--sections', 'robustness',
         '--ports', 'tcp_force_x', '--model-file', str(tmp / 'demo.npz'),
         '--out', str(tmp / 'compare')],
        env=env, capture_output=True, text=True, timeout=600, cwd=tmp)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    for page, other in (('PlainDamper', 'example_controller'),
                        ('example_controller', 'PlainDamper')):
        text = (tmp / 'compare' / page / 'report.md').read_text()
        header = next(line for line in text.splitlines() if line.startswith('| position'))
        assert f'| {page} | {other} |' in header, header


def test_refused_answers_leave_out_the_expected_copies_of_a_re_sent_step():
    """``rejected_by_reason``: stale and duplicate copies are no fault; older bags count all."""
    from pentapod_damper.judge.demand import _refused
    assert _refused({'rejected_messages': '25', 'rejected_by_reason':
                     'disturbance/duplicate=22,lab/limit=3'}) == 3
    assert _refused({'rejected_messages': '2', 'rejected_by_reason':
                     'disturbance/duplicate=1,plaindamper/stale=1'}) == 0
    assert _refused({'rejected_messages': '0', 'rejected_by_reason': ''}) == 0
    assert _refused({'rejected_messages': '4'}) == 4


def test_a_command_in_its_own_process_is_judged_as_the_composed_class(lab):
    """``--command``: separate processes, the same lockstep loop: the same identified margin."""
    tmp, env, _ = lab
    command = (f'{sys.executable} -m pentapod_sim.nodes.component my_lab.plain:PlainDamper '
               f'--ros-args -p gain:={TCP_GAIN} -p source_name:=lab')
    runs = {}
    for how, args in (('command', ['--command', command]),
                      ('class', ['my_lab.plain:PlainDamper', '--params',
                                 str(tmp / 'gain.yaml')])):
        (tmp / 'gain.yaml').write_text(f'gain: {TCP_GAIN}\n')
        proc = subprocess.run(
            [sys.executable, '-m', 'pentapod_damper.judge', *args, '--source', 'lab',
             '--config', str(tmp / 'judge.yaml'), '--sections', 'robustness', '--ports',
             'tcp_force_x', '--model-file', str(tmp / 'demo.npz'), '--out', str(tmp / how)],
            env=env, capture_output=True, text=True, timeout=600, cwd=tmp)
        assert proc.returncode == 0, proc.stdout + proc.stderr
        page = next((tmp / how).glob('*/numbers.csv'))
        with open(page, newline='') as f:
            runs[how] = _summary(list(csv.DictReader(f)), 'return-difference margin')
    assert 'separate processes' in (tmp / 'command' / 'lab' / 'report.md').read_text()
    assert runs['command']['lab'] == runs['class']['PlainDamper']


def test_the_csv_names_the_unit_of_a_row_that_has_its_own():
    """'xx peak at [Hz]' in a table of um/N columns: its cells are in Hz."""
    from pentapod_damper.judge.document import Column, csv_text, Table
    table = Table('compliance', [Column('quantity'), Column('a', 'um/N'), Column('b', '-')])
    table.add('xx peak', 1.5, 2.0)
    table.add('xx peak at [Hz]', 26.7, None)
    rows = list(csv.reader(csv_text([table]).splitlines()))
    assert rows == [['compliance', 'xx peak', 'a', '1.5', 'um/N'],
                    ['compliance', 'xx peak', 'b', '2.0', '-'],
                    ['compliance', 'xx peak at [Hz]', 'a', '26.7', 'Hz'],
                    ['compliance', 'xx peak at [Hz]', 'b', '', '-']]


def test_mode_labels_give_the_fe_number_its_cause_and_the_tcp_direction():
    """A plant that left FE mode 3 out: its third mode is FE mode 4, with that mode's cause."""
    from pentapod_damper.judge.models import mode_labels
    plant = demo_model(3, inputs=['tcp_force_x', 'tcp_force_y', 'tcp_force_z'])
    plant.meta.update(kept_modes=[1, 2, 4], mode_causes=['frame', 'struts', 'feed_drives',
                                                         'bp_joints'])
    rows = [plant.output_names.index(f'tcp_displacement_{a}') for a in 'xyz']
    plant.c_disp[rows, 2] = [0.1, -0.7, 0.3]
    third = mode_labels(plant)[2]
    assert (third.plant_mode, third.fe_mode, third.cause, third.tcp_direction) == (
        3, 4, 'bp_joints', 'y')
    assert third.text() == 'FE 4 (plant 3), bp_joints, y'


def test_a_node_that_already_runs_is_judged_with_node(lab):
    """``--node``: a controller started by the user as its own process answers the judge's runs."""
    tmp, env, models = lab
    log = open(tmp / 'node.log', 'w')
    node = subprocess.Popen(
        [sys.executable, '-m', 'pentapod_sim.nodes.component', 'my_lab.plain:PlainDamper',
         '--ros-args', '-p', f'gain:={TCP_GAIN}', '-p', 'source_name:=lab'],
        env=env, stdout=log, stderr=subprocess.STDOUT, cwd=tmp)
    try:
        proc = subprocess.run(
            [sys.executable, '-m', 'pentapod_damper.judge', '--node', 'plain_damper',
             '--source', 'lab', '--config', str(tmp / 'judge.yaml'), '--sections',
             'damping,robustness', '--ports', 'tcp_force_x', '--model-file',
             str(tmp / 'demo.npz'),
             '--out', str(tmp / 'node')],
            env=env, capture_output=True, text=True, timeout=600, cwd=tmp)
        assert node.poll() is None, (tmp / 'node.log').read_text()  # it outlives the runs
    finally:
        node.send_signal(signal.SIGINT)
        node.wait(timeout=20)
        log.close()
    assert proc.returncode == 0, proc.stdout + proc.stderr + (tmp / 'node.log').read_text()
    with open(tmp / 'node' / 'plain_damper' / 'numbers.csv', newline='') as f:
        numbers = list(csv.DictReader(f))
    plant = models['demo']
    a, b, c, _ = plant.discrete_matrices(DT)
    i, j = plant.input_names.index('tcp_force_x'), plant.output_names.index('tcp_velocity_x')
    margin = control.stability_margins(control.ss(a, b[:, [i]], c[[j]], [[0.0]], DT)
                                       * TCP_GAIN)[2]
    row = _summary(numbers, 'return-difference margin')
    assert float(row['plain_damper'].split()[0]) == pytest.approx(margin, rel=0.02)
