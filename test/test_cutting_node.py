"""
The cutting node in processes and composed: the offline cut bit for bit; recorded cuts.

Recorded cuts reproduce the analytic stability limit (issue 27, "done when", on a small modal
model).

The model is two TCP modes (150 and 170 Hz, 4 and 5 % damping) so that a cut settles or
chatters within half a second. The lobes come from the sampled loop of the scenario's laws
(statespace lobes' functions), the speed and the run lengths from
:func:`pentapod_sim.machining.loop_lobes.check_runs`; each run is a composed scenario with a
recorder, judged by ``analyze chatter`` on its bag.
"""
import csv
import math
import os

import numpy as np
import pytest

from fixtures.processes import NodeProcesses
from pentapod_sim.analysis.bag.cutting_record import cut_record
from pentapod_sim.analysis.bag.reader import open_bag
from pentapod_sim.cli import analyze
from pentapod_sim.interface import force_topic
from pentapod_sim.machining.cutting_process import simulate_cut
from pentapod_sim.machining.loop_lobes import check_runs, loop_lobes
from pentapod_sim.machining.materials import load_machining
from pentapod_sim.machining.tcp_frf import tcp_plant, TcpMode
from pentapod_sim.nodes.parameter_tables import CuttingParams
from pentapod_sim.scenario.cutting import record_cut
from pentapod_sim.scenario.files import dump_params
from pentapod_sim.scenario.laws import scenario_loop_laws
from pentapod_sim.scenario.warm_start import WarmStarter

pytestmark = [pytest.mark.ros, pytest.mark.slow]

RATE = 10000.0
OPERATION = 'aluminium_half_down'
PLANT = tcp_plant([TcpMode(150.0, 0.04, 4e6, (1.0, 0.3)), TcpMode(170.0, 0.05, 5e6, (-0.3, 1.0))])
DAMPER = {'tcp_directions': ['x', 'y'], 'tcp_gain': 400.0}


@pytest.fixture
def procs(tmp_path):
    """Node processes in the session's isolated environment (conftest.py)."""
    assert os.environ.get('ROS_DOMAIN_ID')
    p = NodeProcesses(tmp_path, dict(os.environ))
    yield p
    p.close()


def _scenario(tmp_path, name, cutting, steps, damper=True, record=True):
    """Plant + cutting (+ TCP damper) (+ recorder) as a scenario file."""
    model = PLANT.save(tmp_path / 'model.npz')
    sources = ['cutting'] + (['damper'] if damper else [])
    doc = {'/**': {'ros__parameters': {'sample_rate': RATE}},
           'cutting': {'ros__parameters': dict(cutting)},
           'plant': {'ros__parameters': {
               'model_file': str(model), 'steps': steps, 'sources': sources,
               'output_file': str(tmp_path / f'{name}.npz'), 'startup_timeout': 60.0}}}
    if damper:
        doc['damper'] = {'ros__parameters': dict(DAMPER)}
    if record:
        doc['recorder'] = {'ros__parameters': {'output_dir': str(tmp_path / 'bags'),
                                               'bag_name': name}}
        doc['plant']['ros__parameters']['wait_for_subscribers'] = ['recorder']
    path = tmp_path / f'{name}.yaml'
    path.write_text(dump_params(doc))
    return path


def _assert_offline(run, path, conditions, steps, damped):
    """
    The trace of a run is simulate_cut's with the scenario's laws, bit for bit.

    The TCP force of the trace is the sum of the sources'; without a damper the cut's alone.
    """
    ref = simulate_cut(PLANT, conditions, 1.0 / RATE, steps / RATE,
                       scenario_loop_laws(path, 1.0 / RATE))
    assert int(run['steps_run']) == steps
    names = list(run['input_names'])
    force = run['u'][:, [names.index('tcp_force_x'), names.index('tcp_force_y')]]
    outputs = list(run['output_names'])
    disp = run['y'][:, [outputs.index('tcp_displacement_x'), outputs.index('tcp_displacement_y')]]
    assert np.array_equal(disp, ref.displacement)
    assert np.any(ref.force) and np.any(ref.displacement)
    if not damped:
        assert np.array_equal(force, ref.force)
    return ref


