"""
Run every benchmark and print one table of figures and ratios.

Usage::

    python bench/run_all.py [--quick] [--only modes,plant]
    python bench/run_all.py --tables      # run nothing: rebuild the tables from bench/results

The rows of each topic are kept in ``bench/results/<topic>.json``. ``bench/RESULTS.md``, the
one table of the benchmarks, is built from the latest rows of every topic after each run, so
``--only`` refreshes part of it; test/test_docs.py checks that it equals what ``--tables``
makes from the committed results. A row that the current ``bench_<topic>.py`` can no longer
produce (its name matches none of the script's row-name templates, see
:func:`row_name_patterns`) is left out and listed below the table.

Each ``bench/bench_<topic>.py`` module has ``run(quick: bool) -> list[dict]`` returning rows with
``name``, ``value``, ``unit``, ``baseline``, ``baseline_value``, ``ratio`` (> 1: ours is better)
and ``note``. Ratios compare against a baseline measured in the same run on the same input, so
they mean something on a shared, noisy machine where absolute times do not.
"""
from __future__ import annotations

import ast
import importlib.util
import json
import math
from pathlib import Path
import platform
import re
import sys
import time
import traceback

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))          # the bench scripts import the checkout's package
from pentapod_sim.cli import CommandParser  # noqa: E402

RESULTS = HERE / 'results'
COLUMNS = ('benchmark', 'ours', 'baseline', 'baseline figure', 'ratio', 'note')
TABLES_COMMAND = 'python bench/run_all.py --tables'


def _load(path: Path):
    spec = importlib.util.spec_from_file_location(path.stem, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _fmt(value, unit: str = '') -> str:
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return '-'
    if isinstance(value, float):
        text = f'{value:.4g}'
    else:
        text = str(value)
    return f'{text} {unit}'.strip()


def _ratio(r: dict) -> str:
    ratio = r.get('ratio')
    return '-' if ratio is None or math.isnan(ratio) else f'{ratio:.2f}x'


def _row(topic: str, r: dict) -> list[str]:
    return [f'{topic}: {r["name"]}', _fmt(r.get('value'), r.get('unit', '')),
            r.get('baseline') or '-', _fmt(r.get('baseline_value'), r.get('unit', '')),
            _ratio(r), r.get('note', '')]


def _table(rows: list[list[str]], columns: tuple[str, ...] = COLUMNS) -> str:
    lines = ['| ' + ' | '.join(columns) + ' |', '|' + '---|' * len(columns)]
    lines += ['| ' + ' | '.join(c.replace('|', '/') for c in row) + ' |' for row in rows]
    return '\n'.join(lines)


def _template(node: ast.expr) -> str | None:
    """Regular expression of a literal row name; f-string fields match any text, also none."""
    if isinstance(node, ast.Constant) and isinstance(node.value, str):
        return re.escape(node.value)
    if isinstance(node, ast.JoinedStr):
        return ''.join(re.escape(part.value) if isinstance(part, ast.Constant) else '.*'
                       for part in node.values)
    return None                       # a variable: its callers hold the literal


def row_name_patterns(script: Path) -> list[re.Pattern]:
    """
    Patterns of the row names a bench script can produce, read from its source.

    A row name is written either as the value of a ``'name'`` key of a dict literal or as the
    first argument of a helper of that script whose first parameter is ``name``; f-string
    fields (``{n_ctrl}``) match any text.
    """
    tree = ast.parse(script.read_text(encoding='utf-8'))
    helpers = {f.name for f in tree.body if isinstance(f, ast.FunctionDef)
               and f.args.args and f.args.args[0].arg == 'name'}
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Dict):
            found += [v for k, v in zip(node.keys, node.values)
                      if isinstance(k, ast.Constant) and k.value == 'name']
        elif isinstance(node, ast.Call) and getattr(node.func, 'id', None) in helpers:
            found += node.args[:1] + [k.value for k in node.keywords if k.arg == 'name']
    return [re.compile(t) for t in map(_template, found) if t is not None]


