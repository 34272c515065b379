"""docs/machining.md's table of minimum stable depths is what `statespace lobes` writes now."""
from pathlib import Path

import numpy as np
import pytest

from pentapod_sim.cli import statespace
from pentapod_sim.cli.statespace_lobes import DEPTH_SECTION, position_lobes, RUNS_SECTION
from pentapod_sim.machining.loop_lobes import check_runs
from pentapod_sim.machining.materials import load_machining
from pentapod_sim.plant.build import build_plant
from pentapod_sim.reference import section_of
from pentapod_sim.scenario.files import scenario_names
from pentapod_sim.scenario.laws import scenario_loop_laws

DOC = Path(__file__).resolve().parents[1] / 'docs' / 'machining.md'
#: The command line the doc names for its table (without --depth-table and --out).
COMMAND = ['lobes', '--scenario', 'all', '--operation', 'aluminium_half_down,steel_half_down']

pytestmark = pytest.mark.slow


def _rows(text: str) -> list[list[str]]:
    lines = section_of(text, DEPTH_SECTION).splitlines()[2:]
    return [[c.strip() for c in line.strip('|').split('|')] for line in lines]


def _numbers(row: list[str]) -> list[float]:
    """Depths [mm] and gains [-] of a row."""
    gains = [float(g.strip().rstrip('x')) for g in row[-1].split('/')]
    return [float(c) for c in row[2:-1]] + gains


def test_the_doc_names_the_command_that_writes_its_table():
    text = DOC.read_text(encoding='utf-8')
    assert 'statespace ' + ' '.join(COMMAND) + ' --depth-table docs/machining.md' in text


def test_the_depth_table_is_what_the_command_writes(tmp_path, capsys):
    copy = tmp_path / 'machining.md'
    copy.write_text(DOC.read_text(encoding='utf-8'), encoding='utf-8')
    assert statespace.main([*COMMAND, '--depth-table', str(copy), '--out', str(tmp_path)]) == 0
    capsys.readouterr()
    stated, made = _rows(DOC.read_text(encoding='utf-8')), _rows(copy.read_text())
    assert [r[:2] for r in stated] == [r[:2] for r in made]
    assert sorted({r[1] for r in stated}) == scenario_names()
    assert sorted({r[0] for r in stated}) == ['P1', 'P2']
    for old, new in zip(stated, made):           # 4 digits (gains 3): allow the last one
        np.testing.assert_allclose(_numbers(old), _numbers(new), rtol=2e-3, err_msg=old[1])
    baseline = [r for r in made if r[1] == 'baseline']
    assert all(_numbers(r)[-2:] == [1.0, 1.0] for r in baseline)


#: The command line the doc names for its table of recorded cuts (without --record, --out).
RUNS_COMMAND = ['lobes', '--position', 'P1,P2', '--scenario', 'baseline,tcp_damping']


def test_the_recorded_cuts_are_what_the_code_predicts_and_came_out_as_predicted():
    """Speeds, limits, depths, durations and predicted rates are the current code's checks."""
    text = DOC.read_text(encoding='utf-8')
    assert ('statespace ' + ' '.join(RUNS_COMMAND) + ' --record out/cutting --runs-table '
            'docs/machining.md') in text
    rows = _rows_of(section_of(text, RUNS_SECTION))
    assert sorted({(r[0], r[1]) for r in rows}) == [
        ('P1', 'baseline'), ('P1', 'tcp_damping'), ('P2', 'baseline'), ('P2', 'tcp_damping')]
    table = load_machining()
    for position in ('P1', 'P2'):
        plant = build_plant(position)
        for rec in position_lobes(plant, position, ['baseline', 'tcp_damping'], table,
                                  ['aluminium_half_down'], np.linspace(*table.spindle_speeds,
                                                                       2000)):
            laws = scenario_loop_laws(rec.label, rec.loop.dt)
            point = check_runs(plant, laws, rec.loop.dt, table,
                               rec.operations['aluminium_half_down'])
            stated = [r for r in rows if (r[0], r[1]) == (position, rec.label)]
            assert [r[6] for r in stated] == [f'{run.factor:g}x' for run in point.runs]
            for row, run in zip(stated, point.runs):
                assert row[2] == 'aluminium_half_down'
                assert float(row[3]) == pytest.approx(point.speed, abs=0.06)
                assert float(row[4]) == pytest.approx(point.depth * 1e3, rel=1e-3)
                assert float(row[5]) == pytest.approx(point.chatter_freq, abs=0.06)
                assert float(row[7]) == pytest.approx(run.params['axial_depth'] * 1e3,
                                                      rel=1e-3)
                assert float(row[8]) == pytest.approx(run.duration, rel=5e-3)
                assert row[9] == run.expected
                assert float(row[14]) == pytest.approx(run.growth_rate, rel=1e-2, abs=1e-3)
    misses = [r for r in rows if r[9] != r[10]]
    assert not misses, misses


def _rows_of(section: str) -> list[list[str]]:
    return [[c.strip() for c in line.strip('|').split('|')]
            for line in section.splitlines()[2:]]
