"""
Docs that cannot drift: generated tables equal their generators, stated facts equal the code.

* bench/RESULTS.md is what ``python bench/run_all.py --tables`` makes from the committed
  bench/results (no benchmark runs here).
* docs/results.md's study tables and the README's result sentences are what
  ``python -m pentapod_damper.study docs`` makes from docs/results/*.csv, and the analytic
  columns of those CSV copies are what the current code and config/study.yaml compute (the
  recorded columns need the ROS runs of the study).
* The README stays a newcomer's page: short, the two commands, its figure drawn from the
  current code (docs/dataflow.py), its example's options taken as written.
* Topic tables, module paths, links, commands and stated defaults in README.md and docs/*.md
  exist in, and agree with, the code.
"""
import ast
import importlib
import importlib.util
import inspect
import json
import math
from pathlib import Path
import re

import numpy as np
import pytest

from pentapod_damper.study import readme as study_readme
from pentapod_damper.study.config import load_study_config
from pentapod_damper.study.records import as_row, StudyResults
from pentapod_damper.study.tables import (
    pma_highpass_rows,
    pma_rows,
    struts12_share,
    summary_rows,
)
from pentapod_sim import interface
from pentapod_sim.registry import executables

ROOT = Path(__file__).resolve().parents[1]
EXECUTABLES = executables()
README = ROOT / 'README.md'
MARKDOWN = [README, *sorted((ROOT / 'docs').glob('*.md'))]
RESULTS = ROOT / 'docs' / 'results'
RESULTS_MD = ROOT / 'docs' / 'results.md'
BENCH_MD = ROOT / 'bench' / 'RESULTS.md'
STALE = ('docs/results/ is stale: run tools/study.sh, then '
         'python -m pentapod_damper.study docs --from out/study')


def _run_all():
    spec = importlib.util.spec_from_file_location('run_all', ROOT / 'bench' / 'run_all.py')
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _section(text: str, name: str) -> str:
    return text.split(f'<!-- {name}:begin -->')[1].split(f'<!-- {name}:end -->')[0].strip()


def _table_rows(text: str, first_header: str) -> list[list[str]]:
    """Body rows (cells stripped) of every Markdown table whose first header is given."""
    rows, inside = [], False
    for line in text.splitlines():
        if not line.startswith('|'):
            inside = False
            continue
        cells = [c.strip() for c in line.strip().strip('|').split('|')]
        if cells[0] == first_header:
            inside = True
        elif inside and not set(cells[0]) <= set('-'):
            rows.append(cells)
    return rows


def _number(cell: str) -> float:
    return float(re.match(r'[-+0-9.e]+', cell).group(0).rstrip('.'))


# --- benchmark tables --------------------------------------------------------------------------

def test_results_md_is_made_from_the_results():
    run_all = _run_all()
    assert BENCH_MD.read_text() == run_all.results_markdown(run_all.load_results())


def test_benchmark_figures_are_those_of_the_json_files():
    """Read back from bench/RESULTS.md and compared with the JSON, not with the formatter."""
    rows = _table_rows(BENCH_MD.read_text().split('Runs:')[0], 'benchmark')
    # a row is named by its benchmark and its baseline (one benchmark may have two baselines)
    shown = {(row[0], row[2]): row for row in rows}
    assert len(shown) == len(rows)
    retired = 0
    for path in sorted((ROOT / 'bench' / 'results').glob('*.json')):
        for r in json.loads(path.read_text())['rows']:
            row = shown.get((f'{path.stem}: {r["name"]}', str(r.get('baseline') or '-')))
            if row is None:
                retired += 1
                continue
            if math.isfinite(r['value']):
                assert _number(row[1]) == pytest.approx(r['value'], rel=1e-3), row
            else:                                 # no figure, e.g. a solver that was stopped
                assert row[1] == '-', row
            if r.get('baseline_value') is not None and math.isfinite(r['baseline_value']):
                assert _number(row[3]) == pytest.approx(r['baseline_value'], rel=1e-3), row
            if r.get('ratio') is not None and math.isfinite(r['ratio']):
                assert _number(row[4]) == pytest.approx(r['ratio'], abs=0.006), row
            elif r.get('ratio') is not None:     # e.g. no missed deadline against a target
                assert row[4] == '-', row
    assert len(shown) > 10
    # the lfilter fast path (simulate_linear) was deleted from bench_plant.py
    assert not any('lfilter' in name for name, _ in shown)
    assert retired == sum(len(t['retired']) for t in _run_all().load_results())


