"""Smoke test of the benchmark harness: fast benchmarks run and return well-formed rows."""
import importlib.util
from pathlib import Path

import pytest

BENCH = Path(__file__).resolve().parents[1] / 'bench'
KEYS = {'name', 'value', 'unit'}


def _load(name: str):
    spec = importlib.util.spec_from_file_location(name, BENCH / f'{name}.py')
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_every_benchmark_has_a_run_function():
    scripts = sorted(BENCH.glob('bench_*.py'))
    assert len(scripts) >= 5
    for path in scripts:
        assert 'def run(quick' in path.read_text(), path.name


@pytest.mark.parametrize('name', ['bench_assembly', 'bench_statespace'])
def test_quick_benchmark_rows(name):
    rows = _load(name).run(quick=True)
    assert rows
    for row in rows:
        assert KEYS <= set(row), row
        assert row['value'] > 0
        if row.get('ratio') is not None:
            assert row['ratio'] > 0


def test_table_lists_every_row():
    run_all = _load('run_all')
    row = run_all._row('demo', {'name': 'x', 'value': 2.0, 'unit': 's', 'baseline': 'y',
                                'baseline_value': 4.0, 'ratio': 2.0, 'note': 'n'})
    table = run_all._table([row])
    assert '| demo: x | 2 s | y | 4 s | 2.00x | n |' in table