def load_results(results: Path = RESULTS, bench: Path = HERE) -> list[dict]:
    """
    The saved run of every topic, with the rows split by whether the current script makes them.

    Returns a list of dicts with ``topic``, ``saved`` (the JSON), ``rows`` (rows the current
    ``bench_<topic>.py`` can produce, or all rows if the script is gone) and ``retired``.
    """
    topics = []
    for path in sorted(results.glob('*.json')):
        saved = json.loads(path.read_text())
        script = bench / f'bench_{path.stem}.py'
        patterns = row_name_patterns(script) if script.exists() else None
        rows, retired = [], []
        for r in saved['rows']:
            current = patterns is None or any(p.fullmatch(r['name']) for p in patterns)
            (rows if current else retired).append(r)
        topics.append({'topic': path.stem, 'saved': saved, 'rows': rows, 'retired': retired})
    return topics


def _run_label(saved: dict) -> str:
    return f"{'quick' if saved['quick'] else 'full'}, {saved['date']}"


def results_markdown(topics: list[dict]) -> str:
    """bench/RESULTS.md: every current row with its note, then the runs and left-out rows."""
    rows = [_row(t['topic'], dict(r, note=f"{r.get('note', '')} [{_run_label(t['saved'])}]"))
            for t in topics for r in t['rows']]
    lines = ['# Benchmarks', '',
             f'Latest run of each topic, from `bench/results/*.json` (made by `{TABLES_COMMAND}`'
             '; a run of `python bench/run_all.py` refreshes it). Ratio > 1: ours is better '
             'than the baseline measured in the same run on the same input.', '',
             _table(rows), '', 'Runs:', '']
    for t in topics:
        saved = t['saved']
        where = ', '.join(str(saved[k]) for k in ('machine', 'python') if k in saved)
        lines.append(f"- {t['topic']}: {_run_label(saved)}, {saved['seconds']:.0f} s"
                     + (f', {where}' if where else ''))
    retired = [f"{t['topic']}: {r['name']} ({r.get('baseline') or '-'})"
               for t in topics for r in t['retired']]
    if retired:
        lines += ['', 'Left out (rows of a saved run that the current script no longer makes; '
                  'they go with the next run of the topic):', '']
        lines += [f'- {name}' for name in retired]
    return '\n'.join(lines) + '\n'


def write_tables(results: Path = RESULTS, out: Path = HERE / 'RESULTS.md') -> None:
    """Rewrite bench/RESULTS.md from the saved results."""
    out.write_text(results_markdown(load_results(results)))


def _run(path: Path, quick: bool) -> bool:
    topic = path.stem[len('bench_'):]
    print(f'[bench] {topic} ...', flush=True)
    t0 = time.perf_counter()
    try:
        results = _load(path).run(quick=quick)
    except Exception:  # a broken benchmark must not hide the others' figures
        traceback.print_exc()
        return False
    for r in results:
        print('   ', ' | '.join(_row(topic, r)), flush=True)
    elapsed = time.perf_counter() - t0
    print(f'[bench] {topic} done in {elapsed:.1f} s', flush=True)
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / f'{topic}.json').write_text(json.dumps(
        {'quick': quick, 'date': time.strftime('%Y-%m-%d %H:%M'), 'seconds': elapsed,
         'machine': platform.processor() or platform.machine(),
         'python': f'Python {platform.python_version()}', 'rows': results},
        indent=1, default=float))
    return True


def main(argv: list[str] | None = None) -> int:
    """Run the selected benchmarks; return 1 if any of them failed to run."""
    parser = CommandParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--quick', action='store_true', help='short smoke version (CI)')
    parser.add_argument('--only', default='', help='comma-separated topics, e.g. modes,plant')
    parser.add_argument('--tables', action='store_true',
                        help='run nothing; rebuild bench/RESULTS.md')
    args = parser.parse_args(argv)
    wanted = {t for t in args.only.split(',') if t}
    failed = []
    for path in [] if args.tables else sorted(HERE.glob('bench_*.py')):
        if (not wanted or path.stem[len('bench_'):] in wanted) and not _run(path, args.quick):
            failed.append(path.stem[len('bench_'):])
    write_tables()
    print((HERE / 'RESULTS.md').read_text())
    if failed:
        print(f'failed to run: {", ".join(failed)}')
    return 1 if failed else 0


if __name__ == '__main__':
    sys.exit(main())
