"""
Run every benchmark and print one table of figures and ratios.

Usage::

    python bench/run_all.py [--quick] [--only modal,plant] [--out bench/RESULTS.md]

The rows of each topic are also kept in ``bench/results/<topic>.json``; the Markdown table is
built from the latest rows of every topic, so ``--only`` refreshes part of it.

Each ``bench/bench_<topic>.py`` module has ``run(quick: bool) -> list[dict]`` returning rows with
``name``, ``value``, ``unit``, ``baseline``, ``baseline_value``, ``ratio`` (> 1: ours is better)
and ``note``. Ratios compare against a baseline measured in the same run on the same input, so
they mean something on a shared, noisy machine where absolute times do not.
"""
from __future__ import annotations

import argparse
import importlib.util
import json
import math
from pathlib import Path
import platform
import sys
import time
import traceback

HERE = Path(__file__).resolve().parent
RESULTS = HERE / 'results'
COLUMNS = ('benchmark', 'ours', 'baseline', 'baseline figure', 'ratio', 'note')


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


def _row(topic: str, r: dict) -> list[str]:
    ratio = r.get('ratio')
    return [f'{topic}: {r["name"]}', _fmt(r.get('value'), r.get('unit', '')),
            r.get('baseline') or '-', _fmt(r.get('baseline_value'), r.get('unit', '')),
            '-' if ratio is None else f'{ratio:.2f}x', r.get('note', '')]


def _table(rows: list[list[str]]) -> str:
    lines = ['| ' + ' | '.join(COLUMNS) + ' |', '|' + '---|' * len(COLUMNS)]
    lines += ['| ' + ' | '.join(c.replace('|', '/') for c in row) + ' |' for row in rows]
    return '\n'.join(lines)


def main(argv: list[str] | None = None) -> int:
    """Run the selected benchmarks; return 1 if any of them failed to run."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--quick', action='store_true', help='short smoke version (CI)')
    parser.add_argument('--only', default='', help='comma-separated topics, e.g. modal,plant')
    parser.add_argument('--out', type=Path, default=HERE / 'RESULTS.md')
    args = parser.parse_args(argv)
    wanted = {t for t in args.only.split(',') if t}
    rows, failed = [], []
    for path in sorted(HERE.glob('bench_*.py')):
        topic = path.stem[len('bench_'):]
        if wanted and topic not in wanted:
            continue
        print(f'[bench] {topic} ...', flush=True)
        t0 = time.perf_counter()
        try:
            results = _load(path).run(quick=args.quick)
        except Exception:  # a broken benchmark must not hide the others' figures
            traceback.print_exc()
            failed.append(topic)
            continue
        for r in results:
            print('   ', ' | '.join(_row(topic, r)), flush=True)
        elapsed = time.perf_counter() - t0
        print(f'[bench] {topic} done in {elapsed:.1f} s', flush=True)
        RESULTS.mkdir(exist_ok=True)
        (RESULTS / f'{topic}.json').write_text(json.dumps(
            {'quick': args.quick, 'date': time.strftime('%Y-%m-%d %H:%M'), 'seconds': elapsed,
             'rows': results}, indent=1, default=float))
    for path in sorted(RESULTS.glob('*.json')):
        saved = json.loads(path.read_text())
        mode = 'quick' if saved['quick'] else 'full'
        rows += [_row(path.stem, dict(r, note=f"{r.get('note', '')} [{mode}, {saved['date']}]"))
                 for r in saved['rows']]
    table = _table(rows)
    made = time.strftime('%Y-%m-%d %H:%M')
    header = (f'Benchmarks (latest run of each topic; table made {made}), '
              f'{platform.processor() or platform.machine()}, Python {platform.python_version()}')
    print('\n' + header + '\n\n' + table)
    if failed:
        print(f'\nfailed to run: {", ".join(failed)}')
    args.out.write_text(f'# {header}\n\n{table}\n' + (
        f'\nFailed to run: {", ".join(failed)}\n' if failed else ''))
    return 1 if failed else 0


if __name__ == '__main__':
    sys.exit(main())
