"""
docs/dampers.md says what docs/results/dampers.csv says, and the CSV what the code computes.

The Markdown table and the verdict are generated from the CSV (``python -m
pentapod_damper.design --docs docs/dampers.md``); the slow test recomputes the best strut-only
row at P1 from its gains on freshly built models.
"""
from pathlib import Path

import pytest

from pentapod_damper.design.report import (
    best_strut_law,
    energy_lines,
    fill,
    markdown_records,
    read_csv,
    verdict,
)
from pentapod_damper.design.rows import default_rows
from pentapod_damper.design.scenarios import (
    node_params,
    scenario_text,
    SCENARIOS,
    shipped_records,
)
from pentapod_sim.sim.design_models import load_design_model
from pentapod_sim.sim.law_models import Dynamics
from pentapod_sim.sim.tuning import Judge, TuneSettings

ROOT = Path(__file__).resolve().parents[1]
DOC = ROOT / 'docs' / 'dampers.md'
CSV = ROOT / 'docs' / 'results' / 'dampers.csv'
ENERGY = ROOT / 'docs' / 'results' / 'dampers_energy.csv'


def test_docs_table_and_verdict_are_the_csv():
    records = read_csv(CSV)
    text = DOC.read_text()
    expected = fill(fill(text, 'dampers-table', markdown_records(records)), 'dampers-verdict',
                    verdict(records))
    assert text == fill(expected, 'dampers-energy', energy_lines(ENERGY))


def _values(gains: str) -> dict[str, float]:
    return {} if gains == '-' else {
        k: float(v) for k, v in (item.split(' ') for item in gains.split('; '))}


@pytest.mark.slow
def test_best_strut_law_at_p1_is_what_the_code_computes(tmp_path):
    records = [r for r in read_csv(CSV) if (r['position'], r['machine'], r['delay_steps'])
               == ('P1', 'locked', '0')]
    best = best_strut_law(records)
    assert best is not None
    spec = next(s for s in default_rows() if s.name == best['law'])
    model = load_design_model('P1', float(best['sample_rate_hz']), cache_dir=tmp_path)
    settings = TuneSettings(sample_rate=float(best['sample_rate_hz']),
                            dynamics=Dynamics(delay_steps=int(best['delay_steps'])))
    judge = Judge(model, spec.family, settings)
    ev = judge.evaluate(_values(best['gains']))
    assert ev.feasible
    assert judge.baseline.peak / ev.peak == pytest.approx(float(best['peak_reduction']),
                                                          rel=1e-4)
    assert ev.static_ratio == pytest.approx(float(best['static_ratio']), rel=1e-6)
    radii = judge.check(_values(best['gains']))        # the full check model (every mode)
    assert 1 - radii[0] == pytest.approx(float(best['full_check_margin']), rel=1e-3)
    assert 1 - radii[1] == pytest.approx(float(best['full_check_margin_extra_delay']),
                                         rel=1e-3)


def test_shipped_scenarios_are_the_tuned_records():
    """config/scenarios/<law>_struts.yaml hold the gains the table tuned (first position)."""
    records = read_csv(CSV)
    position = next(r['position'] for r in records)
    model = load_design_model(position, check=False, corners=False)
    written = 0
    for record in shipped_records(records, position):
        if record['law'] in SCENARIOS:
            name = SCENARIOS[record['law']][0]
            shipped = (ROOT / 'config' / 'scenarios' / f'{name}.yaml').read_text()
            assert shipped == scenario_text(record, node_params(record, model.stiffness)), name
            written += 1
    assert written == len(SCENARIOS)
