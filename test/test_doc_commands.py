r"""
Every command line in the README and docs/ parses as written (issue 25 item 7).

The command lines are taken from the pages themselves: whole lines of fenced code blocks (with
their ``\\`` continuations joined and trailing comments cut) and inline code spans, for the
project's commands (registry.COMMANDS), ``python -m pentapod_...``, ``python bench/...``,
``ros2 run pentapod_testbed NODE`` and ``ros2 launch pentapod_testbed FILE``. A code block's
line is handed to the command's own argument parser, stopped right after a successful parse
(nothing runs), so a renamed option, an option given to the wrong sub-command or a missing
sub-command fails here with the page and line. Synopsis lines (``[--opt X]``, ``A | B``,
``...``) and commands named inline in a sentence are checked by option name: every
``--option`` they show must exist on the command or one of its sub-commands.
"""
from __future__ import annotations

import argparse
import ast
import functools
import importlib
import inspect
from pathlib import Path
import re
import shlex
import signal
import sys
from typing import Any, Callable

import pytest

from pentapod_sim.registry import COMMANDS, NODES

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / 'README.md', *sorted((ROOT / 'docs').glob('*.md'))]
HEADS = (*COMMANDS, 'python -m pentapod_', 'python bench/', 'ros2 run pentapod_testbed',
         'ros2 launch pentapod_testbed')
ENV_PREFIX = re.compile(r'^((PYTHONPATH|OPENBLAS_NUM_THREADS|ROS_DOMAIN_ID)=\S+\s+'
                        r'|nice -n \d+\s+)+')
SYNOPSIS = re.compile(r'\[|\]|\||\.\.\.|<|>')


def doc_commands() -> list[tuple[str, str, bool]]:
    """
    (page:line, command, whole) of every command line in the pages.

    whole: a code block's line, parsed as written; an inline span names a command and its
    options in a sentence.
    """
    found = []
    for page in PAGES:
        lines = page.read_text().splitlines()
        in_block, pending, start = False, '', 0
        for number, line in enumerate(lines, 1):
            if line.strip().startswith('```'):
                in_block, pending = not in_block, ''
                continue
            if in_block:
                text = (pending + ' ' + line.strip()) if pending else line.strip()
                start = start if pending else number
                if text.endswith('\\'):
                    pending = text[:-1].strip()
                    continue
                pending = ''
                spans = [(start, re.sub(r'\s+#\s.*$', '', text), True)]
            else:
                spans = [(number, m.group(1), False) for m in re.finditer(r'`([^`]+)`', line)]
            for at, span, whole in spans:
                command = ENV_PREFIX.sub('', span.strip())
                first = command.split(' ', 1)[0]
                if ' ' in command and (first in COMMANDS
                                       or command.startswith(HEADS[len(COMMANDS):])):
                    found.append((f'{page.relative_to(ROOT)}:{at}', command, whole))
    return found


class Parsed(Exception):
    """Raised by the patched parser once the outermost parse succeeded."""


class Leftover(Exception):
    """Raised by the patched parser for arguments no parser took."""


def _stop_after_parse(monkeypatch) -> None:
    """
    Make the outermost parse raise Parsed once it succeeded.

    Arguments left over by the outermost parse_known_args (which a parser's own parse_args
    would refuse later) raise Leftover: the documented commands carry no ROS arguments here.
    """
    known = argparse.ArgumentParser.parse_known_args
    depth = [0]

    def parse_known_args(self, args=None, namespace=None):
        depth[0] += 1
        try:
            parsed, extra = known(self, args, namespace)
        finally:
            depth[0] -= 1
        if depth[0] == 0:
            raise Leftover(extra) if extra else Parsed(parsed)
        return parsed, extra

    monkeypatch.setattr(argparse.ArgumentParser, 'parse_known_args', parse_known_args)


def _entry(spec: str) -> Callable[..., Any]:
    module, _, func = spec.partition(':')
    return getattr(importlib.import_module(module), func)


def command_main(words: list[str]) -> tuple[Callable[..., Any] | None, list[str]]:
    """The main function a documented command line calls, and its arguments."""
    if words[0] in COMMANDS:
        return _entry(COMMANDS[words[0]]), words[1:]
    if words[:2] == ['python', '-m']:
        name = words[2]
        spec = importlib.util.find_spec(name)
        assert spec is not None, f'no module {name}'
        if spec.submodule_search_locations:
            name += '.__main__'
        return getattr(importlib.import_module(name), 'main'), words[3:]
    return None, words