def test_separate_processes_cut_as_offline(tmp_path, procs):
    """
    Plant, cutting and damper nodes as processes: the offline loop bit for bit.

    Three teeth in up-milling at 30 % immersion with an edge force: overrides of the
    operation's end mill, engagement and material.
    """
    steps = 1200
    cut = {'spindle_speed': 2400.0, 'axial_depth': 1e-3, 'teeth': 3, 'milling': 'up',
           'radial_immersion': 0.3, 'edge_tangential': 2e4}
    path = _scenario(tmp_path, 'separate', cut, steps, record=False)
    procs.start('damper', 'pentapod_damper.nodes.damper_node', "tcp_directions:=['x','y']",
                'tcp_gain:=400.0', f'sample_rate:={RATE}')
    procs.start('cutting', 'pentapod_sim.nodes.cutting_node', 'spindle_speed:=2400.0',
                'axial_depth:=0.001', 'teeth:=3', 'milling:=up', 'radial_immersion:=0.3',
                'edge_tangential:=20000.0', f'sample_rate:={RATE}')
    procs.start('plant', 'pentapod_sim.nodes.plant_node', f'model_file:={tmp_path}/model.npz',
                f'steps:={steps}', f'sample_rate:={RATE}', 'sources:=[cutting,damper]',
                f"output_file:='{tmp_path}/separate.npz'", 'startup_timeout:=60.0')
    assert procs.wait('plant') == 0, procs.log('plant') + procs.log('cutting')
    spec = CuttingParams.build({**cut, 'sample_rate': RATE}, 'test').spec()
    cut_ = spec.conditions.cut
    assert (cut_.teeth, cut_.entry_angle, spec.conditions.edge_tangential) == (3, 0.0, 2e4)
    _assert_offline(np.load(tmp_path / 'separate.npz'), path, spec.conditions, steps, True)
    # the node's linear model (the averaged cut as a delay line) entered the plant's check
    assert 'loop of plant and ' in procs.log('plant') and 'cutting' in procs.log('plant')


#: Composed runs forked from one process that imported the nodes once (as the study does).
WARM = WarmStarter()


def _base(tmp_path, damped):
    """A damping scenario as the study has them: plant, exciter, (damper), recorder."""
    model = PLANT.save(tmp_path / 'model.npz')
    sources = ['exciter'] + (['damper'] if damped else [])
    doc = {'/**': {'ros__parameters': {'sample_rate': RATE}},
           'exciter': {'ros__parameters': {'kind': 'sine', 'amplitude': 5.0}},
           'plant': {'ros__parameters': {'model_file': str(model), 'sources': sources,
                                         'source_ports': {'exciter': ['tcp_force_x']}}},
           'recorder': {'ros__parameters': {'bag_name': 'never'}}}
    if damped:
        doc['damper'] = {'ros__parameters': dict(DAMPER)}
    path = tmp_path / 'base.yaml'
    path.write_text(dump_params(doc))
    return path, model


@pytest.mark.parametrize('damped', [False, True], ids=['baseline', 'tcp_damper'])
def test_recorded_cuts_reproduce_the_stability_limit(tmp_path, damped, capsys):
    """
    At the chosen speed, runs at 0.8x and 1.2x of the predicted limit are stable and chatter.

    Each run is the scenario with a cutting node instead of its exciter and a recorder
    (:func:`pentapod_sim.scenario.cutting.record_cut`, composed and warm, as a study stage
    runs it); ``analyze chatter`` on its bag gives the verdict. The bag holds the offline cut
    bit for bit: TCP displacement, cutting force, chips and engagement.
    """
    table = load_machining()
    base, model = _base(tmp_path, damped)
    laws = scenario_loop_laws(base)
    assert len(laws) == int(damped)
    dt = 1.0 / RATE
    lobes = loop_lobes(PLANT, laws, dt, table, [OPERATION], np.linspace(1000, 24000, 500),
                       'scenario')
    point = check_runs(PLANT, laws, dt, table, lobes.operations[OPERATION])
    assert 1e-4 < point.depth < 1e-2 and 100.0 < point.chatter_freq < 200.0
    for run in point.runs:
        bag = tmp_path / 'bags' / f'cut_{run.factor:g}'.replace('.', '_')
        done = record_cut(base, run, bag, model_file=str(model), warm=WARM)
        assert done.as_expected, done.verdict
        assert analyze.main(['--out', str(tmp_path / 'analysis'), 'chatter', str(bag),
                             '--settle', str(run.settle)]) == 0
        printed = capsys.readouterr().out
        with open(tmp_path / 'analysis' / f'chatter_{bag.name}_summary.csv') as f:
            summary = next(csv.DictReader(f))
        assert summary['verdict'] == run.expected, printed
        assert run.expected.upper() in printed
        offline = simulate_cut(PLANT, run.conditions(table), dt, run.duration,
                               scenario_loop_laws(base, dt))
        record = cut_record(bag)
        assert record.time.size == offline.time.size
        assert np.array_equal(record.displacement, offline.displacement)
        assert np.array_equal(record.chip, offline.chip)
        assert np.array_equal(record.in_cut, offline.in_cut)
        assert np.array_equal(record.engaged, offline.engaged)
        force = [open_bag(bag).series(f'{force_topic("cutting")}.effort.tcp_force_{a}').values
                 for a in 'xy']
        assert np.array_equal(np.column_stack(force), offline.force)
        if run.expected == 'chatter':
            tooth = float(summary['tooth_passing_Hz'])
            found = float(summary['chatter_Hz'])
            # the chatter line or one of its images by the tooth-passing modulation
            aliases = point.chatter_freq + tooth * np.arange(-3, 4)
            assert np.min(np.abs(np.abs(aliases) - found)) < 0.05 * point.chatter_freq, printed
            assert float(summary['off_harmonic_share']) > 0.05
        else:
            assert math.isnan(float(summary['chatter_Hz']))
