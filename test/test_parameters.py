"""Node parameters: one schema per node, checks, scenario files, generated docs (no ROS)."""
from dataclasses import dataclass
from pathlib import Path
import subprocess
import sys

import pytest

from pentapod_damper.node_parameters import damper_laws, DamperParams, pma_law, PmaParams
from pentapod_sim import registry
from pentapod_sim.errors import ConfigError
from pentapod_sim.nodes.parameter_tables import PlantParams
from pentapod_sim.parameters import declares, NodeParams, param, params_of, sample_time
from pentapod_sim.paths import scenario_dir
from pentapod_sim.reference import config_markdown, parameters_markdown
from pentapod_sim.scenario.files import read_scenario

ROOT = Path(__file__).resolve().parents[1]

SCENARIO = """
/**:
  ros__parameters:
    sample_rate: 5000.0
plant:
  ros__parameters:
    model_file: m.npz
    sources: [damper_tcp, pma]
damper_tcp:
  ros__parameters:
    tcp_directions: ['x']
    tcp_gain: 5000.0
pma:
  ros__parameters:
    proof_mass: 2.0
"""


def _write(tmp_path: Path, text: str, name: str = 'scenario.yaml') -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def test_every_node_kind_has_a_parameter_class_its_node_declares():
    """The registry's ROS-free parameter class is the one the node class declares."""
    import importlib
    for kind in registry.NODES:
        cls = params_of(kind.name)
        assert issubclass(cls, NodeParams) and cls.ros_params(), kind.name
        module, name = kind.node.split(':')
        assert getattr(importlib.import_module(module), name).Params is cls, kind.name
        assert cls.build({}, kind.name) == cls()       # the defaults pass their own checks


@pytest.mark.parametrize(('params', 'message'), [
    ({'postion': 'P2'}, "unknown parameter 'postion'; did you mean 'position'?"),
    ({'sample_rate': -5.0}, 'parameter sample_rate = -5.0 Hz: must lie in [1, 1e+06]'),
    ({'timing': 'fast'}, "parameter timing = 'fast': must be one of lockstep, realtime"),
    ({'sources': 'damper'}, "parameter sources = 'damper': expected a list"),
    ({'sources': ['x', True]}, 'parameter sources[1] = True: expected a text (YAML reads a '
                               'bare y, n, yes, no, on, off as true or false: quote it)'),
    ({'steps': 2.5}, 'parameter steps = 2.5: expected an integer'),
    ({'steps': True}, 'parameter steps = True: expected an integer'),
    ({'source_ports.damper': 'tcp_force_x'},
     "parameter source_ports.damper = 'tcp_force_x': expected a list"),
    ({'sources': ['damper'], 'source_ports': {'damperr': ['tcp_force_x']}},
     "parameter 'source_ports.damperr' names no source of parameter 'sources' = ['damper']"),
])
def test_a_bad_parameter_is_named_with_its_value(params, message):
    with pytest.raises(ConfigError) as err:
        PlantParams.build(params, 'file.yaml: node plant')
    assert str(err.value) == f'file.yaml: node plant: {message}'


def test_good_values_placeholders_and_ros_own_parameters_are_typed():
    values = PlantParams.build({'position': 'P2', 'sample_rate': 3000, 'steps': 10 ** 12,
                                'sources': ['damper', 'pma'],
                                'source_ports': {'damper': ['tcp_force_x']},
                                'use_sim_time': False, 'wait_for_subscribers': None}, 'here')
    assert values.sample_rate == 3000.0 and isinstance(values.sample_rate, float)
    assert values.dt == sample_time(3000.0) == 1 / 3000.0
    assert values.source_ports == {'damper': ('tcp_force_x',), 'pma': ()}     # () = all
    assert values.wait_for_subscribers == ()             # None: an empty list in a ROS 2 file
    ros = values.ros_values()            # every source gets its parameter, [] as its mark
    assert ros['source_ports.damper'] == ['tcp_force_x'] and ros['source_ports.pma'] == ['']
    assert ros['wait_for_subscribers'] == [''] and 'source_ports' not in ros
    assert PlantParams.build(ros, 'again') == values       # the ROS form reads back
    assert declares(PlantParams, 'source_ports.pma') and not declares(PlantParams, 'source_ports')


def test_none_marks_mean_nothing_and_defaults_apply():
    v = DamperParams.build({'bending_struts': [0], 'tcp_directions': ['', 'x']}, 'n')
    assert v.bending_struts == () and v.tcp_directions == ('x',)
    assert v.tcp_gain == DamperParams.tcp_gain == 20000.0 and v.axial_struts == ()


