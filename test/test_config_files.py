"""
Every configuration file is checked one way (pentapod_sim.schema); CLIs show a user's mistake.

A mistake is one line naming the file, with exit code 1 and no traceback. The shipped files
are compared with the YAML read here independently of the loaders.
"""
from dataclasses import dataclass
import math
import os
from pathlib import Path
import subprocess
import sys

import pytest
import yaml

from pentapod_damper.study.config import load_study_config
from pentapod_sim.errors import ConfigError
from pentapod_sim.fe.machine_data import load_machine, load_positions
from pentapod_sim.machining.materials import load_machining
from pentapod_sim.plant.build import load_reduction_config
from pentapod_sim.plant.drives import load_drives
from pentapod_sim.plant.ports import INPUT_NAMES, OUTPUT_NAMES
from pentapod_sim.schema import build, NON_NEGATIVE, POSITIVE, read_mapping, spec

ROOT = Path(__file__).resolve().parents[1]
CONFIG = ROOT / 'config'
LOADERS = {'machine.yaml': load_machine, 'positions.yaml': load_positions,
           'reduction.yaml': load_reduction_config, 'study.yaml': load_study_config,
           'machining.yaml': load_machining, 'drives.yaml': load_drives}


def _raw(name: str) -> dict:
    return yaml.safe_load((CONFIG / name).read_text(encoding='utf-8'))


def _node(doc, keys):
    for key in keys:
        doc = doc[key]
    return doc


def _write(tmp_path: Path, name: str, doc) -> Path:
    path = tmp_path / name
    path.write_text(yaml.safe_dump(doc, sort_keys=False), encoding='utf-8')
    return path


@pytest.mark.parametrize('name, keys, wrong, right', [
    ('machine.yaml', ['installation'], 'instalation', 'installation'),
    ('machine.yaml', ['struts', 'shear_factor'], 'shear_factr', 'shear_factor'),
    ('positions.yaml', ['positions', 'P2', 'b_deg'], 'b_dg', 'b_deg'),
    ('reduction.yaml', ['static_correction'], 'static_corection', 'static_correction'),
    ('reduction.yaml', ['relevance', 1, 'rel_limit'], 'rel_limt', 'rel_limit'),
    ('study.yaml', ['excitation', 'settle_periods'], 'settle_period', 'settle_periods'),
    ('study.yaml', ['step_response'], 'step_respons', 'step_response'),
    ('machining.yaml', ['materials', 'steel', 'kienzle', 'exponent'], 'exponnt', 'exponent'),
    ('machining.yaml', ['operations', 'steel_half_down', 'milling'], 'miling', 'milling'),
    ('drives.yaml', ['position_gain'], 'position_gian', 'position_gain'),
])
def test_misspelt_key_is_refused_naming_file_path_and_closest_key(tmp_path, name, keys, wrong,
                                                                  right):
    doc = _raw(name)
    parent = _node(doc, keys[:-1])
    parent[wrong] = parent.pop(keys[-1])
    path = _write(tmp_path, name, doc)
    where = ''.join(f'[{k}]' if isinstance(k, int) else f'.{k}' for k in keys[:-1] + [wrong])
    with pytest.raises(ConfigError) as info:
        LOADERS[name](path)
    assert str(info.value) == (f"{path}: {where.lstrip('.')}: unknown key; "
                               f"did you mean '{right}'?")


def test_the_issues_example_relevance_measure(tmp_path):
    doc = _raw('reduction.yaml')
    doc['relevance'][1]['measur'] = 'resonance'
    with pytest.raises(ConfigError, match=r"reduction\.yaml: relevance\[1\]\.measur: unknown "
                                          r"key; did you mean 'measure'\?$"):
        load_reduction_config(_write(tmp_path, 'reduction.yaml', doc))


