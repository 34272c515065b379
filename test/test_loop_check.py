"""
The ROS-free pieces of the plant's start-up truncation check and of its run status.

The model a source publishes must compute what the source computes: the stacked models of a
damper node's laws and the ideal PMA's model are stepped here against the laws' own ``step``.
The JSON round trip of a controller is tested in test/test_stability.py.
"""
import logging
import signal

import numpy as np
import pytest

from fixtures.demo_model import demo_model
from fixtures.stopping import stop_handlers  # noqa: F401  (a fixture)
from pentapod_damper.node_parameters import damper_laws, pma_law
from pentapod_sim import interface, shutdown
from pentapod_sim.errors import ConfigError
from pentapod_sim.nodes import loop_check
from pentapod_sim.nodes.loop_check import sort_models
from pentapod_sim.nodes.run_status import status_values
from pentapod_sim.nodes.source_model import model_text
from pentapod_sim.recording.run_end import RunStatus
from pentapod_sim.sim.controllers import controller_of, DiscreteController, parallel

DT = 1 / 4000.0


def step_model(ctrl: DiscreteController, sensors: np.ndarray) -> np.ndarray:
    """Efforts of a controller for a sequence of sensor vectors (rows), from rest."""
    x = np.zeros(ctrl.n_states)
    out = []
    for y in sensors:
        out.append(ctrl.c @ x + ctrl.d @ y)
        x = ctrl.a @ x + ctrl.b @ y
    return np.array(out)


def test_a_damper_nodes_model_computes_what_its_laws_compute():
    params = {'bending_struts': [1, 4], 'tcp_directions': ['x', 'z'], 'tcp_gain': 3000.0,
              'axial_struts': [2], 'filter_order': 2, 'bandwidth_hz': 400.0, 'delay_steps': 1}
    laws = list(damper_laws(params, dt=DT).values())
    model = parallel([controller_of(law) for law in laws])
    assert model.sensor_ports == tuple(p for law in laws for p in law.sensor_ports)
    assert model.actuator_ports == tuple(p for law in laws for p in law.actuator_ports)
    assert model.n_states == sum(controller_of(law).n_states for law in laws) > 0
    sensors = np.random.default_rng(3).standard_normal((200, len(model.sensor_ports)))
    by_laws, start = [], 0
    for law in laws:
        n = len(law.sensor_ports)
        by_laws.append(np.array([law.step(y) for y in sensors[:, start:start + n]]))
        start += n
    np.testing.assert_allclose(step_model(model, sensors), np.hstack(by_laws),
                               rtol=1e-12, atol=1e-12 * np.abs(sensors).max() * 3000.0)


def test_the_ideal_pmas_model_computes_its_force_and_a_limited_one_has_none():
    law = pma_law({'directions': ['x', 'y'], 'proof_mass': 2.0, 'gain': 500.0}, DT)
    sensors = np.random.default_rng(1).standard_normal((50, 2)) * 1e-3
    text = model_text(lambda: controller_of(law))
    model = DiscreteController.from_json(text)
    np.testing.assert_allclose(step_model(model, sensors), [law.step(y) for y in sensors],
                               rtol=1e-12)
    limited = pma_law({'directions': ['x'], 'stroke_limit': 0.01}, DT)
    text = model_text(lambda: controller_of(limited))
    assert text.startswith(interface.NO_LINEAR_MODEL) and 'no linear discrete model' in text
    assert model_text(lambda: 1 / 0, feedback=False) == interface.NO_FEEDBACK


def test_models_are_sorted_and_bad_ones_named():
    plant = demo_model(3, inputs=['tcp_force_x', 'tcp_force_y'])
    good = DiscreteController.static(['tcp_velocity_x'], ['tcp_force_x'], [[-100.0]])
    stray = DiscreteController.static(['strut1_bending_rate_2'], ['strut1_bending_moment_2'],
                                      [[-1.0]])
    models, open_loop, unchecked = sort_models({
        'damper': good.to_json(), 'exciter': interface.NO_FEEDBACK, 'user': None,
        'pma': f'{interface.NO_LINEAR_MODEL}: limits', 'broken': '{"a": [[1]]}',
        'elsewhere': stray.to_json()}, plant)
    assert list(models) == ['damper']
    np.testing.assert_array_equal(models['damper'].d, good.d)
    assert open_loop == ['exciter']
    assert sorted(unchecked) == ['broken', 'elsewhere', 'pma', 'user']
    assert 'published no model' in unchecked['user']
    assert unchecked['pma'] == f'{interface.NO_LINEAR_MODEL}: limits'
    assert 'not a controller description' in unchecked['broken']
    assert 'strut1_bending_rate_2' in unchecked['elsewhere']


def test_status_values_carry_every_key_and_the_recorder_parses_them():
    values = status_values('running', 3, 1e-3, ['/clock', '/pentapod/forces/damper'], 1234.5,
                           2, 7)
    assert set(values) == set(interface.RUN_STATUS_KEYS + interface.RUN_PROGRESS_KEYS)
    assert values['last_stamp_ns'] == str(2_000_000)          # t_2 = 2 ms
    assert float(values['step_rate']) == 1234.5
    assert (values['deadline_misses'], values['rejected_messages']) == ('2', '7')
    assert values['rejected_by_reason'] == ''
    status = RunStatus.from_values(values)
    assert (status.state, status.steps, status.dt, status.ended) == ('running', 3, 1e-3, False)
    assert status_values('finished', 0, 1e-3, [], 0.0, 0, 0)['last_stamp_ns'] == '-1'


