"""docs/machining.md's table of minimum stable depths is what the current code computes."""
from pathlib import Path

import numpy as np
import pytest

from pentapod_damper.scenario_laws import continuous_dampers, scenario_laws
from pentapod_sim.machining.lobes import milling_limit, turning_limit
from pentapod_sim.machining.materials import load_machining
from pentapod_sim.machining.tcp_frf import plant_poles, resonance_grid, tcp_frf
from pentapod_sim.plant.build import build_plant
from pentapod_sim.plant.frf import damper_feedback
from pentapod_sim.scenario.files import read_scenario

DOC = Path(__file__).resolve().parents[1] / 'docs' / 'machining.md'
SECTION = 'machining-depths'


def _rows() -> list[list[str]]:
    text = DOC.read_text(encoding='utf-8')
    body = text.split(f'<!-- {SECTION}:begin -->')[1].split(f'<!-- {SECTION}:end -->')[0]
    lines = body.strip().splitlines()[2:]
    return [[c.strip() for c in line.strip('|').split('|')] for line in lines]


def _depths(position: str, scenario: str) -> list[float]:
    """The table's four figures [mm], computed as the doc says."""
    plant = build_plant(position)
    table = load_machining()
    sections = read_scenario(scenario).sections
    dampers = continuous_dampers(scenario_laws(sections, 1.0 / 5000.0))
    poles = (np.linalg.eigvals(damper_feedback(plant, dampers).A) if dampers
             else plant_poles(plant))
    frf = tcp_frf(plant, resonance_grid(poles, 1.0, 1000.0), dampers or None)
    out = [milling_limit(frf, table.milling_cut(op)).minimum().depth
           for op in ('aluminium_half_down', 'steel_half_down')]
    for material in ('aluminium', 'steel'):
        k_tc = table.materials[material].coefficients()[0]
        out.append(turning_limit(frf.along([1.0, 0.0]), frf.freq, k_tc).minimum().depth)
    return [1e3 * d for d in out]


@pytest.mark.parametrize('row', _rows(), ids=lambda r: f'{r[0]}-{r[1]}')
def test_minimum_stable_depths_in_the_doc(row):
    got = _depths(row[0], row[1])
    stated = [float(c) for c in row[2:]]
    np.testing.assert_allclose(stated, got, rtol=1e-3)
    assert [float(f'{g:.4g}') for g in got] == stated       # printed to 4 digits


def test_the_table_lists_both_positions_and_scenarios():
    assert sorted((r[0], r[1]) for r in _rows()) == [
        ('P1', 'baseline'), ('P1', 'tcp_damping'), ('P2', 'baseline'), ('P2', 'tcp_damping')]