def test_rows_a_bench_script_no_longer_makes_are_left_out(tmp_path):
    bench, results = tmp_path / 'bench', tmp_path / 'results'
    bench.mkdir()
    results.mkdir()
    (bench / 'bench_demo.py').write_text(
        'def _row(name, value):\n'
        "    return {'name': name, 'value': value, 'unit': 's'}\n\n\n"
        'def run(quick):\n'
        '    n = 3\n'
        "    return [_row(f'kept {n} things', 1.0), {'name': 'plain', 'value': 2.0}]\n")
    rows = [{'name': n, 'value': 1.0, 'unit': 's'}
            for n in ('kept 7 things', 'plain', 'lfilter fast path', 'kept things')]
    saved = {'quick': True, 'date': '2026-01-01 00:00', 'seconds': 1.0, 'rows': rows}
    (results / 'demo.json').write_text(json.dumps(saved))
    (results / 'gone.json').write_text(json.dumps(dict(saved, rows=rows[2:3])))
    run_all = _run_all()
    demo, gone = run_all.load_results(results, bench)
    assert [r['name'] for r in demo['rows']] == ['kept 7 things', 'plain']
    assert [r['name'] for r in demo['retired']] == ['lfilter fast path', 'kept things']
    assert [r['name'] for r in gone['rows']] == ['lfilter fast path']   # no script: all kept
    text = run_all.results_markdown([demo])
    table, left_out = text.split('Left out')
    assert 'demo: kept 7 things' in table and 'lfilter' not in table
    assert 'demo: lfilter fast path' in left_out


def test_replace_section_names_a_missing_or_doubled_marker():
    text = 'a\n<!-- t:begin -->\nold\n<!-- t:end -->\nb\n'
    assert study_readme.replace_section(text, 't', 'new\n') == (
        'a\n<!-- t:begin -->\nnew\n<!-- t:end -->\nb\n')
    with pytest.raises(ValueError, match='<!-- u:begin -->'):
        study_readme.replace_section(text, 'u', 'x')
    with pytest.raises(ValueError, match='found 2'):
        study_readme.replace_section(text + text, 't', 'x')


# --- study tables ------------------------------------------------------------------------------

def test_results_md_study_tables_are_made_from_the_committed_csv():
    section = _section(RESULTS_MD.read_text(), study_readme.SECTION)
    assert section == study_readme.study_section(RESULTS, load_study_config()).strip()
    csv_rows = {(r['position'], r['scenario']): r
                for r in study_readme.read_csv(RESULTS / 'summary.csv')}
    shown = _table_rows(section, 'position')[:len(csv_rows)]
    n_runs = len(load_study_config().positions) * len(load_study_config().scenarios)
    assert len(shown) == len(csv_rows) == n_runs
    for row in shown:
        ref = csv_rows[(row[0], row[1].strip('`'))]
        shown_row = dict(zip([c[0] for c in study_readme.COLUMNS['summary']], row))
        for column in ('peak_um_per_N', 'peak_reduction', 'rms_reduction'):
            assert _number(shown_row[column]) == pytest.approx(float(ref[column]), rel=5e-3)


