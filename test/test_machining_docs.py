"""docs/machining.md's table of minimum stable depths is what `statespace lobes` writes now."""
from pathlib import Path

import numpy as np
import pytest

from pentapod_sim.cli import statespace
from pentapod_sim.cli.statespace_lobes import DEPTH_SECTION
from pentapod_sim.reference import section_of
from pentapod_sim.scenario.files import scenario_names

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
