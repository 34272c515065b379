"""Tests of the machine parameter schema and loaders (pentapod_sim.fe.machine_data)."""
import copy
import math

import pytest
import yaml

from pentapod_sim.errors import ConfigError
from pentapod_sim.fe.machine_data import (
    config_dir,
    load_machine,
    load_positions,
    machine_from_dict,
)


@pytest.fixture(scope='module')
def raw():
    with open(config_dir() / 'machine.yaml', encoding='utf-8') as stream:
        return yaml.safe_load(stream)


def _set(data, path, value):
    out = copy.deepcopy(data)
    node = out
    keys = path.split('.')
    for key in keys[:-1]:
        node = node[key]
    if value is _DELETE:
        del node[keys[-1]]
    else:
        node[keys[-1]] = value
    return out


_DELETE = object()


def test_default_file_loads_and_converts_degrees(raw):
    machine = load_machine()
    assert machine.source.endswith('machine.yaml')
    bp_deg = raw['bp_joints']['angles_deg'][0]
    assert machine.bp_joints.angles[0] == pytest.approx(math.radians(bp_deg))
    wp_deg = raw['wp_joints']['angle_max_deg']
    assert machine.wp_joints.angle_max == pytest.approx(math.radians(wp_deg))
    assert machine.installation.foot_stiffness_z == raw['installation']['foot_stiffness_z']


@pytest.mark.parametrize(('path', 'value', 'expected'), [
    ('installation.foot_stiffness_x', -1.0e8,
     r'installation\.foot_stiffness_x = -100000000\.0 N/m: must be > 0'),
    ('feed_drives.nut_axial_stiffness', 'stiff',
     r"feed_drives\.nut_axial_stiffness = 'stiff' N/m: expected a number in N/m"),
    ('frame.bed_inertia', [1.0, 2.0],
     r'frame\.bed_inertia = \[1\.0, 2\.0\]: expected a list of 3'),
    ('mesh.min_elements_per_member', 2.5,
     r'mesh\.min_elements_per_member = 2\.5: expected an integer'),
    ('struts.section.thickness', 0.2, r'struts\.section\.thickness 0\.2 is too large'),
    ('struts.stroke_min', 2.0, r'struts\.stroke_min 2\.0 must be < struts\.stroke_max'),
    ('platform.mass', True, r'platform\.mass = True kg: expected a number'),
    ('bp_joints.angle_max_deg', -5, r'bp_joints\.angle_max_deg = -5\.0 deg: must be > 0'),
])
def test_bad_values_name_file_key_and_value(raw, path, value, expected):
    with pytest.raises(ConfigError, match=r'^machine\.yaml: ' + expected):
        machine_from_dict(_set(raw, path, value), source='machine.yaml')


def test_missing_and_unknown_keys(raw):
    with pytest.raises(ConfigError, match=r'wp_joints\.axial_stiffness: missing key'):
        machine_from_dict(_set(raw, 'wp_joints.axial_stiffness', _DELETE))
    with pytest.raises(ConfigError, match=r'struts\.colour: unknown key; known keys: tube_'):
        machine_from_dict(_set(raw, 'struts.colour', 'red'))
    with pytest.raises(ConfigError, match=r"struts\.shear_factr: unknown key; did you mean "
                                          r"'shear_factor'\?"):
        machine_from_dict(_set(raw, 'struts.shear_factr', 0.8))
    both = _set(raw, 'wp_joints.angle_max', 0.5)
    with pytest.raises(ConfigError, match='either angle_max or angle_max_deg'):
        machine_from_dict(both)


def test_config_error_is_value_error_and_unreadable_file(tmp_path):
    assert issubclass(ConfigError, ValueError)
    with pytest.raises(ConfigError, match='absent.yaml: cannot read'):
        load_machine(tmp_path / 'absent.yaml')
    bad = tmp_path / 'bad.yaml'
    bad.write_text('mesh: [unclosed\n')
    with pytest.raises(ConfigError, match=r'bad\.yaml:2:1: not valid YAML') as info:
        load_machine(bad)
    assert '\n' not in str(info.value)


def test_positions_degrees_and_radians(tmp_path):
    positions = load_positions()
    assert {'P1', 'P2'} <= set(positions)
    assert positions['P1'].shape == (5,)
    path = tmp_path / 'pos.yaml'
    path.write_text('positions:\n  A: {x: 0.1, y: 0, z: 0.8, a_deg: 90, b: 0.5}\n')
    pose = load_positions(path)['A']
    assert pose == pytest.approx([0.1, 0.0, 0.8, math.pi / 2, 0.5])
    path.write_text('positions:\n  A: {x: 0.1, y: 0, z: 0.8, a_deg: 90}\n')
    with pytest.raises(ConfigError, match=r'pos\.yaml: positions\.A\.b: missing key'):
        load_positions(path)
    path.write_text('positions: {}\n')
    with pytest.raises(ConfigError, match=r'pos\.yaml: positions = \{\}: expected a mapping of '
                                          r'at least 1 item'):
        load_positions(path)


def test_per_strut_tube_and_stroke_accept_one_number_or_five(raw):
    one = machine_from_dict(_set(_set(_set(raw, 'struts.tube_length', 2.4),
                                      'struts.stroke_max', 1.8), 'struts.stroke_min', 0.7))
    assert one.struts.tube_length == (2.4,) * 5
    assert one.struts.stroke_max == (1.8,) * 5 and one.struts.stroke_min == (0.7,) * 5
    five = machine_from_dict(_set(raw, 'struts.tube_length', [2.6, 2.6, 1.9, 1.9, 2.5]))
    assert five.struts.tube_length == (2.6, 2.6, 1.9, 1.9, 2.5)
    with pytest.raises(ConfigError,
                       match=r'struts\.tube_length = \[2\.6, 2\.6\]: expected a list of 5'):
        machine_from_dict(_set(raw, 'struts.tube_length', [2.6, 2.6]))
    # strut 3's tube too short for its own stroke: the message names the strut
    short = _set(raw, 'struts.tube_length', [2.65, 2.65, 1.20, 1.93, 2.50])
    with pytest.raises(ConfigError, match=r'struts\.stroke_max 1\.4 must be < struts\.tube_length '
                                          r'1\.2 \(strut 3'):
        machine_from_dict(short)