def test_readme_result_sentences_are_made_from_the_committed_csv():
    """The README's sentences equal the generator's, and their figures the CSV's, read back."""
    cfg = load_study_config()
    section = _section(README.read_text(), study_readme.SUMMARY)
    assert section == study_readme.summary_section(RESULTS, cfg).strip()
    text = ' '.join(section.split())
    summary = {(r['position'], r['scenario']): r
               for r in study_readme.read_csv(RESULTS / 'summary.csv')}
    stated = re.findall(r'([\d.]+) / ([\d.]+)-fold with the ([\w\s]+?)(?:,|\s\()', text)
    labels = {label: scn for scn, label in study_readme.SUMMARY_SCENARIOS}
    assert [labels[name] for *_, name in stated] == [
        scn for scn, _ in study_readme.SUMMARY_SCENARIOS]
    for p1, p2, name in stated:
        for value, pos in ((p1, 'P1'), (p2, 'P2')):
            assert float(value) == pytest.approx(
                float(summary[(pos, labels[name])]['peak_reduction']), rel=5e-3), name
    share = {r['position']: r for r in study_readme.read_csv(RESULTS / 'struts12_share.csv')}
    peak = re.search(r'alone give (\d+)% \(P1\) and (\d+)% \(P2\) of the peak', text)
    rms = re.search(r'and (\d+)% and (\d+)% of the RMS improvement', text)
    for match, column in ((peak, 'peak_share'), (rms, 'rms_share')):
        for value, pos in zip(match.groups(), ('P1', 'P2')):
            assert int(value) == round(100 * float(share[pos][column])), (column, pos)
    # the verdict on the paper's 70 %, worked out here from the shares
    for name, column in (('peak', 'peak_share'), ('RMS', 'rms_share')):
        holds = [p for p in ('P1', 'P2') if float(share[p][column]) >= 0.7]
        verdict = {0: 'at neither position', 2: 'at both positions'}.get(
            len(holds), f'at {holds[0] if holds else ""} only')
        assert f'by {name} {verdict}' in text, (name, holds)
    stable = sum(r['sampled_loop'] == 'stable' for r in summary.values())
    assert (f'All {stable} sampled loops' if stable == len(summary)
            else f'{stable} of the {len(summary)} sampled loops') in text
    worst = max(float(r['deviation_db']) for r in summary.values())
    assert float(re.search(r'by at most ([\d.e+-]+) dB', text).group(1)) == pytest.approx(
        worst, rel=0.05)
    # the study's FRF runs: every line of every scenario at every position within 1 dB of the
    # sampled loop (issue: measured peaks as the analytic ones)
    assert worst < 1.0, worst


def _analytic_results(out_dir: Path) -> StudyResults:
    """
    What the study computes before its ROS runs, with its own pipeline functions.

    Fresh plants of both positions; the truncation check against the (slow to build) check
    models is left out: it flags loops but changes none of the tables' numbers.
    """
    from pentapod_damper.study import machining, pipeline, stages
    cfg = load_study_config()
    res = StudyResults(cfg, np.linspace(*cfg.freq_grid[:2], int(cfg.freq_grid[2])), out_dir)
    for pos in cfg.positions:
        res.models[pos] = model = pipeline.prepare_model(pos, out_dir, lambda msg: None)
        for scn in cfg.scenarios:
            res.analytic[(pos, scn)] = pipeline.scenario_analytic(model, scn, cfg, res.freq)
            res.lobes[(pos, scn)] = machining.scenario_lobes(cfg, model, res.analytic[(pos, scn)])
    step = cfg.step_position
    res.pma = {scn: stages.pma_requirements(cfg, res.freq, res.models[step],
                                            res.analytic[(step, scn)])
               for scn in cfg.scenarios if res.analytic[(step, scn)].pma is not None}
    return res


@pytest.fixture(scope='module')
def study_analytic(tmp_path_factory) -> StudyResults:
    return _analytic_results(tmp_path_factory.mktemp('study'))


def _key(row: dict) -> tuple:
    return tuple(row[k] for k in ('position', 'scenario') if k in row)