def long_options(parser: argparse.ArgumentParser) -> set[str]:
    """Every long option of a parser and of its sub-commands."""
    names = set()
    for action in parser._actions:  # argparse has no public walk over its actions
        names.update(o for o in action.option_strings if o.startswith('--'))
        if isinstance(action, argparse._SubParsersAction):
            for sub in action.choices.values():
                names |= long_options(sub)
    return names


def captured_parser(main, monkeypatch) -> argparse.ArgumentParser:
    """The parser ``main`` builds, captured as it parses ``--help``-free empty arguments."""
    seen: list[argparse.ArgumentParser] = []
    original = argparse.ArgumentParser.parse_known_args

    def parse_known_args(self, args=None, namespace=None):
        seen.append(self)
        raise Parsed(None)

    monkeypatch.setattr(argparse.ArgumentParser, 'parse_known_args', parse_known_args)
    try:
        main([])
    except (Parsed, SystemExit):
        pass
    finally:
        monkeypatch.setattr(argparse.ArgumentParser, 'parse_known_args', original)
    assert seen, 'the command parsed nothing'
    return seen[0]


COMMANDS_IN_DOCS = doc_commands()


def test_the_pages_hold_commands_of_every_kind():
    heads = {c.split()[0] for _, c, whole in COMMANDS_IN_DOCS if whole}
    assert {'statespace', 'analyze', 'judge', 'python', 'ros2', 'scenario'} <= heads
    assert len(COMMANDS_IN_DOCS) > 100


@pytest.mark.parametrize('where,command,whole', COMMANDS_IN_DOCS,
                         ids=[w for w, _, _ in COMMANDS_IN_DOCS])
def test_a_documented_command_parses_as_written(where, command, whole, monkeypatch, capsys):
    words = shlex.split(command, comments=True)
    if words[:3] == ['ros2', 'run', 'pentapod_testbed']:
        names = {kind.name for kind in NODES} | set(COMMANDS)
        for name in words[3].replace('\\|', '|').split('|'):
            assert name in names | {'<node>', 'NODE'}, f'{where}: no executable {name}'
        return
    if words[:3] == ['ros2', 'launch', 'pentapod_testbed']:
        launch = ROOT / 'launch' / words[3]
        assert launch.is_file(), f'{where}: no launch file {words[3]}'
        declared = {node.args[0].value for node in ast.walk(ast.parse(launch.read_text()))
                    if isinstance(node, ast.Call) and getattr(node.func, 'id', '')
                    == 'DeclareLaunchArgument'}
        for arg in words[4:]:
            assert arg.partition(':=')[0] in declared, f'{where}: {arg} is not a launch argument'
        return
    node_modules = {kind.entry_point.partition(':')[0] for kind in NODES}
    if '--ros-args' in words or words[:2] == ['python', '-m'] and words[2] in node_modules:
        # a node: its arguments are ROS arguments (rclpy parses them); the node must exist
        assert words[0] != 'python' or importlib.util.find_spec(words[2]), where
        return
    shown = set(re.findall(r'(?<![\w-])--[a-z][\w-]*', command))
    if words[0] == 'python' and words[1].startswith('bench/'):
        # benchmarks read their few options from sys.argv or argparse: each shown must be there
        source = (ROOT / words[1]).read_text()
        missing = {o for o in shown if f"'{o}'" not in source}
        assert not missing, f'{where}: {words[1]} has no option {sorted(missing)}'
        return
    main, argv = command_main(words)
    assert main is not None, f'{where}: {words[:2]} has no main'
    if not inspect.signature(main).parameters:  # a main() that reads sys.argv itself
        monkeypatch.setattr(sys, 'argv', [words[0], *argv])
        main = functools.partial(_without_argv, main)
    if not whole or SYNOPSIS.search(command):
        if shown:
            options = long_options(captured_parser(main, monkeypatch))
            assert shown <= options, f'{where}: {sorted(shown - options)} not options'
        return
    _stop_after_parse(monkeypatch)
    signal.signal(signal.SIGALRM, _too_long)
    signal.alarm(60)
    try:
        main(argv)
    except Parsed:
        return
    except Leftover as extra:
        pytest.fail(f'{where}: `{command}`: no parser takes {extra.args[0]}')
    except TimeoutError:
        pytest.fail(f'{where}: `{command}` ran for 60 s instead of stopping after its parse')
    except SystemExit as stop:
        if stop.code in (0, None) and '--help' in argv:
            return
        pytest.fail(f'{where}: `{command}` does not parse: {capsys.readouterr().err.strip()}')
    finally:
        signal.alarm(0)
    if '--help' in argv:  # a node's own --help prints its parameter table and returns
        return
    pytest.fail(f'{where}: `{command}` returned without parsing its arguments')


def _without_argv(main, argv):
    return main()


def _too_long(signum, frame):
    raise TimeoutError
