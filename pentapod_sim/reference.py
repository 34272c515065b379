"""
The reference pages generated from the schemas: node parameters and configuration files.

``python -m pentapod_sim.reference parameters > docs/parameters.md`` writes one table per node
kind of :data:`pentapod_sim.registry.NODES` from its parameter class;
``python -m pentapod_sim.reference config > docs/config.md`` one table per file of
:data:`pentapod_sim.registry.CONFIG_FILES` from its schema; ``python -m pentapod_sim.reference
NODE`` prints one node's parameters as ``--help`` does. test/test_parameters.py checks that the
committed pages are what this module makes. :func:`replace_section` puts a generated block
between its markers in a page written by hand.
"""
from __future__ import annotations

import argparse
import dataclasses
import types
import typing
from typing import Any

from pentapod_sim import registry
from pentapod_sim.parameters import help_text, load_class, NodeParams, params_of, show, summary
from pentapod_sim.schema import range_text

PARAMETERS_HEADER = """# Node parameters

Generated from the nodes' parameter classes (`pentapod_sim/registry.py` names the class of
each) by `python -m pentapod_sim.reference parameters > docs/parameters.md`;
test/test_parameters.py checks that this file is up to date. Do not edit it by hand.

Units are SI. Every node refuses a parameter name it does not know, naming the closest known
one, and so does the scenario runner for a scenario file. A `/**` section may hold parameters
that only some nodes declare: a node ignores a name that another node kind of the testbed
declares (the runner still checks each node's own section strictly). An integer is taken for a
`double`. Read-only parameters are read once at start; the others may be changed while the
node runs (`ros2 param set`). An empty list default is declared as `['']`, `[0]` or `[0.0]`
(ROS 2 cannot type an empty list); these entries mean nothing in any list, and a parameter
file should write them (or leave the parameter out) instead of `[]`.
`ros2 run pentapod_testbed <node> --help` prints a node's table.
"""

CONFIG_HEADER = """# Configuration files

Generated from the files' schemas (`pentapod_sim/registry.py` names the schema of each) by
`python -m pentapod_sim.reference config > docs/config.md`; test/test_parameters.py checks that
this file is up to date. Do not edit it by hand.

Every file is checked one way (`pentapod_sim/schema.py`): an unknown key is refused naming the
closest known one, a missing key or a value of the wrong type or out of range naming the file,
the key path and the value with its unit. Units are SI; a key in `rad` may also be given in
degrees as `<key>_deg`. `<name>` in a key path stands for a name of your choice, `[i]` for
each item of a list.
"""


def _escape(text: str) -> str:
    return text.replace('<', '&lt;').replace('>', '&gt;').replace('|', '\\|')


def _row(cells: list[str]) -> str:
    return '| ' + ' | '.join(cells) + ' |'


def node_table(cls: type[NodeParams]) -> str:
    """The parameters of a node class as a Markdown table."""
    rows = ['| name | type | default | unit | range | read-only | description |',
            '|---|---|---|---|---|---|---|']
    for p in cls.ros_params():
        rows.append(_row([f'`{p.name}`', p.type, f'`{show(p.default)}`', _escape(p.unit),
                          _escape(p.range), 'yes' if p.read_only else 'no',
                          _escape(p.description)]))
    return '\n'.join(rows)


def parameters_markdown() -> str:
    """docs/parameters.md: one table per node kind."""
    parts = [PARAMETERS_HEADER]
    for kind in registry.NODES:
        cls = params_of(kind.name)
        parts += [f'## {kind.name}', '', f'`{kind.node}`: {summary(cls, whole=True)}', '',
                  node_table(cls), '']
    return '\n'.join(parts)


def _type_text(hint: Any) -> str:
    """A field's type in words."""
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if origin in (typing.Union, types.UnionType):
        words = [_type_text(a) for a in args if a is not type(None)]
        return ' or '.join(words) + (' or null' if type(None) in args else '')
    if origin is tuple:
        return f'list of {_type_text(args[0]) if args else "number"}'
    if origin is dict:
        return f'mapping of {_type_text(args[1])}'
    if dataclasses.is_dataclass(hint):
        return 'section'
    return {bool: 'true/false', int: 'integer', float: 'number', str: 'text'}.get(
        hint, getattr(hint, '__name__', str(hint)))


