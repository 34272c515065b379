"""
The plant's truncation check at start-up and its periodic run status, as a ROS user meets them.

Real processes (the scenario runner, like test/test_stopping.py) on the session's domain. The
spectral radii the plant reports are checked against loops closed here with python-control
(``c2d`` of the continuous modal plant, static velocity feedback), not the testbed's own loop
construction. The ROS-free pieces are in test/test_loop_check.py.
"""
import ast
import os
from pathlib import Path
import re
import subprocess

import control
from diagnostic_msgs.msg import DiagnosticStatus
import numpy as np
import pytest
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.serialization import deserialize_message
from std_msgs.msg import String
from test_stopping import Runner

from fixtures.demo_model import demo_model
from pentapod_damper.nodes.damper_node import DamperNode
from pentapod_sim import interface
from pentapod_sim.analysis.bag.reader import open_bag
from pentapod_sim.nodes.common import spin_until
from pentapod_sim.nodes.source_model import MODEL_QOS
from pentapod_sim.plant.model import PlantModel
from pentapod_sim.scenario.files import dump_params
from pentapod_sim.sim.controllers import DiscreteController

RATE = 2000.0
TCP = (['tcp_velocity_x', 'tcp_velocity_y'], ['tcp_force_x', 'tcp_force_y'])
RADIUS = re.compile(r'spectral radius ([0-9.eE+-]+)')


def python_control_radius(plant, sensors, actuators, gains, dt) -> float:
    """Spectral radius of u = -b v closed on the ZOH plant, built with python-control."""
    m = plant.n_modes
    a = np.block([[np.zeros((m, m)), np.eye(m)],
                  [-np.diag(plant.omega ** 2), -np.diag(2 * plant.zeta * plant.omega)]])
    b = np.vstack([np.zeros_like(plant.b), plant.b])
    c = np.hstack([plant.c_disp, plant.c_vel])
    sysd = control.c2d(control.ss(a, b, c, plant.d), dt, 'zoh')
    ii = [plant.input_names.index(p) for p in actuators]
    oo = [plant.output_names.index(p) for p in sensors]
    assert not np.any(plant.d[oo]), 'sensed outputs with feed-through need u_{k-1} states'
    k = np.zeros((len(plant.input_names), len(plant.output_names)))
    k[ii, oo] = -np.asarray(gains, dtype=float)
    return float(np.abs(np.linalg.eigvals(sysd.A + sysd.B @ k @ sysd.C)).max())


def scenario(tmp_path: Path, gain: float, steps: int, loop_check: str, example=False,
             rate: float = RATE, **plant) -> Path:
    """Plant (demo model, no FE position) + exciter + TCP damper (+ example) + recorder."""
    model_file = demo_model(6, seed=4).save(tmp_path / 'model.npz')
    sources = ['exciter', 'damper'] + (['example'] if example else [])
    doc = {
        '/**': {'ros__parameters': {'sample_rate': rate}},
        'exciter': {'ros__parameters': {'kind': 'sine', 'amplitude': 20.0, 'frequency': 7.0,
                                        'duration': 1.0e6}},
        'damper': {'ros__parameters': {'tcp_directions': ['x', 'y'], 'tcp_gain': gain}},
        'plant': {'ros__parameters': {
            'model_file': str(model_file), 'steps': steps, 'sources': sources,
            'loop_check': loop_check, 'source_timeout': 5.0, 'startup_timeout': 60.0,
            'model_cache_dir': str(tmp_path / 'models'),
            'wait_for_subscribers': ['recorder'], **plant}},
        'recorder': {'ros__parameters': {'output_dir': str(tmp_path / 'bags'),
                                         'bag_name': 'run'}},
    }
    if example:
        doc['example_controller'] = {'ros__parameters': {'gain': 500.0}}
    path = tmp_path / 'scenario.yaml'
    path.write_text(dump_params(doc))
    return path


@pytest.fixture
def start(tmp_path):
    """Start the scenario runner on a file; killed at the end of the test."""
    made = []

    def run(path, *args):
        made.append(Runner(path, tmp_path, *args))
        return made[-1]
    yield run
    for runner in made:
        runner.kill_all()


def finish(run, timeout: float = 120.0) -> tuple[int, str]:
    try:
        code = run.proc.wait(timeout=timeout)
    except subprocess.TimeoutExpired:
        pytest.fail(f'the runner had not ended after {timeout} s:\n{run.text()}')
    return code, run.text()


# -- with ROS ------------------------------------------------------------------------------


