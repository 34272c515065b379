"""Parameter tables: checks, scenario files, override origins, generated docs (no ROS)."""
from pathlib import Path
import subprocess
import sys

import pytest

from pentapod_damper.node_parameters import DAMPER, damper_laws, PMA, pma_law
from pentapod_sim.errors import ConfigError
from pentapod_sim.executables import NODE_KINDS, PARAMETER_TABLES
from pentapod_sim.nodes.overrides import override_origins
from pentapod_sim.nodes.parameter_tables import PLANT
from pentapod_sim.parameters import all_tables, markdown, Param, ParameterTable, table_of
from pentapod_sim.paths import scenario_dir
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


def _write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / 'scenario.yaml'
    path.write_text(text)
    return path


def test_every_node_executable_has_a_table():
    assert set(PARAMETER_TABLES) == set(NODE_KINDS)
    for kind in NODE_KINDS:
        table = table_of(kind)
        assert isinstance(table, ParameterTable) and table.node == kind and len(table.names)


@pytest.mark.parametrize(('params', 'match'), [
    ({'postion': 'P2'}, "unknown parameter 'postion'; did you mean 'position'"),
    ({'sample_rate': 5000}, r"'sample_rate' = 5000 is an integer.*5000\.0"),
    ({'sample_rate': -5.0}, r"'sample_rate' = -5.0 is outside the range \[1, 1e\+06\]"),
    ({'timing': 'fast'}, "'fast' is not one of lockstep, realtime"),
    ({'sources': 'damper'}, "'damper' is not a list"),
    ({'sources': ['x', True]}, 'YAML reads a bare y'),
    ({'steps': 2.5}, "'steps' = 2.5 is not of type int"),
    ({'steps': True}, "'steps' = True is not of type int"),
    ({'source_ports.damper': 'tcp_force_x'}, 'is not a list'),
])
def test_check_names_the_bad_parameter_and_value(params, match):
    with pytest.raises(ConfigError, match=match) as err:
        PLANT.check(params, 'file.yaml: node plant')
    assert str(err.value).startswith('file.yaml: node plant: ')


def test_check_accepts_good_values_placeholders_and_ros_own_parameters():
    PLANT.check({'position': 'P2', 'sample_rate': 1.0, 'steps': 10 ** 12,
                 'source_ports': {'damper': ['tcp_force_x']}, 'use_sim_time': False,
                 'sources': None}, 'here')          # None: an empty list in a ROS 2 file
    assert PLANT['source_ports.pma'].name == 'source_ports.<source>'
    assert 'source_ports' not in PLANT and 'source_ports.a.b' not in PLANT


def test_values_apply_defaults_and_drop_none_marks():
    v = DAMPER.values({'bending_struts': [0], 'tcp_directions': ['', 'x']})
    assert v.bending_struts == [] and v.tcp_directions == ['x']
    assert v.tcp_gain == 20000.0 and v.axial_struts == []
    with pytest.raises(AttributeError, match="did you mean 'tcp_gain'"):
        v.tcp_gian


def test_a_bad_table_is_refused_when_written():
    with pytest.raises(ValueError, match='default 5 is an integer'):
        Param('x', 'float', 5, 'a number')
    with pytest.raises(ValueError, match='type'):
        Param('x', 'complex', 1j, 'a number')
    with pytest.raises(ValueError, match='repeats'):
        ParameterTable('n', [Param('a', 'int', 1, ''), Param('a', 'int', 2, '')])


def test_laws_from_parameters_use_the_tables_defaults():
    laws = damper_laws({'tcp_directions': ['x', 'z'], 'bending_struts': [2]})
    assert list(laws) == ['bending_gain', 'tcp_gain']
    assert laws['tcp_gain'].actuator_ports == ['tcp_force_x', 'tcp_force_z']
    assert list(laws['tcp_gain'].gains) == [DAMPER['tcp_gain'].default] * 2
    assert list(laws['bending_gain'].gains) == [DAMPER['bending_gain'].default] * 2
    law = pma_law({}, 1e-4)
    assert (law.mass, law.gain, law.actuator_ports) == (
        PMA['proof_mass'].default, PMA['gain'].default, ['pma_force_x'])
    with pytest.raises(ConfigError, match="node 'd': unknown parameter 'tcp_gian'"):
        damper_laws({'tcp_gian': 5.0}, "node 'd'")