@pytest.mark.slow
def test_committed_study_tables_are_what_the_current_code_computes(study_analytic):
    """Analytic columns of docs/results/*.csv = the current code's, to 1e-6 relative."""
    res = study_analytic
    for name, rows in (('summary', [as_row(r) for r in summary_rows(res)]),
                       ('struts12_share', [as_row(r) for r in struts12_share(res)]),
                       ('pma', pma_rows(res)), ('pma_highpass', pma_highpass_rows(res))):
        committed = {_key(r): r for r in study_readme.read_csv(RESULTS / f'{name}.csv')}
        assert sorted(committed) == sorted(_key(r) for r in rows), (name, STALE)
        for row in rows:
            for column, value in row.items():
                if (isinstance(value, float) and np.isfinite(value)
                        and column in committed[_key(row)]):
                    assert float(committed[_key(row)][column]) == pytest.approx(
                        value, rel=1e-6), (name, _key(row), column, STALE)


# --- the README ---------------------------------------------------------------------------------

def _dataflow():
    spec = importlib.util.spec_from_file_location('dataflow', ROOT / 'docs' / 'dataflow.py')
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_readme_is_a_newcomers_page():
    """Short; the two commands as they are; its figure; a link to every page of docs/."""
    text = README.read_text()
    assert len(text.splitlines()) < 150
    commands = text.split('## Two commands')[1].split('```bash\n')[1].split('```')[0]
    assert [line.split('#')[0].strip() for line in commands.splitlines()] == [
        'bash tools/study.sh', 'bash tools/test.sh']
    assert '](docs/figures/dataflow.png)' in text
    linked = set(re.findall(r'\]\(docs/(\w+\.md)', text))
    assert linked == {p.name for p in (ROOT / 'docs').glob('*.md')}
    assert '<!-- bench-table:begin -->' not in text and '<!-- study-tables:begin -->' not in text


def test_the_dataflow_figure_is_drawn_from_the_current_code():
    """The spec stored in the committed PNG is what docs/dataflow.py makes now."""
    dataflow = _dataflow()
    assert dataflow.stored_spec() == dataflow.spec(), 'run python docs/dataflow.py'


def test_the_dataflow_figure_names_what_exists():
    spec = _dataflow().spec()
    topics = set(interface.TOPIC_TYPES) | {interface.force_topic('<source>')}
    for arrow in spec['arrows']:
        assert set(arrow['topics']) <= topics, arrow
        for topic in arrow['topics']:
            assert topic in arrow['label'], arrow
    for box in spec['boxes']:
        where = box['where']
        if where.startswith('run:'):
            assert where[4:] in EXECUTABLES, box
        else:
            assert (ROOT / where).is_dir() == where.endswith('/') and (ROOT / where).exists(), box
    keys = {box['key'] for box in spec['boxes']} | {'sources'}
    assert all(a['from'] in keys and a['to'] in keys for a in spec['arrows'])
    assert set(spec['sources']) < keys


def _example_lines() -> list[list[str]]:
    """Command lines (split as the shell would, variables kept) of the README's example."""
    import shlex
    block = README.read_text().split('## A run and its analysis')[1].split('```bash\n')[1]
    block = block.split('```')[0].replace('\\\n', ' ')
    return [shlex.split(line, comments=True) for line in block.splitlines()]


def test_the_readme_example_is_taken_as_written():
    """Every option of the example reaches the option it names (no abbreviation taken)."""
    from pentapod_sim.cli.analyze import build_parser
    from pentapod_sim.scenario import runner
    lines = [words for words in _example_lines() if words]
    assert [w[0] for w in lines].count('scenario') == 2
    for words in lines:
        if words[0] == 'scenario':
            assert runner.main([*words[1:], '--list']) == 0, words
        elif words[0] == 'analyze':
            args = build_parser().parse_args(words[1:])
            given: dict = {}
            for word, value in zip(words, words[1:]):
                if word.startswith('--'):
                    given.setdefault(word[2:].replace('-', '_'), []).append(value)
            for name, values in given.items():
                got = getattr(args, name)
                if isinstance(got, list):             # --output may be repeated
                    assert got == values, (name, got)
                else:
                    assert [got] == [type(got)(v) for v in values], (name, got)
        else:
            assert words[0] == 'source' or re.fullmatch(r'[A-Z]+=\$\(.*', ' '.join(words))