@pytest.mark.ros
@pytest.mark.slow
def test_refuse_ends_an_unstable_loop_naming_its_spectral_radius(tmp_path, start):
    gain = 1.0e6                       # u = -b v: far beyond what 2 kHz sampling holds
    expected = python_control_radius(demo_model(6, seed=4), *TCP, [gain, gain], 1 / RATE)
    assert expected > 1.5
    code, out = finish(start(scenario(tmp_path, gain, 1000, 'refuse')))
    assert code != 0, out
    line = next(x for x in out.splitlines() if x.startswith('error: truncation check'))
    assert '(loop_check = refuse)' in line and 'is unstable' in line, line
    assert float(RADIUS.search(line).group(1)) == pytest.approx(expected, rel=1e-6)
    assert 'Traceback' not in out and 'lockstep run of' not in out, out


@pytest.mark.ros
@pytest.mark.slow
def test_warn_warns_loudly_and_runs(tmp_path, start):
    gain, steps = 1.0e6, 40
    expected = python_control_radius(demo_model(6, seed=4), *TCP, [gain, gain], 1 / RATE)
    code, out = finish(start(scenario(tmp_path, gain, steps, 'warn', max_state_norm=1e100,
                                          max_effort=1e100)))
    warning = next(x for x in out.splitlines() if '!!! truncation check (loop_check = warn)'
                   in x)
    assert '[WARN]' in warning and 'is unstable' in warning, warning
    assert float(RADIUS.search(warning).group(1)) == pytest.approx(expected, rel=1e-6)
    assert code == 0, out
    assert f'finished: ran {steps} of {steps} steps' in out, out


@pytest.mark.ros
@pytest.mark.slow
def test_stable_loop_logs_its_margin_names_unchecked_sources_and_reports_progress(
        tmp_path, start):
    """Damper checked, the example controller (no model) unchecked; run status in the bag."""
    gain, steps = 2000.0, 3000
    # the example controller's law is left out: the radius is the damper's loop alone
    expected = python_control_radius(demo_model(6, seed=4), *TCP, [gain, gain], 1 / RATE)
    code, out = finish(start(scenario(tmp_path, gain, steps, 'refuse', example=True,
                                          status_period=0.1)))
    assert code == 0, out
    line = next(x for x in out.splitlines() if 'truncation check in' in x)
    assert 'is stable on the plant (no check model)' in line, line
    radius = float(RADIUS.search(line).group(1))
    assert radius == pytest.approx(expected, rel=1e-5)
    assert f'margin {1 - expected:.3g}' in line, line
    assert 'open-loop sources: exciter' in line, line
    unchecked = next(x for x in out.splitlines() if 'gave no linear model' in x)
    assert 'source(s) example gave' in unchecked and 'published no model' in unchecked, unchecked
    assert 'damper' not in unchecked.split('gave no linear model')[0], unchecked

    bag = open_bag(tmp_path / 'bags' / 'run', topics=[interface.RUN_STATUS])
    msgs = [deserialize_message(p, DiagnosticStatus)
            for p in bag.topic(interface.RUN_STATUS).payloads]
    values = [{kv.key: kv.value for kv in m.values} for m in msgs]
    steps_seen = [int(v['steps']) for v in values]
    states = [v['state'] for v in values]
    assert len(values) >= 5, values
    assert steps_seen == sorted(steps_seen) and steps_seen[-1] == steps, steps_seen
    assert len(set(steps_seen)) >= 4, steps_seen           # progress between the messages
    assert states[-1] == 'finished' and set(states[:-1]) == {'running'}, states
    for v in values:
        assert set(interface.RUN_STATUS_KEYS + interface.RUN_PROGRESS_KEYS) <= set(v), v
        assert v['deadline_misses'] == '0', v              # lockstep
        assert int(v['rejected_messages']) >= 0
    # step_rate = steps per wall second since the previous message: the wall times it implies
    # add up to the time between the first and the last 'running' message in the bag
    times = bag.topic(interface.RUN_STATUS).log_time_ns / 1e9
    last = len(values) - 2
    implied = sum((steps_seen[i] - steps_seen[i - 1]) / float(values[i]['step_rate'])
                  for i in range(1, last + 1) if steps_seen[i] > steps_seen[i - 1])
    assert implied == pytest.approx(times[last] - times[0], rel=0.1, abs=0.05)