@pytest.mark.parametrize('name, keys, value, message', [
    ('machine.yaml', ['frame', 'bed_mass'], -1500, 'frame.bed_mass = -1500.0 kg: must be > 0'),
    ('positions.yaml', ['positions', 'P1', 'x'], 'far',
     "positions.P1.x = 'far' m: expected a number in m"),
    ('reduction.yaml', ['sample_rate'], -5000.0, 'sample_rate = -5000.0 Hz: must be > 0'),
    ('reduction.yaml', ['modes_f_max'], True, 'modes_f_max = True Hz: expected a number in Hz'),
    ('reduction.yaml', ['relevance', 1, 'rel_limit'], 1.5,
     'relevance[1].rel_limit = 1.5: must lie in (0, 1)'),
    ('reduction.yaml', ['relevance', 0, 'measure'], 'peak',
     "relevance[0].measure = 'peak': must be one of dc, resonance"),
    ('reduction.yaml', ['damping_ratio'], [0.001, -0.002],
     'damping_ratio[1] = -0.002: must be >= 0'),
    ('reduction.yaml', ['inputs'], ['tcp_force_x', 'tcp_forse_y'],
     "inputs[1] = 'tcp_forse_y': not a known value; did you mean 'tcp_force_y'?"),
    ('reduction.yaml', ['static_correction'], 'yes',
     "static_correction = 'yes': expected true or false"),
    ('reduction.yaml', ['frequency', 'n_points'], 40.5,
     'frequency.n_points = 40.5: expected an integer'),
    ('reduction.yaml', ['frequency', 'f_min'], 500.0,
     'frequency: f_min = 500.0 Hz must be < f_max = 400.0 Hz'),
    ('reduction.yaml', ['report_pair'], ['tcp_displacement_y'],
     "report_pair = ['tcp_displacement_y']: expected a list of 2 items"),
    ('study.yaml', ['excitation', 'periods'], 0, 'excitation.periods = 0: must be > 0'),
    ('study.yaml', ['excitation', 'direction'], 'w',
     "excitation.direction = 'w': must be one of x, y, z"),
    ('study.yaml', ['positions'], ['P1', 'P22'],
     "positions[1] = 'P22': must be one of P1, P2, P3, P4, P5; did you mean 'P2'?"),
    ('machining.yaml', ['tools', 'endmill_4', 'teeth'], 4.5,
     'tools.endmill_4.teeth = 4.5: expected an integer'),
    ('machining.yaml', ['materials', 'aluminium', 'tangential'], -796e6,
     'materials.aluminium.tangential = -796000000.0 N/m^2: must be > 0'),
    ('machining.yaml', ['operations', 'aluminium_slot', 'radial_immersion'], 1.5,
     'operations.aluminium_slot.radial_immersion = 1.5: must lie in (0, 1]'),
    ('machining.yaml', ['operations', 'aluminium_slot', 'milling'], 'climb',
     "operations.aluminium_slot.milling = 'climb': must be one of up, down"),
    ('machining.yaml', ['operations', 'aluminium_slot', 'material'], 'aluminum',
     "operations.aluminium_slot.material = 'aluminum': must be one of aluminium, steel; did "
     "you mean 'aluminium'?"),
    ('machining.yaml', ['spindle_speeds'], [24000.0, 1000.0],
     'spindle_speeds = [24000.0, 1000.0] rpm must increase'),
])
def test_wrong_value_names_file_key_value_and_unit(tmp_path, name, keys, value, message):
    doc = _raw(name)
    _node(doc, keys[:-1])[keys[-1]] = value
    path = _write(tmp_path, name, doc)
    with pytest.raises(ConfigError) as info:
        LOADERS[name](path)
    assert str(info.value) == f'{path}: {message}'


def test_unknown_scenario_names_the_closest(tmp_path):
    doc = _raw('study.yaml')
    doc['scenarios'][2] = 'strut_damping_21'
    path = _write(tmp_path, 'study.yaml', doc)
    with pytest.raises(ConfigError, match=rf"^{path}: scenarios\[2\] = 'strut_damping_21': .*; "
                                          r"did you mean 'strut_damping_12'\?$"):
        load_study_config(path)


@pytest.mark.parametrize('name', sorted(LOADERS))
@pytest.mark.parametrize('text, message', [
    ('', 'the file is empty (expected a mapping of keys)'),
    ('# only a comment\n', 'the file is empty (expected a mapping of keys)'),
    ('- a\n- b\n', "expected a mapping of keys at the top level, got list ['a', 'b']"),
])
def test_empty_or_non_mapping_file_names_the_file(tmp_path, name, text, message):
    path = tmp_path / name
    path.write_text(text)
    with pytest.raises(ConfigError) as info:
        LOADERS[name](path)
    assert str(info.value) == f'{path}: {message}'