# --- facts stated in the docs ------------------------------------------------------------------

def _qos_cell(topic: str) -> str:
    """How a topic table states the QoS of ``topic``, e.g. ``reliable, depth 40000``."""
    spec = interface.QOS[interface.qos_class(topic)]
    durability = '' if spec.durability == 'volatile' else f', {spec.durability.replace("_", " ")}'
    return f'{spec.reliability}{durability}, depth {spec.depth}'


def test_the_topic_table_lives_in_interface_md():
    assert [p.name for p in MARKDOWN if '\n| topic |' in p.read_text()] == ['interface.md']


@pytest.mark.parametrize('path', [ROOT / 'docs' / 'interface.md'], ids=lambda p: p.name)
def test_topic_tables_match_the_interface(path):
    rows = _table_rows(path.read_text(), 'topic')
    types = dict(interface.TOPIC_TYPES, **{interface.RUN_STATUS: interface.DIAGNOSTIC_STATUS,
                                          interface.force_topic('<source>'):
                                          interface.JOINT_STATE,
                                          interface.excitation_spec_topic('<source>'):
                                          interface.STRING,
                                          interface.controller_model_topic('<source>'):
                                          interface.STRING})
    assert sorted(r[0].strip('`') for r in rows) == sorted(types)
    header = next(line for line in path.read_text().splitlines()
                  if line.startswith('| topic |'))
    for row in rows:
        topic = row[0].strip('`')
        assert row[1] == types[topic].replace('/msg/', '/'), row
        if 'QoS' in header:
            assert row[-1] == _qos_cell(topic), row


def _backticked(text: str) -> list[str]:
    return re.findall(r'`([^`\n]+)`', text)


def _resolves(dotted: str) -> bool:
    """True if ``a.b.c`` is a module or an attribute of the longest importable module prefix."""
    parts = dotted.split('.')
    for n in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module('.'.join(parts[:n]))
        except ImportError:
            continue
        for attr in parts[n:]:
            if not hasattr(obj, attr):
                return False
            obj = getattr(obj, attr)
        return True
    return False


@pytest.mark.parametrize('path', MARKDOWN, ids=lambda p: p.name)
def test_named_modules_paths_and_executables_exist(path):
    text = path.read_text()
    missing = []
    for name in sorted(set(re.findall(r'\bpentapod_(?:sim|damper)(?:\.\w+)+', text))):
        if not _resolves(name):
            missing.append(name)
    links = re.findall(r'\]\(([^)#\s]+)', text)
    for token in set(_backticked(text) + links):
        for word in token.split():
            word = word.rstrip('.,;:)')
            if (re.match(r'(pentapod_sim|pentapod_damper|test|bench|config|tools|docs|launch)/',
                         word) and not re.search(r'[<>{}*|]', word)
                    and not (ROOT / word).exists() and not (path.parent / word).exists()):
                missing.append(word)
        if token.startswith('python -m '):
            module = token.split()[2]
            if '<' not in module and importlib.util.find_spec(module) is None:
                missing.append(module)
        for exe in re.findall(r'ros2 run pentapod_testbed ([\w|\\]+)', token):
            missing += [e for e in exe.replace('\\', '').split('|') if e not in EXECUTABLES]
    assert missing == []


def _anchors(path: Path) -> set[str]:
    """The anchors GitHub gives the headings of a Markdown file (lower case, punctuation out)."""
    found: set[str] = set()
    text = re.sub(r'```.*?```', '', path.read_text(), flags=re.S)
    for heading in re.findall(r'^#+ (.+)$', text, flags=re.M):
        slug = re.sub(r'[^\w\- ]', '', heading.lower()).replace(' ', '-')
        anchor, n = slug, 0
        while anchor in found:
            n += 1
            anchor = f'{slug}-{n}'
        found.add(anchor)
    return found