@pytest.mark.ros
@pytest.mark.slow
def test_a_loop_stable_only_thanks_to_truncation_is_refused_then_warned_about(tmp_path, start):
    """
    Truncation: a loop stable on the plant, unstable on the check model, refused or warned.

    P2 at 2 kHz, bending damper 500 N m s/rad on strut 1: stable on the plant, not on the check
    model (FE modes below 5 kHz). The first run builds and caches the check model and refuses;
    the second loads it (no second build) and runs with a warning.
    """
    cache = tmp_path / 'models'

    def real(loop_check):
        doc = {'/**': {'ros__parameters': {'sample_rate': RATE}},
               'exciter': {'ros__parameters': {'kind': 'impulse', 'amplitude': 10.0}},
               'damper': {'ros__parameters': {'bending_struts': [1], 'bending_gain': 500.0}},
               'plant': {'ros__parameters': {
                   'position': 'P2', 'model_cache_dir': str(cache), 'steps': 200,
                   'sources': ['exciter', 'damper'], 'loop_check': loop_check,
                   'startup_timeout': 120.0}}}
        path = tmp_path / f'{loop_check}.yaml'
        path.write_text(dump_params(doc))
        return finish(start(path), timeout=300.0)

    code, out = real('refuse')
    assert code != 0, out
    assert 'building the check model of P2 (FE modes below 5000 Hz)' in out, out
    line = next(x for x in out.splitlines() if x.startswith('error: truncation check'))
    assert 'is stable only thanks to truncation' in line, line
    plant = PlantModel.load(next(cache.glob('plant_P2_*.npz')))
    check = PlantModel.load(next(cache.glob('check_P2_5000hz_*.npz')))
    assert check.n_modes > 2 * plant.n_modes
    sensors, actuators = ['strut1_bending_rate_2', 'strut1_bending_rate_3'], [
        'strut1_bending_moment_2', 'strut1_bending_moment_3']
    on_plant = python_control_radius(plant, sensors, actuators, [500.0, 500.0], 1 / RATE)
    on_check = python_control_radius(check.select(plant.input_names, plant.output_names),
                                     sensors, actuators, [500.0, 500.0], 1 / RATE)
    assert on_plant < 1.0 < on_check
    radii = [float(r) for r in RADIUS.findall(line)] + [
        float(r) for r in re.findall(r'([0-9.]+) on the check model', line)]
    assert radii[0] == pytest.approx(on_plant, abs=5e-7), line      # printed: 6 digits
    assert radii[-1] == pytest.approx(on_check, abs=5e-6), line

    code, out = real('warn')
    assert 'building the check model' not in out and 'loaded cached' in out, out
    assert 'truncation check: result of an earlier run read from' in out, out
    warning = next(x for x in out.splitlines() if '!!! truncation check (loop_check = warn)'
                   in x)
    assert [float(r) for r in RADIUS.findall(warning)][0] == radii[0], warning
    assert f'{radii[-1]:g} on the check model' in warning, warning
    assert code == 0 and 'finished: ran 200 of 200 steps' in out, out


@pytest.mark.ros
@pytest.mark.slow
def test_realtime_run_status_counts_the_deadline_misses_of_the_trace(tmp_path, start):
    """20 kHz in real time on a shared machine: answers miss their periods, the status counts."""
    path = scenario(tmp_path, 2000.0, 10000, 'off', rate=20000.0, timing='realtime',
                    status_period=0.2, output_file=str(tmp_path / 'trace.npz'))
    code, out = finish(start(path))
    assert code == 0, out
    trace = np.load(tmp_path / 'trace.npz')
    misses = sum(ast.literal_eval(str(trace['misses_per_source'])).values())
    bag = open_bag(tmp_path / 'bags' / 'run', topics=[interface.RUN_STATUS])
    values = [{kv.key: kv.value for kv in deserialize_message(p, DiagnosticStatus).values}
              for p in bag.topic(interface.RUN_STATUS).payloads]
    assert values[-1]['state'] == 'finished' and values[-1]['steps'] == '10000'
    assert int(values[-1]['deadline_misses']) == misses > 0, (misses, out)
    running = [int(v['deadline_misses']) for v in values[:-1]]
    assert running == sorted(running) and running[-1] <= misses


@pytest.mark.ros
def test_a_damper_publishes_its_model_latched_and_again_after_a_gain_change():
    """A subscriber created after the publication gets the model; a new gain sends a new one."""
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=int(os.environ.get('ROS_DOMAIN_ID', '0')))
    nodes = []
    try:
        damper = DamperNode(context=ctx, cli_args=['--ros-args', '-p', "tcp_directions:=['x']",
                                                   '-p', 'tcp_gain:=700.0'])
        listener = Node('model_listener', context=ctx)
        nodes += [damper, listener]
        got = []
        listener.create_subscription(String, interface.controller_model_topic('damper'),
                                     lambda msg: got.append(msg.data), MODEL_QOS)
        executor = SingleThreadedExecutor(context=ctx)
        for node in nodes:
            executor.add_node(node)

        def gains():
            return [float(-DiscreteController.from_json(text).d[0, 0]) for text in got]
        assert spin_until(executor, lambda: len(got) >= 1, 10.0), got
        assert gains() == [700.0]
        assert damper.set_parameters([Parameter('tcp_gain', value=123.0)])[0].successful
        assert spin_until(executor, lambda: len(got) >= 2, 10.0), got
        assert gains() == [700.0, 123.0]
        model = DiscreteController.from_json(got[-1])
        assert model.sensor_ports == ('tcp_velocity_x',)
        assert model.actuator_ports == ('tcp_force_x',)
    finally:
        for node in nodes:
            node.destroy_node()
        rclpy.shutdown(context=ctx)