@pytest.mark.parametrize('name', sorted(LOADERS))
def test_missing_file_and_bad_yaml_name_the_file_on_one_line(tmp_path, name):
    with pytest.raises(ConfigError, match=rf'^{tmp_path / "absent.yaml"}: cannot read'):
        LOADERS[name](tmp_path / 'absent.yaml')
    path = tmp_path / name
    path.write_text('a: 1\nb: [2, 3\nc: 4\n')
    with pytest.raises(ConfigError, match=rf'^{path}:3:2: not valid YAML') as info:
        LOADERS[name](path)
    assert '\n' not in str(info.value)


def _expect_machine(obj, raw: dict, where: str = '') -> int:
    """Compare every leaf of the raw YAML with the loaded object; return the leaves seen."""
    seen = 0
    for key, value in raw.items():
        if isinstance(value, dict):
            seen += _expect_machine(getattr(obj, key), value, f'{where}{key}.')
            continue
        if key.endswith('_deg'):
            key, value = key[:-4], (list(map(math.radians, value)) if isinstance(value, list)
                                    else math.radians(value))
        got = getattr(obj, key)
        if isinstance(got, tuple) and not isinstance(value, list):
            value = [value] * len(got)               # one number for all struts
        if isinstance(value, str):                   # a choice (frame.model)
            assert got == value, f'{where}{key}'
        else:
            assert got == pytest.approx(tuple(value) if isinstance(value, list) else value,
                                        rel=1e-15), f'{where}{key}'
        seen += 1
    return seen


def test_shipped_machine_file_gives_the_raw_values():
    machine = load_machine()
    assert _expect_machine(machine, _raw('machine.yaml')) > 60
    assert machine.source == str(CONFIG / 'machine.yaml')


def test_shipped_positions_file_gives_the_raw_values():
    raw = _raw('positions.yaml')['positions']
    positions = load_positions()
    assert list(positions) == list(raw)
    for name, entry in raw.items():
        expect = [entry['x'], entry['y'], entry['z'],
                  math.radians(entry['a_deg']) if 'a_deg' in entry else entry['a'],
                  math.radians(entry['b_deg']) if 'b_deg' in entry else entry['b']]
        assert positions[name].tolist() == pytest.approx(expect, rel=1e-15, abs=0)


def test_shipped_reduction_file_gives_the_raw_values():
    raw, cfg = _raw('reduction.yaml'), load_reduction_config()
    assert cfg.inputs == (INPUT_NAMES if raw['inputs'] == 'all' else tuple(raw['inputs']))
    assert cfg.outputs == (OUTPUT_NAMES if raw['outputs'] == 'all' else tuple(raw['outputs']))
    assert len(cfg.relevance) == len(raw['relevance'])
    for rule, raw_rule in zip(cfg.relevance, raw['relevance']):
        assert rule.inputs == tuple(raw_rule['inputs'])
        assert rule.outputs == tuple(raw_rule['outputs'])
        assert rule.measure == raw_rule.get('measure', 'dc')
        limits = {k: raw_rule[k] for k in ('abs_limit', 'rel_limit', 'count') if k in raw_rule}
        assert rule.criterion == limits
    for key in ('modes_f_max', 'static_correction', 'damping_ratio', 'sample_rate'):
        assert getattr(cfg, key) == raw[key], key
    assert vars(cfg.frequency) == raw['frequency']
    assert cfg.positions == tuple(raw['positions'])
    assert cfg.report_pair == tuple(raw['report_pair'])