@pytest.mark.parametrize('path', MARKDOWN, ids=lambda p: p.name)
def test_links_to_sections_find_their_heading(path):
    wrong = []
    for target, anchor in re.findall(r'\]\(([^)#\s]*)#([^)\s]+)\)', path.read_text()):
        file = (path.parent / target) if target else path
        if not file.is_file() or anchor not in _anchors(file):
            wrong.append(f'{target}#{anchor}')
    assert wrong == []


def _public_functions() -> dict:
    """Name -> function of every ROS-free module of both packages (names defined twice: None)."""
    found: dict = {}
    for package in ('pentapod_sim', 'pentapod_damper'):
        for file in sorted((ROOT / package).rglob('*.py')):
            module = '.'.join(file.relative_to(ROOT).with_suffix('').parts)
            if '.nodes' in module or module.endswith('__main__'):
                continue
            for name, obj in vars(importlib.import_module(module)).items():
                if inspect.isfunction(obj) and obj.__module__ == module and name[0] != '_':
                    found[name] = obj if found.get(name, obj) is obj else None
    return found


def test_signatures_in_the_docs_match_the_code():
    """``solve_modes(K, M, modes_per_window=30)`` in a doc: the keyword exists, default equal."""
    functions, checked, wrong = _public_functions(), 0, []
    for path in MARKDOWN:
        for token in _backticked(path.read_text()):
            call = re.fullmatch(r'(\w+)\((.*)\)', token)
            if not call or not functions.get(call.group(1)):
                continue
            try:
                keywords = ast.parse(token, mode='eval').body.keywords
            except SyntaxError:
                continue
            params = inspect.signature(functions[call.group(1)]).parameters
            for kw in keywords:
                try:
                    stated = ast.literal_eval(kw.value)
                except ValueError:
                    continue
                if '...' in ast.unparse(kw.value):     # topics=[...]: no value stated
                    stated = Ellipsis
                checked += 1
                if kw.arg not in params:
                    wrong.append(f'{path.name}: {token}: no parameter {kw.arg}')
                elif stated is not Ellipsis and params[kw.arg].default != stated:
                    wrong.append(f'{path.name}: {token}: {kw.arg} defaults to '
                                 f'{params[kw.arg].default!r}')
    assert wrong == []
    assert checked >= 4


def _defaults_stated():
    from pentapod_sim.modes import slicing, window_pool
    from pentapod_sim.modes.causes import DEFAULT_ALPHA
    from pentapod_sim.scenario.runner import stop
    grace = inspect.signature(stop).parameters['grace'].default
    return [('modes.md', r'alpha = (\S+) \(default\)', DEFAULT_ALPHA),
            ('nodes.md', r'SIGKILL after (\S+) s\)', grace),
            ('statespace.md', r'SIGKILL (\S+) s after its SIGINT', grace),
            ('modes.md', r'(?:From|core from|of at least) ([0-9,]+) DOF',
             window_pool.PARALLEL_MIN_DOF),
            ('modes.md', r'at most (\d+), for problems', window_pool.MAX_DEFAULT_WORKERS),
            ('modes.md', r'`AHEAD_SPACING = ([0-9.]+)`', slicing.AHEAD_SPACING)]


@pytest.mark.parametrize('doc,pattern,value', _defaults_stated(), ids=lambda v: str(v)[:20])
def test_defaults_stated_in_prose_match_the_code(doc, pattern, value):
    stated = re.findall(pattern, (ROOT / 'docs' / doc).read_text())
    assert stated, pattern
    assert all(float(s.replace(',', '')) == value for s in stated), (stated, value)


def _load_test_module(name: str):
    spec = importlib.util.spec_from_file_location(name, ROOT / 'test' / f'{name}.py')
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_architecture_names_every_stage_in_pipeline_order():
    """docs/architecture.md lists the stages of test/test_layout.py in the same order."""
    text = (ROOT / 'docs' / 'architecture.md').read_text()
    text = text.split('## Modules, in pipeline order')[1].split('\n## ')[0]
    spans = []
    for prefixes in _load_test_module('test_layout').STAGES:
        found = []
        for prefix in (p for p in prefixes if not p.endswith('__init__')):
            path = prefix.replace('.', '/')
            at = max(text.find(f'`{path}/`'), text.find(f'`{path}.py`'))
            assert at >= 0, f'{prefix} is not named in docs/architecture.md'
            found.append(at)
        spans.append((min(found), max(found)))
    assert all(a[1] < b[0] for a, b in zip(spans, spans[1:])), spans