def test_an_empty_parallel_model_and_bad_shapes():
    with pytest.raises(ConfigError, match='shape'):
        DiscreteController(['tcp_velocity_x'], ['tcp_force_x'], [[0.5]], [[1.0, 2.0]],
                           [[1.0]], [[0.0]])
    one = DiscreteController.static(['tcp_velocity_x'], ['tcp_force_x'], [[-5.0]])
    assert parallel([one]).n_states == 0
    np.testing.assert_array_equal(parallel([one, one]).d, np.diag([-5.0, -5.0]))


class _Models:
    """The plant's model subscriptions, standing in: the damper's model is in at once."""

    def __init__(self, text: str, stop_while_waiting: bool):
        self.text, self.stop = text, stop_while_waiting

    def wait(self, executor):
        if self.stop:
            shutdown.request(signal.SIGINT)
        return {'damper': self.text}


@pytest.mark.usefixtures('stop_handlers')
@pytest.mark.parametrize('when', ['waiting for the models', 'building the check model'])
def test_a_stop_during_the_truncation_check_skips_the_rest_of_it(monkeypatch, when):
    """
    SIGINT while the plant waits for its models or builds its check model skips the rest.

    No eigenvalue problem follows (seconds that could outlast the runner's grace before its
    SIGKILL).
    """
    plant = demo_model(3, inputs=['tcp_force_x', 'tcp_force_y'])
    law = DiscreteController.static(['tcp_velocity_x'], ['tcp_force_x'], [[-100.0]])
    check = loop_check.TruncationCheck(
        _Models(law.to_json(), when == 'waiting for the models'), plant, DT, 'refuse', 1 / DT,
        5000.0, 'unused', logging.getLogger('plant'))
    built = []

    def build(self):
        built.append(True)
        shutdown.request(signal.SIGINT)
        return None, ''

    def solved(*args):
        raise AssertionError('the eigenvalue problem ran after the stop request')
    monkeypatch.setattr(loop_check.TruncationCheck, 'check_model', build)
    monkeypatch.setattr(loop_check.TruncationCheck, 'result', solved)
    assert check.at_start(executor=None) is None
    assert built == ([] if when == 'waiting for the models' else [True])


@pytest.mark.usefixtures('stop_handlers')
def test_a_stop_during_the_eigenvalue_problem_ends_the_check_at_once(monkeypatch, tmp_path):
    """
    SIGINT while the loop's eigenvalues are solved ends the check within a poll slice.

    The stand-in solve sleeps 10 s without the GIL, as LAPACK does; the stop comes after 0.3 s.
    """
    import threading
    import time
    plant = demo_model(3, inputs=['tcp_force_x', 'tcp_force_y'])
    law = DiscreteController.static(['tcp_velocity_x'], ['tcp_force_x'], [[-100.0]])
    check = loop_check.TruncationCheck(_Models(law.to_json(), False), plant, DT, 'refuse',
                                       1 / DT, 5000.0, str(tmp_path), logging.getLogger('plant'))
    solving = threading.Event()

    def slow_check(*args):
        solving.set()
        time.sleep(10)
        raise AssertionError('the check was waited for')
    monkeypatch.setattr(loop_check.TruncationCheck, 'check_model',
                        lambda self: (plant, 'check.npz'))
    monkeypatch.setattr(loop_check, 'check_loop', slow_check)
    threading.Timer(0.3, lambda: shutdown.request(signal.SIGINT)).start()
    start = time.monotonic()
    assert check.at_start(executor=None) is None
    assert solving.is_set()
    assert time.monotonic() - start < 2.0
    assert not list(tmp_path.glob('loop_check_*.json'))     # nothing kept of an unsolved check


@pytest.mark.usefixtures('stop_handlers')
def test_unless_requested_gives_the_result_or_the_error_of_the_work():
    assert shutdown.unless_requested(lambda: 42) == 42
    with pytest.raises(ZeroDivisionError):
        shutdown.unless_requested(lambda: 1 / 0)
    ran = []
    shutdown.request(signal.SIGTERM)
    assert shutdown.unless_requested(lambda: ran.append(1)) is None
    assert ran == []            # a stop already requested: the work does not start


_FINISH = """
import sys, threading, time
from pentapod_sim import shutdown
release = threading.Event()
shutdown.install()
def work():
    release.wait({hold})
    return 1
threading.Timer(0.2, shutdown.request).start()
assert shutdown.unless_requested(work, name='long work') is None
print('given up', flush=True)
code = shutdown.finish(7, wait=0.5)
print('returned', code, flush=True)
sys.exit(code + 1)
"""


@pytest.mark.parametrize('hold, code, said', [(0.3, 8, 'returned 7'),
                                              (60.0, 7, 'exiting with long work still')])
def test_a_process_ends_with_its_code_whether_or_not_given_up_work_still_runs(hold, code, said):
    """Work ending within the wait: finish returns; still running: the process exits at once."""
    import subprocess
    import sys
    import time
    start = time.monotonic()
    proc = subprocess.run([sys.executable, '-c', _FINISH.format(hold=hold)],
                          capture_output=True, text=True, timeout=30)
    out = proc.stdout + proc.stderr
    assert proc.returncode == code, out
    assert 'given up' in out and said in out, out
    assert time.monotonic() - start < 20.0      # not the 60 s of the work