def test_a_parameter_type_ros_cannot_hold_is_refused():
    @dataclass(frozen=True)
    class Bad(NodeParams):
        """A mapping of floats."""

        x: dict[str, float] | None = param(None, 'no ROS 2 type')
    with pytest.raises(TypeError, match="parameter 'x'"):
        Bad.ros_params()


def test_laws_from_parameters_use_the_classes_defaults():
    laws = damper_laws({'tcp_directions': ['x', 'z'], 'bending_struts': [2]})
    assert list(laws) == ['bending_gain', 'tcp_gain']
    assert laws['tcp_gain'].actuator_ports == ['tcp_force_x', 'tcp_force_z']
    assert list(laws['tcp_gain'].gains) == [DamperParams.tcp_gain] * 2
    assert list(laws['bending_gain'].gains) == [DamperParams.bending_gain] * 2
    assert laws['tcp_gain'].dt == 1 / DamperParams.sample_rate
    law = pma_law({}, 1e-4)
    assert (law.mass, law.gain, law.actuator_ports, law.dt) == (
        PmaParams.proof_mass, PmaParams.gain, ['pma_force_x'], 1e-4)
    with pytest.raises(ConfigError, match="node 'd': unknown parameter 'tcp_gian'"):
        damper_laws({'tcp_gian': 5.0}, "node 'd'")


def test_scenario_with_a_misspelt_key_is_refused_naming_file_node_and_key(tmp_path):
    path = _write(tmp_path, SCENARIO.replace('tcp_gain: 5000.0', 'tcp_gian: 5.0'))
    with pytest.raises(ConfigError) as err:
        read_scenario(path)
    assert str(err.value) == (f"{path}: node 'damper_tcp' (damper): unknown parameter "
                              "'tcp_gian'; did you mean 'tcp_gain'?")


def test_scenario_values_are_checked(tmp_path):
    path = _write(tmp_path, SCENARIO.replace('proof_mass: 2.0', 'proof_mass: 0.0'))
    with pytest.raises(ConfigError) as err:
        read_scenario(path)
    assert str(err.value) == (f"{path}: node 'pma' (pma): parameter proof_mass = 0.0 kg: must "
                              'lie in [1e-06, 1e+06]')


def test_another_kinds_parameter_in_a_nodes_own_section_is_refused(tmp_path):
    """The nodes ignore another kind's names (a shared section); the runner's check does not."""
    path = _write(tmp_path, SCENARIO.replace('tcp_gain: 5000.0', 'proof_mass: 5.0'))
    with pytest.raises(ConfigError, match=r"node 'damper_tcp' \(damper\): unknown parameter "
                                          r"'proof_mass'"):
        read_scenario(path)


def test_shared_section_reaches_only_the_nodes_that_declare_it(tmp_path):
    scenario = read_scenario(_write(tmp_path, SCENARIO.replace(
        'sample_rate: 5000.0', 'sample_rate: 2000.0\n    proof_mass: 3.0')))
    assert scenario.node('pma').params.sample_rate == 2000.0
    assert scenario.node('pma').params.proof_mass == 2.0          # its own entry wins
    assert scenario.plant.params.sample_rate == 2000.0
    assert scenario.node('damper_tcp').params.dt == 1 / 2000.0     # filters and delays
    assert 'proof_mass' not in scenario.sections['damper_tcp']
    with pytest.raises(ConfigError, match=r"'/\*\*'.*'sample_rat'.*did you mean "
                                          r"'sample_rate'"):
        read_scenario(_write(tmp_path, SCENARIO.replace('sample_rate:', 'sample_rat:')))
    with pytest.raises(ConfigError, match=r"'/\*\*' \(for plant\): parameter sample_rate = "
                                          r'-5.0 Hz: must lie in'):
        read_scenario(_write(tmp_path, SCENARIO.replace('5000.0', '-5.0')))


def test_the_written_parameter_file_reads_back_as_the_same_values(tmp_path):
    """The run's one parameter file: resolved sections (no /**), the same typed values."""
    scenario = read_scenario(_write(tmp_path, SCENARIO)).with_params('plant', steps=7)
    written = scenario.write(tmp_path / 'run.yaml')
    again = read_scenario(written)
    assert '/**' not in written.read_text()
    assert [(n.name, n.params) for n in again.nodes] == [(n.name, n.params)
                                                           for n in scenario.nodes]
    assert again.plant.params.steps == 7 and again.plant.params.model_file == 'm.npz'


