"""config/machining.yaml: the shipped table, the Kienzle linearisation, operations to cuts."""
import math
from pathlib import Path
import re

import pytest
import yaml

from pentapod_sim.errors import ConfigError
from pentapod_sim.machining.materials import KienzleLaw, load_machining
from pentapod_sim.machining.milling_cut import immersion_angles

CONFIG = Path(__file__).resolve().parents[1] / 'config' / 'machining.yaml'


def _raw() -> dict:
    return yaml.safe_load(CONFIG.read_text(encoding='utf-8'))


def test_shipped_table_gives_the_raw_values():
    raw, table = _raw(), load_machining()
    assert table.spindle_speeds == tuple(raw['spindle_speeds'])
    assert set(table.materials) == {'aluminium', 'steel'}
    assert sorted(t.teeth for t in table.tools.values()) == [2, 3, 4, 6]
    alu = table.materials['aluminium'].coefficients()
    assert alu == (796e6, pytest.approx(0.212 * 796e6), 0.0, 0.0)
    for name, op in raw['operations'].items():
        cut = table.milling_cut(name)
        assert cut.teeth == raw['tools'][op['tool']]['teeth']
        assert (cut.entry_angle, cut.exit_angle) == immersion_angles(op['radial_immersion'],
                                                                     op['milling'])
        assert cut.radial_ratio == raw['materials'][op['material']]['radial_ratio']


def test_kienzle_tangent_touches_the_power_law():
    law = KienzleLaw(1780e6, 0.25, 1e-4)
    k_tc, k_te = law.tangent()

    def force(h):          # per unit width [N/m]: k_c1.1 h^(1 - m_c), h in mm, k_c1.1 N/mm^2
        return 1780.0 * (h * 1e3) ** 0.75 * 1e3
    assert k_tc * 1e-4 + k_te == pytest.approx(force(1e-4), rel=1e-12)
    slope = (force(1e-4 * (1 + 1e-6)) - force(1e-4 * (1 - 1e-6))) / (2e-10)
    assert k_tc == pytest.approx(slope, rel=1e-6)


def test_the_steel_description_states_the_computed_coefficients():
    steel = load_machining().materials['steel']
    k_tc, _, k_te, _ = steel.coefficients()
    text = ' '.join(steel.description.split())
    assert f'K_tc = {k_tc / 1e6:.0f} N/mm^2' in text
    assert f'K_te = {k_te / 1e3:.0f} N/mm' in text
    stated = re.search(r'k_c1.1 = (\d+) N/mm\^2, m_c = ([\d.]+), linearised at a mean chip of '
                       r'([\d.]+) mm', text).groups()
    assert (float(stated[0]) * 1e6, float(stated[1]), float(stated[2]) * 1e-3) == (
        steel.kienzle.specific_force, steel.kienzle.exponent,
        pytest.approx(steel.kienzle.chip_thickness))


def test_conditions_of_an_operation():
    table = load_machining()
    cond = table.conditions('steel_half_down', 8000.0, 1e-3)
    assert cond.tooth_period == pytest.approx(60.0 / (4 * 8000.0))
    assert cond.edge_tangential == pytest.approx(table.materials['steel'].kienzle.tangent()[1])
    assert cond.cut.exit_angle == pytest.approx(math.pi)
    with pytest.raises(ConfigError, match="operation = 'steel_half_dwn': .*did you mean "
                                          "'steel_half_down'"):
        table.conditions('steel_half_dwn', 8000.0, 1e-3)


def test_a_material_needs_exactly_one_force_law(tmp_path):
    raw = _raw()
    raw['materials']['aluminium']['kienzle'] = raw['materials']['steel']['kienzle']
    path = tmp_path / 'machining.yaml'
    path.write_text(yaml.safe_dump(raw), encoding='utf-8')
    with pytest.raises(ConfigError, match=rf'^{path}: materials.aluminium: give exactly one of '
                                          'tangential and kienzle$'):
        load_machining(path)