def test_shipped_study_file_gives_the_raw_values():
    raw, cfg = _raw('study.yaml'), load_study_config()
    exc, ana, freq, step = (raw[k] for k in ('excitation', 'analysis', 'frequency',
                                              'step_response'))
    assert cfg.positions == tuple(raw['positions'])
    assert cfg.scenarios == tuple(raw['scenarios'])
    assert (cfg.sample_rate, cfg.pma_force_amplitude) == (raw['sample_rate'],
                                                          raw['pma_force_amplitude'])
    assert (cfg.direction, cfg.amplitude, cfg.band, cfg.period, cfg.periods,
            cfg.settle_periods) == (exc['direction'], exc['amplitude'], tuple(exc['band']),
                                    exc['period'], exc['periods'], exc['settle_periods'])
    assert cfg.f_max == ana['f_max']
    assert cfg.freq_grid == (freq['f_min'], freq['f_max'], freq['n_points'])
    assert (cfg.step_position, cfg.step_amplitude, cfg.step_duration) == (
        step['position'], step['amplitude'], step['duration'])
    assert isinstance(cfg.periods, int) and isinstance(cfg.freq_grid[2], int)


def test_study_overrides_are_checked_and_named():
    cfg = load_study_config(period=2.0, positions=('P2',))
    assert cfg.period == 2.0 and cfg.positions == ('P2',)
    assert cfg.duration == 2.0 * (cfg.settle_periods + cfg.periods)
    with pytest.raises(ConfigError, match=r'study\.yaml with period=-1\.0: excitation\.'
                                          r'period = -1\.0 s: must be > 0$'):
        load_study_config(period=-1.0)
    with pytest.raises(ConfigError, match="unknown study setting 'perod'; did you mean "
                                          "'period'"):
        load_study_config(perod=2.0)


# ------------------------------------------------------------------------ the schema itself
@dataclass(frozen=True)
class _Inner:
    mode: str = spec(choices=('fast', 'slow'), default='fast')
    gain: float | None = spec('N s/m', POSITIVE, default=None)

    def __post_init__(self):
        if self.mode == 'slow' and self.gain is None:
            raise ConfigError('gain is required when mode is slow')


@dataclass(frozen=True)
class _Outer:
    zeta: float | tuple[float, ...] = spec('-', NON_NEGATIVE)
    angle: float = spec('rad', bounds=(-1.0, 1.0), closed=(True, False))
    sizes: tuple[float, ...] = spec('m', POSITIVE, length=3, broadcast=True, default=(1.0,) * 3)
    items: tuple[_Inner, ...] = spec(default=())
    table: dict[str, float] = spec('kg', default_factory=dict)


def test_schema_types_rules_defaults_and_degrees():
    out = build(_Outer, {'zeta': [0.1, 0.2], 'angle_deg': 45, 'sizes': '2e-1',
                         'items': [{}, {'mode': 'slow', 'gain': '1e4'}], 'table': {'a': 3}},
                'x.yaml')
    assert out.zeta == (0.1, 0.2) and out.angle == pytest.approx(math.pi / 4)
    assert out.sizes == (0.2, 0.2, 0.2)          # one number for all, '2e-1' as PyYAML reads it
    assert out.items == (_Inner('fast', None), _Inner('slow', 1e4)) and out.table == {'a': 3.0}
    assert build(_Outer, {'zeta': 0, 'angle': -1}, 'x.yaml').zeta == 0.0
    cases = [({'zeta': -0.1, 'angle': 0}, 'zeta = -0.1: must be >= 0'),
             ({'zeta': 0, 'angle': 1.0}, 'angle = 1.0 rad: must lie in [-1, 1)'),
             ({'zeta': 0, 'angle_deg': 60}, 'angle_deg = 60.0 deg: must lie in [-57.2958, '
                                            '57.2958)'),
             ({'zeta': 0, 'angle': 0, 'items': [{}, {'mode': 'slo'}]},
              "items[1].mode = 'slo': must be one of fast, slow; did you mean 'slow'?"),
             ({'zeta': 0, 'angle': 0, 'items': [{'mode': 'slow'}]},
              'items[0]: gain is required when mode is slow'),
             ({'zeta': 0, 'angle': 0, 'items': [{'gian': 1.0}]},
              "items[0].gian: unknown key; did you mean 'gain'?"),
             ({'zeta': 0, 'angle': 0, 'table': {'a': 'heavy'}},
              "table.a = 'heavy' kg: expected a number in kg"),
             ({'zeta': 0, 'angle': 0, 'sizes': [1.0, 2.0]},
              'sizes = [1.0, 2.0]: expected a list of 3 items'),
             ({'zeta': float('nan'), 'angle': 0}, 'zeta = nan: not a finite number'),
             ({'angle': 0}, 'zeta: missing key'),
             ({'zeta': 0, 'angle': 0, 'angle_deg': 0},
              'angle: give either angle or angle_deg, not both'),
             ({'zeta': 0, 'angle': 0, 'colour': 1},
              'colour: unknown key; known keys: zeta, angle, angle_deg, sizes, items, table')]
    for data, message in cases:
        with pytest.raises(ConfigError) as info:
            build(_Outer, data, 'x.yaml')
        assert str(info.value) == f'x.yaml: {message}', data