def _nested(hint: Any) -> tuple[str, type] | None:
    """(key suffix, schema) of a field holding sections: itself, a list or a mapping of them."""
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    for suffix, inner in (('', hint), ('[i]', args[0] if origin is tuple and args else None),
                          ('.<name>', args[1] if origin is dict else None)):
        if isinstance(inner, type) and dataclasses.is_dataclass(inner):
            return suffix, inner
    options = [a for a in args if a is not type(None)] if origin in (
        typing.Union, types.UnionType) else []
    return _nested(options[0]) if len(options) == 1 else None


def _default(field: dataclasses.Field[Any]) -> str:
    if field.default is not dataclasses.MISSING:
        value = field.default
    elif field.default_factory is not dataclasses.MISSING:
        value = field.default_factory()
    else:
        return 'required'
    return f'`{show(value if value is not None else "null")}`'.replace("`'null'`", '`null`')


def config_rows(cls: type, prefix: str = '') -> list[str]:
    """Table rows of every key of a schema, sections expanded (key paths)."""
    rows = []
    hints = typing.get_type_hints(cls)
    for field in dataclasses.fields(cls):
        meta = field.metadata
        if meta.get('internal'):
            continue
        key = f'{prefix}{field.name}'
        unit = meta.get('unit', '-')
        nested = _nested(hints[field.name])
        description = meta.get('description', '') or (summary(nested[1]) if nested else '')
        if unit == 'rad':
            description = f'{description} (or `{field.name}_deg` in degrees)'.lstrip()
        rows.append(_row([f'`{key}`', _type_text(hints[field.name]),
                          '' if unit == '-' else _escape(unit), _escape(range_text(meta)),
                          _default(field), _escape(description)]))
        if nested is not None:
            rows += config_rows(nested[1], f'{key}{nested[0]}.')
    return rows


def config_markdown() -> str:
    """docs/config.md: one table per configuration file."""
    parts = [CONFIG_HEADER]
    for name, target in registry.CONFIG_FILES.items():
        cls = load_class(target)
        parts += [f'## {name}', '', f'`{target}`: {summary(cls)}', '',
                  '| key | type | unit | range | default | description |',
                  '|---|---|---|---|---|---|', *config_rows(cls), '']
    return '\n'.join(parts)


def replace_section(text: str, name: str, body: str) -> str:
    """
    Replace what stands between ``<!-- name:begin -->`` and ``<!-- name:end -->`` by ``body``.

    Raises ValueError naming the marker if either is missing or appears more than once.
    """
    begin, end = f'<!-- {name}:begin -->', f'<!-- {name}:end -->'
    for marker in (begin, end):
        if text.count(marker) != 1:
            raise ValueError(f'{marker} must appear exactly once (found {text.count(marker)})')
    head, rest = text.split(begin)
    _, tail = rest.split(end)
    return f'{head}{begin}\n{body.strip()}\n{end}{tail}'


def section_of(text: str, name: str) -> str:
    """What stands between ``<!-- name:begin -->`` and ``<!-- name:end -->`` (stripped)."""
    return text.split(f'<!-- {name}:begin -->')[1].split(f'<!-- {name}:end -->')[0].strip()


def main(argv: list[str] | None = None) -> int:
    """``python -m pentapod_sim.reference parameters | config | NODE``."""
    kinds = [k.name for k in registry.NODES]
    # whole option names only, as CommandParser (pentapod_sim.cli, a later stage) does
    parser = argparse.ArgumentParser(description='Print the generated reference pages.',
                                     allow_abbrev=False)
    parser.add_argument('page', choices=['parameters', 'config', *kinds],
                        help='docs/parameters.md, docs/config.md or one node (text)')
    args = parser.parse_args(argv)
    if args.page == 'parameters':
        print(parameters_markdown(), end='')
    elif args.page == 'config':
        print(config_markdown(), end='')
    else:
        print(help_text(params_of(args.page)))
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