def test_a_node_class_named_by_the_section(tmp_path, monkeypatch):
    """``node_class``: a node kind for any name, or a class of the user's own module."""
    (tmp_path / 'my_controllers.py').write_text('''
from dataclasses import dataclass
from pentapod_sim.parameters import NodeParams, param


@dataclass(frozen=True)
class GainParams(NodeParams):
    """A gain."""

    gain: float = param(1.0, 'the gain', 'N s/m', bounds=(0.0, 10.0))
    sample_rate: float = param(1000.0, 'rate', 'Hz', bounds=(1.0, 1e6))


class Controller:
    Params = GainParams


class Plain:
    """A class without a parameter schema: its values pass unchecked."""
''')
    monkeypatch.syspath_prepend(str(tmp_path))
    text = SCENARIO + """
strut_ctrl:
  ros__parameters:
    node_class: damper
    axial_struts: [1]
mine:
  ros__parameters:
    node_class: my_controllers:Controller
    gain: 2.0
plain:
  ros__parameters:
    node_class: my_controllers:Plain
    anything: [1, 2]
"""
    scenario = read_scenario(_write(tmp_path, text))
    strut, mine, plain = (scenario.node(n) for n in ('strut_ctrl', 'mine', 'plain'))
    assert (strut.kind, strut.params.axial_struts) == ('damper', (1,))
    assert (mine.kind, mine.executable, mine.role) == (None, 'component', registry.SOURCE)
    assert (mine.params.gain, mine.params.sample_rate) == (2.0, 5000.0)   # /** reached it
    assert plain.params == {'sample_rate': 5000.0, 'anything': [1, 2]}
    doc = scenario.document()
    assert doc['mine']['ros__parameters']['node_class'] == 'my_controllers:Controller'
    assert doc['strut_ctrl']['ros__parameters']['node_class'] == 'damper'
    assert read_scenario(scenario.write(tmp_path / 'again.yaml')).node('mine') == mine
    for bad, match in (('gain: 2.0', "node 'mine' (my_controllers:Controller): parameter gain "
                                     '= 20.0 N s/m: must lie in [0, 10]'),
                       ('my_controllers:Controller', "node class 'my_controllers:Controlr'")):
        wrong = text.replace(bad, bad.replace('2.0', '20.0').replace('Controller', 'Controlr'))
        with pytest.raises(ConfigError) as err:
            read_scenario(_write(tmp_path, wrong))
        assert match in str(err.value)


def test_every_shipped_scenario_passes_its_checks():
    names = sorted(p.stem for p in scenario_dir().glob('*.yaml'))
    assert names
    for name in names:
        assert read_scenario(name).plant.kind == 'plant'


def test_runner_refuses_a_misspelt_key_with_one_line(tmp_path):
    path = _write(tmp_path, SCENARIO.replace('tcp_gain: 5000.0', 'tcp_gian: 5.0'))
    proc = subprocess.run([sys.executable, '-m', 'pentapod_sim.scenario.runner', str(path),
                           '--list'], capture_output=True, text=True, timeout=60, cwd=ROOT)
    assert proc.returncode == 1
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "did you mean 'tcp_gain'" in lines[0], proc.stderr


@pytest.mark.parametrize(('page', 'make'), [('parameters', parameters_markdown),
                                            ('config', config_markdown)])
def test_reference_pages_are_generated_from_the_schemas(page, make):
    """Regenerate: ``python -m pentapod_sim.reference PAGE > docs/PAGE.md``."""
    committed = (ROOT / 'docs' / f'{page}.md').read_text(encoding='utf-8')
    assert committed == make()
    proc = subprocess.run([sys.executable, '-m', 'pentapod_sim.reference', page],
                          capture_output=True, text=True, timeout=60, cwd=ROOT, check=True)
    assert proc.stdout == committed


def test_the_pages_hold_every_parameter_and_config_key():
    text = (ROOT / 'docs' / 'parameters.md').read_text(encoding='utf-8')
    for kind in registry.NODES:
        assert f'## {kind.name}\n' in text
        for p in params_of(kind.name).ros_params():
            assert f'| `{p.name}` |' in text
    config = (ROOT / 'docs' / 'config.md').read_text(encoding='utf-8')
    for key in ('`sample_rate`', '`excitation.band`', '`relevance[i].rel_limit`',
                '`materials.<name>.kienzle.exponent`', '`bp_joints.angles`'):
        assert f'| {key} |' in config, key


def test_nodes_md_links_the_generated_tables_instead_of_repeating_them():
    text = (ROOT / 'docs' / 'nodes.md').read_text(encoding='utf-8')
    assert '(parameters.md)' in text
    assert '`source_timeout` [s] (5)' not in text and '| name | type | default' not in text