def test_scenario_table_matches_the_scenario_files():
    from pentapod_damper.scenario_laws import continuous_dampers, scenario_laws
    from pentapod_sim.scenario.files import read_scenario, scenario_names
    text = (ROOT / 'docs' / 'nodes.md').read_text()
    rows = _table_rows(text, 'scenario')
    assert sorted(r[0].strip('`') for r in rows) == scenario_names()
    common = re.search(r'`sample_rate: ([\d.]+)`\) reaches every node\. All use the machine at '
                       r'(\w+), ([\d.]+) s, a random TCP force in x \(([\d.]+) N RMS, '
                       r'([\d.]+)-([\d.]+) Hz, seed (\d+)\)', text.replace('\n', ' '))
    rate, position, duration, rms, f_start, f_end, seed = common.groups()
    tuned = re.search(r'the tuned strut laws \(\+\) use the machine at (\w+)',
                      text.replace('\n', ' ')).group(1)
    for row in rows:
        sections = read_scenario(row[0].strip('`')).sections
        plant, exciter = sections['plant'], sections['exciter']
        at = tuned if row[1].rstrip().endswith('(+)') else position
        assert (plant['sample_rate'], plant['position'], plant['duration']) == (
            float(rate), at, float(duration)), row[0]
        assert (exciter['kind'], exciter['direction'], exciter['amplitude'], exciter['f_start'],
                exciter['f_end'], exciter['seed']) == (
            'random', [1.0, 0.0, 0.0], float(rms), float(f_start), float(f_end), int(seed))
        if at == tuned and row[1].rstrip().endswith('(+)'):
            continue            # active laws, no viscous gains: test_damper_docs checks them
        gains = continuous_dampers(scenario_laws(sections, 1.0 / plant['sample_rate']))
        stated = {float(g) for g in re.findall(r'([\d.]+) (?:N m s/rad|N s/m)', row[1])}
        assert stated == set(gains.values()), row
        for mass in re.findall(r'm_a = ([\d.]+) kg', row[1]):
            assert sections['pma']['proof_mass'] == float(mass), row


@pytest.fixture(scope='module')
def plants() -> dict:
    from pentapod_sim.plant.build import build_plant
    return {pos: build_plant(pos) for pos in ('P1', 'P2')}


def test_bending_gain_table_is_what_the_code_computes(plants):
    """Spectral radius of the sampled loop and continuous peak reduction, docs/nodes.md."""
    from pentapod_damper.laws import strut_bending_damper
    from pentapod_sim.sim.closed_loop import closed_loop_system
    from pentapod_sim.sim.stepping import DiscretePlant
    rows = _table_rows((ROOT / 'docs' / 'nodes.md').read_text(), 'bending gain [N m s/rad]')
    assert len(rows) >= 3
    cfg = load_study_config()
    freq = np.linspace(*cfg.freq_grid[:2], int(cfg.freq_grid[2]))
    freq = freq[(freq >= 2.0) & (freq <= 400.0)]
    for row in rows:
        gain = float(row[0])
        for col, rate in ((1, 3000.0), (2, 5000.0)):
            for cell, pos in zip(row[col].split(' / '), ('P1', 'P2')):
                plant = DiscretePlant(plants[pos].discretize(1.0 / rate))
                loop = closed_loop_system(plant, [strut_bending_damper(range(1, 6), gain)])
                radius = np.abs(np.linalg.eigvals(loop.a)).max()
                if cell == 'stable':
                    assert radius < 1.0, (row, pos, rate, radius)
                else:
                    assert radius == pytest.approx(float(cell), rel=6e-3), (row, pos, rate)
        dampers = {f'strut{i}_bending_moment_{k}': gain for i in range(1, 6) for k in (2, 3)}
        for cell, pos in zip(row[3].split(' / '), ('P1', 'P2')):
            peak = [_peak_tcp_xx(plants[pos], d, freq) for d in ({}, dampers)]
            assert peak[0] / peak[1] == pytest.approx(float(cell), rel=6e-3), (row, pos)


