"""
Command lines take whole option names only (issue 25 item 7).

argparse accepts a unique prefix of a long option: ``analyze frf BAG ... --out DIR`` (``--out``
is an option of ``analyze`` itself, given before the sub-command) was taken as ``--output`` of
``frf`` and failed later with a misleading "topic not in bag". Every parser of the project's
commands refuses abbreviations (``pentapod_sim.cli.CommandParser``), in sub-commands too.
"""
import ast
from pathlib import Path

import pytest

from pentapod_sim.cli import analyze, CommandParser

ROOT = Path(__file__).resolve().parents[1]


def test_a_top_level_option_after_the_sub_command_is_refused_with_where_it_belongs(capsys):
    with pytest.raises(SystemExit) as stop:
        analyze.main(['frf', 'BAG', '--input', '/pentapod/excitation.force.x',
                      '--output', '/pentapod/tcp_state.position.tcp_x', '--out', 'DIR'])
    assert stop.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert err == ('analyze: error: --out is an option of analyze itself: give it before frf '
                   '(analyze --out ... frf ...)')


@pytest.mark.parametrize('argv', [['frf', 'BAG', '--inp', 'a.b', '--output', 'c.d'],
                                  ['--verb', 'info', 'BAG'],
                                  ['time', 'BAG', 'X.y', '--out', 'DIR'],
                                  ['recover', 'BAG', '--in-pl']])
def test_abbreviations_are_refused_in_commands_and_sub_commands(argv, capsys):
    with pytest.raises(SystemExit) as stop:
        analyze.build_parser().parse_args(argv)
    assert stop.value.code == 2
    assert 'analyze' in capsys.readouterr().err


# the values are of the wrong type, so that a command that did take the abbreviation stops at
# once (with another message) instead of running
@pytest.mark.parametrize('module,argv', [('pentapod_damper.study.__main__', ['--dur', 'x']),
                                         ('pentapod_damper.sweep.__main__', ['--work', 'x']),
                                         ('pentapod_sim.cli.modes', ['--n-mod', 'x']),
                                         ('pentapod_sim.scenario.runner', ['--ste', 'x', 'y']),
                                         ('pentapod_sim.reference', ['--mark', 'parameters'])])
def test_the_other_commands_refuse_abbreviations(module, argv, capsys):
    import importlib
    with pytest.raises(SystemExit) as stop:
        importlib.import_module(module).main(argv)
    assert stop.value.code == 2
    assert 'unrecognized arguments: ' + argv[0] in capsys.readouterr().err


def test_whole_names_still_parse():
    args = analyze.build_parser().parse_args(['--out', 'DIR', 'frf', 'BAG', '--input', 'a.b',
                                              '--output', 'c.d'])
    assert (args.out, args.output, args.input) == ('DIR', ['c.d'], 'a.b')


def test_sub_command_parsers_inherit_the_rule():
    parser = CommandParser(prog='x')
    sub = parser.add_subparsers(dest='command').add_parser('y')
    assert isinstance(sub, CommandParser) and sub.allow_abbrev is False


def _parser_calls():
    """(file, line, call) of every ArgumentParser / CommandParser construction."""
    for folder in ('pentapod_sim', 'pentapod_damper', 'bench'):
        for path in sorted((ROOT / folder).rglob('*.py')):
            for node in ast.walk(ast.parse(path.read_text(encoding='utf-8'))):
                if isinstance(node, ast.Call):
                    name = getattr(node.func, 'attr', getattr(node.func, 'id', ''))
                    if name in ('ArgumentParser', 'CommandParser'):
                        yield str(path.relative_to(ROOT)), node.lineno, name, node


def test_every_parser_of_the_project_refuses_abbreviations():
    calls = list(_parser_calls())
    assert len(calls) >= 12
    loose = []
    for file, line, name, node in calls:
        strict = name == 'CommandParser' or any(
            k.arg == 'allow_abbrev' and isinstance(k.value, ast.Constant) and k.value.value is
            False for k in node.keywords)
        if not strict:
            loose.append(f'{file}:{line}')
    assert loose == []