def test_read_mapping_reports_the_yaml_line(tmp_path):
    path = tmp_path / 'x.yaml'
    path.write_text('a: 1\n  b: 2\n')
    with pytest.raises(ConfigError, match=rf'^{path}:2:4: not valid YAML: mapping values'):
        read_mapping(path)


# ------------------------------------------------------------------------------------- CLIs
def _run(tmp_path, *args) -> subprocess.CompletedProcess:
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get('PYTHONPATH',
                                                                                 '')]))
    return subprocess.run([sys.executable, '-m', *args], cwd=tmp_path, env=env,
                          capture_output=True, text=True, timeout=300)


def _one_error_line(proc, prog: str) -> str:
    assert proc.returncode == 1, proc.stderr
    assert 'Traceback' not in proc.stderr + proc.stdout
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(prog), proc.stderr
    return lines[0]


@pytest.fixture
def far_positions(tmp_path) -> Path:
    """A positions file whose only position lies 3 m off the machine axis."""
    path = tmp_path / 'far.yaml'
    path.write_text('positions:\n  FAR: {x: 3.0, y: 0.0, z: 0.85, a: 0.0, b: 0.0}\n')
    return path


@pytest.mark.parametrize('command', [
    ('pentapod_sim.cli.statespace', 'build'), ('pentapod_sim.cli.statespace', 'report'),
    ('pentapod_sim.cli.modes',)])
def test_unreachable_pose_is_one_line_exit_1(tmp_path, far_positions, command):
    proc = _run(tmp_path, *command, '--positions', str(far_positions), '--position', 'FAR',
                '--out', str(tmp_path / 'out'))
    prog = command[0].rsplit('.', 1)[1]
    line = _one_error_line(proc, f'{prog}: error: {far_positions}: ')
    assert "position 'FAR' cannot be reached" in line and 'stroke_max' in line
    assert not (tmp_path / 'out').exists() or not any((tmp_path / 'out').iterdir())


def test_statespace_misspelt_reduction_config_is_one_line(tmp_path, capsys):
    from pentapod_sim.cli.statespace import main
    doc = _raw('reduction.yaml')
    doc['static_corection'] = doc.pop('static_correction')
    path = _write(tmp_path, 'reduction.yaml', doc)
    assert main(['build', '--config', str(path), '--out', str(tmp_path)]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"statespace: error: {path}: static_corection: unknown key; did you mean "
                   f"'static_correction'?"]


def test_modes_unknown_position_names_the_file(tmp_path, far_positions, capsys):
    from pentapod_sim.cli.modes import main
    assert main(['--positions', str(far_positions), '--position', 'FRA']) == 1
    assert capsys.readouterr().err.strip().splitlines() == [
        f"modes: error: {far_positions}: no position 'FRA'; did you mean 'FAR'? (known: FAR)"]


def test_study_bad_config_is_one_line_exit_1(tmp_path):
    doc = _raw('study.yaml')
    doc['excitation']['amplitude'] = -10.0
    path = _write(tmp_path, 'study.yaml', doc)
    proc = _run(tmp_path, 'pentapod_damper.study', '--config', str(path), '--analytic-only',
                '--out', str(tmp_path / 'out'))
    line = _one_error_line(proc, 'study')
    assert line.endswith(f'{path}: excitation.amplitude = -10.0 N: must be > 0')
    assert proc.stdout == ''