def test_kept_mode_counts_in_statespace_md_are_the_plants(plants):
    text = (ROOT / 'docs' / 'statespace.md').read_text().replace('\n', ' ')
    stated = re.search(r'keeps (\d+) of (\d+) \(P1\) and (\d+) of (\d+) \(P2\) modes', text)
    counts = [plants[pos].n_modes if k == 0 else plants[pos].meta['n_modes_computed']
              for pos in ('P1', 'P2') for k in (0, 1)]
    assert [int(g) for g in stated.groups()] == counts


def _peak_tcp_xx(plant, dampers: dict, freq: np.ndarray) -> float:
    """Largest |H| of TCP x / TCP x force with viscous dampers, by eigen-decomposition."""
    from pentapod_sim.plant.frf import damper_feedback
    sys = damper_feedback(plant, dampers) if dampers else plant.to_statespace()
    o = list(plant.output_names).index('tcp_displacement_x')
    i = list(plant.input_names).index('tcp_force_x')
    lam, vec = np.linalg.eig(sys.A)
    left, right = sys.C[o] @ vec, np.linalg.solve(vec, sys.B[:, i])
    s = 2j * np.pi * freq[:, None]
    return float(np.abs((left * right / (s - lam)).sum(axis=1) + sys.D[o, i]).max())


def _python_blocks(text: str) -> list[tuple[str, str]]:
    """(text before, code) of every ```python block."""
    parts = re.split(r'```python\n(.*?)```', text, flags=re.S)
    return list(zip(parts[0::2], parts[1::2]))


@pytest.mark.parametrize('path', MARKDOWN, ids=lambda p: p.name)
def test_python_examples_import_what_exists(path):
    """Every name a Python example imports from the two packages exists."""
    missing = []
    for _, code in _python_blocks(path.read_text()):
        for node in ast.walk(ast.parse(code)):
            if isinstance(node, ast.ImportFrom) and node.module.startswith('pentapod_'):
                missing += [f'{node.module}.{a.name}' for a in node.names
                            if not _resolves(f'{node.module}.{a.name}')]
            elif isinstance(node, ast.Import):
                missing += [a.name for a in node.names
                            if a.name.startswith('pentapod_') and not _resolves(a.name)]
    assert missing == []


@pytest.mark.parametrize('doc', ['recording.md', 'nodes.md', 'statespace.md'])
def test_examples_marked_as_run_do_run(doc, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    blocks = [code for before, code in _python_blocks((ROOT / 'docs' / doc).read_text())
              if 'test/test_docs.py runs this example' in before.rstrip().split('\n\n')[-1]]
    assert blocks
    for code in blocks:
        exec(compile(code, doc, 'exec'), {})


def test_the_exit_code_table_is_the_code_one():
    """docs/interface.md lists every end of pentapod_sim.exits.TABLE, in its words and order."""
    from pentapod_sim import exits
    text = (ROOT / 'docs' / 'interface.md').read_text()
    section = text.split('## Stopping and exit codes', 1)[1].split('\n## ', 1)[0]
    rows = [line.split(' | ', 1) for line in section.splitlines()
            if line.startswith('| ') and not line.startswith('| code')]
    documented = [(code.strip('| '), meaning.rstrip(' |')) for code, meaning in rows]
    assert documented == [('128 + N' if code == exits.SIGNAL_BASE else str(code), meaning)
                          for code, meaning in exits.TABLE]
    assert exits.of_returncode(-9) == 137 and exits.of_returncode(3) == exits.RECORDING_FAILED