def test_scenario_with_a_misspelt_key_is_refused_naming_file_node_and_key(tmp_path):
    path = _write(tmp_path, SCENARIO.replace('tcp_gain: 5000.0', 'tcp_gian: 5.0'))
    with pytest.raises(ConfigError) as err:
        read_scenario(path)
    text = str(err.value)
    assert str(path) in text and "'damper_tcp'" in text and "'tcp_gian'" in text
    assert "did you mean 'tcp_gain'" in text


def test_scenario_values_are_checked(tmp_path):
    with pytest.raises(ConfigError, match=r"node 'pma'.*'proof_mass' = 0.0 is outside"):
        read_scenario(_write(tmp_path, SCENARIO.replace('proof_mass: 2.0',
                                                        'proof_mass: 0.0')))


def test_shared_section_reaches_only_the_nodes_that_declare_it(tmp_path):
    scenario = read_scenario(_write(tmp_path, SCENARIO))
    assert scenario.sections['pma']['sample_rate'] == 5000.0
    assert scenario.sections['plant']['sample_rate'] == 5000.0
    assert scenario.sections['damper_tcp']['sample_rate'] == 5000.0   # filters and delays
    with pytest.raises(ConfigError, match=r"'/\*\*'.*'sample_rat'.*did you mean "
                                          r"'sample_rate'"):
        read_scenario(_write(tmp_path, SCENARIO.replace('sample_rate:', 'sample_rat:')))
    with pytest.raises(ConfigError, match=r"'/\*\*' \(for plant\): parameter "
                                          r"'sample_rate' = 5000 is an integer"):
        read_scenario(_write(tmp_path, SCENARIO.replace('5000.0', '5000')))


def test_every_shipped_scenario_passes_its_tables():
    names = sorted(p.stem for p in scenario_dir().glob('*.yaml'))
    assert names
    for name in names:
        read_scenario(name)


def test_runner_refuses_a_misspelt_key_with_one_line(tmp_path):
    path = _write(tmp_path, SCENARIO.replace('tcp_gain: 5000.0', 'tcp_gian: 5.0'))
    proc = subprocess.run([sys.executable, '-m', 'pentapod_sim.scenario.runner', str(path),
                           '--list'], capture_output=True, text=True, timeout=60, cwd=ROOT)
    assert proc.returncode == 1
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "did you mean 'tcp_gain'" in lines[0], proc.stderr


def test_override_origins_tell_own_rules_from_shared_sections(tmp_path):
    path = tmp_path / 'p.yaml'
    path.write_text("""
/**:
  ros__parameters: {sample_rate: 5000.0, shared_only: 1}
damper_a:
  ros__parameters:
    tcp_gain: 1.0
    source_ports: {x: ['a']}
/ns:
  damper_a:
    ros__parameters: {nested: 1}
damper_b:
  ros__parameters: {other: 1}
""")
    args = ['prog', 'positional', '--ros-args', '-r', '__node:=damper_a', '-p', 'gain:=5.0',
            '-p', 'damper_b:skipped:=1', '-p', '/**:wild:=1', '--params-file', str(path),
            '--', '-p', 'not_ros:=1', '--ros-args', '--param', 'late:=2']
    origins = override_origins(args, 'damper_a', '/damper_a')
    assert origins.own == {'gain', 'tcp_gain', 'source_ports.x', 'nested', 'late'}
    assert origins.shared == {'sample_rate', 'shared_only', 'wild'}


def test_docs_parameters_md_is_generated_from_the_tables():
    """Regenerate: ``python -m pentapod_sim.parameters --markdown > docs/parameters.md``."""
    committed = (ROOT / 'docs' / 'parameters.md').read_text(encoding='utf-8')
    assert committed == markdown()
    for kind, table in all_tables().items():
        assert f'## {kind}\n' in committed
        for param in table:
            assert f'| `{param.name}` |' in committed


def test_the_markdown_command_prints_the_docs():
    proc = subprocess.run([sys.executable, '-m', 'pentapod_sim.parameters', '--markdown'],
                          capture_output=True, text=True, timeout=60, cwd=ROOT, check=True)
    assert proc.stdout == markdown()


def test_nodes_md_links_the_generated_tables_instead_of_repeating_them():
    text = (ROOT / 'docs' / 'nodes.md').read_text(encoding='utf-8')
    assert '(parameters.md)' in text
    assert '`source_timeout` [s] (5)' not in text and '| name | type | default' not in text
