"""
launch/testbed.launch.py builds its nodes from the checked scenario (no ros2 launch needed).

``launch`` and ``launch_ros`` are not wheels, so the actions the file uses are replaced by
records of their arguments; what is checked is which nodes the launch starts, with which
executable and which parameters.
"""
import importlib.util
from pathlib import Path
import sys
import types

import pytest

from pentapod_sim.scenario.files import read_scenario

ROOT = Path(__file__).resolve().parents[1]


class _Action:
    def __init__(self, *args, **kwargs):
        self.args, self.kwargs = args, kwargs


class _Config:
    """LaunchConfiguration: its value from the test's arguments."""

    values: dict = {}

    def __init__(self, name):
        self.name = name

    def perform(self, context):
        return self.values[self.name]


@pytest.fixture
def launch_file(monkeypatch):
    modules = {
        'launch': {'LaunchDescription': _Action},
        'launch.actions': {n: type(n, (_Action,), {}) for n in (
            'DeclareLaunchArgument', 'EmitEvent', 'LogInfo', 'OpaqueFunction',
            'RegisterEventHandler', 'SetEnvironmentVariable')},
        'launch.event_handlers': {'OnProcessExit': _Action},
        'launch.events': {'Shutdown': _Action},
        'launch.substitutions': {'LaunchConfiguration': _Config},
        'launch_ros': {}, 'launch_ros.actions': {'Node': type('Node', (_Action,), {})},
    }
    for name, attrs in modules.items():
        module = types.ModuleType(name)
        module.__dict__.update(attrs)
        monkeypatch.setitem(sys.modules, name, module)
    spec = importlib.util.spec_from_file_location('testbed_launch',
                                                  ROOT / 'launch' / 'testbed.launch.py')
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _nodes(launch_file, **args):
    _Config.values = {'scenario': 'pma_5kg', 'steps': '', 'duration': '', 'record': 'true',
                      'bag': '', 'live': 'false', 'live_port': '8765', **args}
    return {a.kwargs['name']: a.kwargs for a in launch_file._nodes(None)
            if type(a).__name__ == 'Node'}


def test_every_node_gets_its_checked_parameters(launch_file):
    nodes = _nodes(launch_file, steps='100')
    scenario = read_scenario('pma_5kg')
    assert list(nodes) == [n.name for n in scenario.nodes]
    for node in scenario.nodes:
        assert nodes[node.name]['executable'] == node.kind
        params = nodes[node.name]['parameters'][0]
        expected = node.ros_values()
        if node.name == 'plant':
            expected['steps'] = 100                  # the launch argument
        assert params == expected, node.name
    assert nodes['pma']['parameters'][0]['sample_rate'] == 5000.0    # from /**


def test_record_false_drops_the_recorders_and_the_waits_for_them(launch_file):
    nodes = _nodes(launch_file, record='false')
    assert 'recorder' not in nodes
    assert nodes['plant']['parameters'][0]['wait_for_subscribers'] == ['']   # "none"


def test_bag_moves_the_recording(launch_file, tmp_path):
    nodes = _nodes(launch_file, bag=str(tmp_path / 'here'))
    params = nodes['recorder']['parameters'][0]
    assert (params['output_dir'], params['bag_name']) == (str(tmp_path), 'here')


def test_a_users_class_runs_as_a_component(launch_file, tmp_path, monkeypatch):
    (tmp_path / 'lab_nodes.py').write_text('class Plain:\n    """No parameter class."""\n')
    monkeypatch.syspath_prepend(str(tmp_path))
    text = (ROOT / 'config' / 'scenarios' / 'baseline.yaml').read_text()
    scenario = tmp_path / 'lab.yaml'
    scenario.write_text(text + '\nmine:\n  ros__parameters:\n    node_class: lab_nodes:Plain\n'
                        '    k: 2.0\n')
    nodes = _nodes(launch_file, scenario=str(scenario))
    assert nodes['mine']['executable'] == 'component'
    assert nodes['mine']['arguments'] == ['lab_nodes:Plain']
    assert nodes['mine']['parameters'][0] == {'sample_rate': 5000.0, 'k': 2.0}
