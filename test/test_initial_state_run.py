"""
A lockstep run started at the periodic steady state (plant parameter ``initial_state_file``).

Composed and separate processes give the same run bit for bit; the recorded periods repeat
(no transient); the bag's metadata says where the plant started; a wrong file is one error line.
"""
from pathlib import Path
import re

import numpy as np
import pytest

from fixtures.demo_model import demo_model
from pentapod_damper.scenario_laws import scenario_laws
from pentapod_sim import interface
from pentapod_sim.analysis.bag.reader import open_bag
from pentapod_sim.scenario.files import dump_params, read_scenario
from pentapod_sim.scenario.runner import run_scenario
from pentapod_sim.sim.controllers import controller_of
from pentapod_sim.sim.excitation import Excitation, ExcitationSpec
from pentapod_sim.sim.multirate import MultiRatePlant
from pentapod_sim.sim.periodic_state import plant_periodic_state, save_initial_state

RATE, PERIOD, PERIODS = 2000.0, 0.25, 3
EXCITER = {'kind': 'multisine', 'amplitude': 10.0, 'direction': [1.0, 0.0, 0.0],
           'f_start': 8.0, 'f_end': 300.0, 'period': PERIOD, 'phases': 'schroeder',
           'settle_periods': 0, 'duration': PERIOD * PERIODS}
STEPS = int(RATE * PERIOD * PERIODS)


def _scenario(tmp_path: Path, x0_file: Path | str, tag: str) -> Path:
    model_file = demo_model(6, seed=4, zeta=0.001, feedthrough=1e-7).save(tmp_path / 'model.npz')
    doc = {'/**': {'ros__parameters': {'sample_rate': RATE}},
           'exciter': {'ros__parameters': dict(EXCITER)},
           'damper': {'ros__parameters': {'tcp_directions': ['y'], 'tcp_gain': 500.0}},
           'plant': {'ros__parameters': {
               'model_file': str(model_file), 'steps': STEPS, 'sources': ['exciter', 'damper'],
               'output_file': str(tmp_path / f'trace_{tag}.npz'), 'startup_timeout': 60.0,
               'initial_state_file': str(x0_file), 'wait_for_subscribers': ['recorder']}},
           'recorder': {'ros__parameters': {'output_dir': str(tmp_path / 'bags'),
                                            'bag_name': tag}}}
    path = tmp_path / f'scenario_{tag}.yaml'
    path.write_text(dump_params(doc))
    return path


def _steady_file(tmp_path: Path, path: Path) -> Path:
    """The periodic steady state of the plant and the damper's law under the multisine."""
    plant = MultiRatePlant.from_model(demo_model(6, seed=4, zeta=0.001, feedthrough=1e-7), RATE)
    laws = scenario_laws(read_scenario(path).sections, 1 / RATE)
    exc = Excitation(ExcitationSpec(**EXCITER), 1 / RATE)
    n = exc.period_steps
    e = np.zeros((n, len(plant.input_names)))
    e[:, plant.input_names.index('tcp_force_x')] = exc.series(n)[:, 0]
    state = plant_periodic_state(plant, [controller_of(law) for law in laws], e)
    return save_initial_state(tmp_path / 'x0.npz', state)


def test_composed_and_separate_runs_start_at_the_steady_state_alike(tmp_path):
    x0_file = tmp_path / 'x0.npz'
    draft = _scenario(tmp_path, '', 'draft')
    _steady_file(tmp_path, draft)
    traces = {}
    for tag, composed in (('composed', True), ('separate', False)):
        path = _scenario(tmp_path, x0_file, tag)
        assert run_scenario(path, {}, 300.0, log_dir=tmp_path / f'logs_{tag}',
                            composed=composed) == 0
        traces[tag] = dict(np.load(tmp_path / f'trace_{tag}.npz'))
        bag = open_bag(tmp_path / 'bags' / tag)
        assert bag.custom_data['pentapod_start.initial_state'] == f'file {x0_file}'
        assert bag.topic(interface.TCP_STATE).count == STEPS
    for key in ('y', 'u', 'x_final'):
        assert np.array_equal(traces['composed'][key], traces['separate'][key]), key
    # the recorded periods repeat: no transient of the plant (the law starts at rest, but
    # a static gain has no state), to rounding
    y = traces['composed']['y'][:, 0]
    n = int(RATE * PERIOD)
    assert np.abs(y).max() > 0
    assert np.abs(y[-n:] - y[:n]).max() < 1e-9 * np.abs(y).max()
    # a run from rest rings: the check can fail
    rest = _scenario(tmp_path, '', 'rest')
    assert run_scenario(rest, {}, 300.0, log_dir=tmp_path / 'logs_rest', composed=True) == 0
    y0 = np.load(tmp_path / 'trace_rest.npz')['y'][:, 0]
    assert np.abs(y0[-n:] - y0[:n]).max() > 1e-3 * np.abs(y0).max()
    assert open_bag(tmp_path / 'bags' / 'rest').custom_data[
        'pentapod_start.initial_state'] == 'rest'


@pytest.mark.parametrize('content,message', [('not a zip', 'is not readable as .npz'),
                                             (np.zeros(5), 'needs \\(12,\\)')])
def test_a_wrong_initial_state_file_is_one_named_error(tmp_path, content, message):
    bad = tmp_path / 'bad.npz'
    if isinstance(content, str):
        bad.write_text(content)
    else:
        np.savez(bad, x=content)
    path = _scenario(tmp_path, bad, 'bad')
    code = run_scenario(path, {}, 120.0, log_dir=tmp_path / 'logs', composed=True)
    assert code != 0
    log = (tmp_path / 'logs').glob('*.log')
    errors = [line for f in log for line in f.read_text().splitlines()
              if line.startswith('error:') and 'initial state file' in line]
    assert errors and all('Traceback' not in e for e in errors), errors
    assert re.search(message, errors[0]), errors
