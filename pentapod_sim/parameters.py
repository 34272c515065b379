"""
Typed parameter tables of the nodes: one home for every node parameter (ROS-free).

Each node executable declares its parameters from one :class:`ParameterTable` (the idea of
generate_parameter_library): name, type, default, unit, range or choices, read-only flag and
description. The same table checks scenario files before any node starts
(:meth:`ParameterTable.check`), gives the offline code (study, scenario laws) the nodes'
defaults (:meth:`ParameterTable.values`), prints the ``--help`` of a node and renders
docs/parameters.md::

    python -m pentapod_sim.parameters --markdown > docs/parameters.md

The tables are found through :data:`pentapod_sim.executables.PARAMETER_TABLES` and loaded
with importlib (:func:`table_of`), so this package never imports pentapod_damper statically.
"""
from __future__ import annotations

import argparse
import array
from dataclasses import dataclass
import difflib
import importlib
import math
import re
from typing import Any, Iterator, Mapping, Sequence

from pentapod_sim.errors import ConfigError
from pentapod_sim.executables import module_of, NODE_KINDS, PARAMETER_TABLES

#: Parameter types (the ROS 2 parameter types' names as ``ros2 param describe`` shows them).
TYPES = ('bool', 'int', 'float', 'str', 'double[]', 'integer[]', 'string[]')
_SCALAR = {'bool': bool, 'int': int, 'float': float, 'str': str}
_ELEMENT = {'double[]': 'float', 'integer[]': 'int', 'string[]': 'str'}
#: Entries that mean "none" in a list parameter whose default is empty: rclpy types a
#: parameter by its default and takes ``[]`` for a byte array, so a node declares ``['']``,
#: ``[0]`` or ``[0.0]`` instead, and the node ignores these entries in any value.
_NONE_MARK = {'string[]': '', 'integer[]': 0, 'double[]': 0.0}
#: Parameters every rclpy node declares itself; a parameter file may set them for any node.
ROS_NODE_PARAMETERS = ('use_sim_time', 'start_type_description_service')


@dataclass(frozen=True)
class Param:
    """
    One node parameter.

    Attributes
    ----------
    name : str
        Parameter name. A ``<...>`` part is a placeholder: ``source_ports.<source>`` stands
        for ``source_ports.damper``, ``source_ports.pma`` and so on.
    type : str
        One of :data:`TYPES`.
    default : bool, int, float, str or list
        Default value (of ``type``).
    description : str
        Meaning, without the unit.
    unit : str
        SI unit of the value ('' if none).
    low, high : float, optional
        Allowed closed range of a number.
    read_only : bool
        True if the node reads the value once at start (it cannot be changed while running).
    choices : tuple of str, optional
        Allowed values of a string (or of each element of a string list).
    """

    name: str
    type: str
    default: Any
    description: str
    unit: str = ''
    low: float | None = None
    high: float | None = None
    read_only: bool = True
    choices: tuple[str, ...] | None = None

    def __post_init__(self):
        if self.type not in TYPES:
            raise ValueError(f'parameter {self.name!r}: type {self.type!r} is not one of '
                             f'{", ".join(TYPES)}')
        problem = self.problem(self.default)
        if problem:
            raise ValueError(f'parameter {self.name!r}: default {problem}')

    @property
    def is_array(self) -> bool:
        """True for list types."""
        return self.type.endswith('[]')

    @property
    def pattern(self) -> re.Pattern | None:
        """Regular expression of a placeholder name, None for a plain name."""
        if '<' not in self.name:
            return None
        parts = re.split(r'<[^>]*>', self.name)
        return re.compile('[^.]+'.join(re.escape(p) for p in parts) + '$')

    def matches(self, name: str) -> bool:
        """True if ``name`` is this parameter (or an instance of its placeholder)."""
        pattern = self.pattern
        return name == self.name if pattern is None else bool(pattern.match(name))

    def problem(self, value: Any) -> str | None:
        """What is wrong with ``value`` for this parameter (None if nothing)."""
        if self.is_array:
            if value is None:                   # an empty list in a ROS 2 parameter file
                return None
            if not isinstance(value, (list, tuple, array.array)):
                return f'{value!r} is not a list ({self.type})'
            for item in value:
                bad = _scalar_problem(_ELEMENT[self.type], item, self.choices)
                if bad:
                    return f'{list(value)!r}: element {bad}'
            return None
        bad = _scalar_problem(self.type, value, self.choices)
        if bad:
            return bad
        if self.type in ('int', 'float') and not (
                (self.low is None or value >= self.low)
                and (self.high is None or value <= self.high)):
            return f'{value!r} is outside the range {self.range_text()}'
        return None

    @property
    def none_mark(self) -> Any:
        """What a node declares for an empty default list (``''`` or ``0``); None if none."""
        return _NONE_MARK.get(self.type) if self.default == [] else None

    def clean(self, value: Any) -> Any:
        """The value as the node uses it: lists as lists without "none" marks."""
        if not self.is_array:
            return value
        items = list(value or [])
        mark = self.none_mark
        return items if mark is None else [v for v in items if v != mark]

    def range_text(self) -> str:
        """The range or choices as text ('' if unbounded)."""
        if self.choices:
            return 'one of ' + ', '.join(self.choices)
        if self.low is None and self.high is None:
            return ''
        low, high = ('-inf' if self.low is None else self.low,
                     'inf' if self.high is None else self.high)
        return '[' + ', '.join(v if isinstance(v, str) else str(v) if isinstance(v, int)
                               else f'{v:g}' for v in (low, high)) + ']'

    def full_description(self) -> str:
        """Description with the unit, as a ROS parameter descriptor states it."""
        return f'{self.description} [{self.unit}]' if self.unit else self.description


def _scalar_problem(kind: str, value: Any, choices) -> str | None:
    """What is wrong with one scalar of type ``kind`` (None if nothing)."""
    if kind == 'float' and isinstance(value, int) and not isinstance(value, bool):
        return (f'{value!r} is an integer; a float parameter needs a decimal point '
                f'({float(value)!r})')
    if kind == 'str' and isinstance(value, bool):
        return (f'{value!r} is not a string (YAML reads a bare y, n, yes, no as a boolean: '
                'quote it)')
    expected = _SCALAR[kind]
    if not isinstance(value, expected) or (kind == 'int' and isinstance(value, bool)):
        return f'{value!r} is not of type {kind}'
    if kind == 'float' and not math.isfinite(value):
        return f'{value!r} is not finite'
    if choices and value not in choices:
        return f'{value!r} is not one of {", ".join(choices)}'
    return None


def flatten(params: Mapping[str, Any], prefix: str = '') -> dict[str, Any]:
    """Parameters of a ``ros__parameters`` mapping by full name (nested names joined by '.')."""
    flat: dict[str, Any] = {}
    for key, value in params.items():
        if isinstance(value, dict):
            flat.update(flatten(value, f'{prefix}{key}.'))
        else:
            flat[f'{prefix}{key}'] = value
    return flat


def did_you_mean(name: str, known: Sequence[str]) -> str:
    """'; did you mean X?' for the nearest known name, or the list of known names."""
    close = difflib.get_close_matches(name, known, n=1, cutoff=0.6)
    if close:
        return f'; did you mean {close[0]!r}?'
    return f' (known: {", ".join(sorted(known))})'


class Values:
    """Parameter values of a node by attribute (``values.sample_rate``), typed by its table."""

    def __init__(self, table: ParameterTable, values: Mapping[str, Any]):
        object.__setattr__(self, '_table', table)
        object.__setattr__(self, '_values', dict(values))

    def __getattr__(self, name: str) -> Any:
        try:
            return self._values[name]
        except KeyError:
            raise AttributeError(f'node {self._table.node!r} has no parameter {name!r}'
                                 f'{did_you_mean(name, list(self._values))}') from None

    def __setattr__(self, name: str, value: Any) -> None:
        raise AttributeError('parameter values are read-only')

    def as_dict(self) -> dict[str, Any]:
        """The values as a plain dict."""
        return dict(self._values)

    def __repr__(self) -> str:
        return f'Values({self._table.node!r}, {self._values!r})'


class ParameterTable:
    """
    The parameters of one node executable.

    Parameters
    ----------
    node : str
        Executable name (``plant``, ``damper``, ...).
    params : sequence of Param
        Its parameters, in documentation order.
    summary : str
        One line saying what the node does (shown by ``--help`` and in the docs).
    """

    def __init__(self, node: str, params: Sequence[Param], summary: str = ''):
        self.node = node
        self.params = tuple(params)
        self.summary = summary
        if len(set(self.names)) != len(self.params):
            raise ValueError(f'table {node!r} repeats a parameter name')

    def __iter__(self) -> Iterator[Param]:
        return iter(self.params)

    @property
    def names(self) -> list[str]:
        """Names of the parameters (placeholder names included)."""
        return [p.name for p in self.params]

    def get(self, name: str) -> Param | None:
        """The parameter called ``name`` (placeholders match), or None."""
        return next((p for p in self.params if p.matches(str(name))), None)

    def __getitem__(self, name: str) -> Param:
        param = self.get(name)
        if param is None:
            raise KeyError(name)
        return param

    def __contains__(self, name: str) -> bool:
        return self.get(name) is not None

    def unknown(self, name: str, source: str) -> ConfigError:
        """The error of a parameter this node does not have, naming the closest one."""
        return ConfigError(f'{source}: unknown parameter {name!r}'
                           f'{did_you_mean(name, self.names)}')

    def check(self, params: Mapping[str, Any], source: str) -> None:
        """
        Refuse unknown names and bad values.

        Parameters
        ----------
        params : mapping
            Parameter name -> value (a node section of a parameter file).
        source : str
            Where the parameters come from (file and node), for the message.

        Raises
        ------
        ConfigError
            For the first unknown name (naming the closest known one) or bad value (naming
            the parameter and the value).
        """
        for name, value in flatten(params).items():
            if name in ROS_NODE_PARAMETERS:
                continue
            param = self.get(str(name))
            if param is None:
                raise self.unknown(str(name), source)
            problem = param.problem(value)
            if problem:
                raise ConfigError(f'{source}: parameter {name!r} = {problem}')

    def values(self, params: Mapping[str, Any] | None = None, source: str = '') -> Values:
        """
        The values a node of this table runs with: defaults, overridden by ``params``.

        Checked like :meth:`check`; placeholder parameters are left out.
        """
        params = flatten(params or {})
        self.check(params, source or f'parameters of {self.node}')
        return Values(self, {p.name: p.clean(params.get(p.name, p.default))
                             for p in self.params if p.pattern is None})

    def text(self) -> str:
        """The table as plain text (``--help``)."""
        lines = []
        for p in self.params:
            facts = [p.type, f'default {_show(p.default)}']
            if p.unit:
                facts.append(f'unit {p.unit}')
            if p.range_text():
                facts.append(p.range_text())
            facts.append('read-only' if p.read_only else 'settable while running')
            lines += [f'  {p.name} ({"; ".join(facts)})', f'      {p.description}']
        return '\n'.join(lines)

    def markdown(self) -> str:
        """The table as a Markdown table (docs/parameters.md)."""
        rows = ['| name | type | default | unit | range | read-only | description |',
                '|---|---|---|---|---|---|---|']
        for p in self.params:
            text = p.description.replace('<', '&lt;').replace('>', '&gt;')   # not HTML tags
            cells = [f'`{p.name}`', p.type, f'`{_show(p.default)}`', p.unit, p.range_text(),
                     'yes' if p.read_only else 'no', text]
            rows.append('| ' + ' | '.join(c.replace('|', '\\|') for c in cells) + ' |')
        return '\n'.join(rows)


def _show(value: Any) -> str:
    """A default as it would be written in a parameter file."""
    if isinstance(value, str):
        return repr(value)
    if isinstance(value, bool):
        return str(value).lower()
    return repr(value)


def table_of(executable: str) -> ParameterTable:
    """The parameter table of a node executable (imported on first use)."""
    try:
        target = PARAMETER_TABLES[executable]
    except KeyError:
        raise ConfigError(f'{executable!r} is not a node executable; node executables: '
                          f'{", ".join(NODE_KINDS)}') from None
    module, attribute = target.split(':')
    return getattr(importlib.import_module(module), attribute)


def all_tables() -> dict[str, ParameterTable]:
    """Every node executable's table, in :data:`NODE_KINDS` order."""
    return {kind: table_of(kind) for kind in NODE_KINDS}


HEADER = """# Node parameters

Generated from the nodes' parameter tables (`pentapod_sim/executables.py` names the module
of each) by `python -m pentapod_sim.parameters --markdown > docs/parameters.md`;
test/test_parameters.py checks that this file is up to date. Do not edit it by hand.

Units are SI. Every node refuses a parameter name it does not know, naming the closest known
one, and so does the scenario runner for a scenario file; a `/**` section may hold parameters
that only some nodes declare. Read-only parameters are read once at start; the others may be
changed while the node runs (`ros2 param set`). An empty list default is declared as `['']`,
`[0]` or `[0.0]` (ROS 2 cannot type an empty list); these entries mean nothing in any list.
`ros2 run pentapod_testbed <node> --help` prints a node's table.
"""


def markdown() -> str:
    """docs/parameters.md: one table per node executable."""
    parts = [HEADER]
    for kind, table in all_tables().items():
        parts += [f'## {kind}', '', f'`{module_of(kind)}`: {table.summary}', '',
                  table.markdown(), '']
    return '\n'.join(parts)


def main(argv=None) -> int:
    """``python -m pentapod_sim.parameters [--markdown | NODE]``: print tables."""
    # whole option names only, as CommandParser (pentapod_sim.cli, a later stage) does
    parser = argparse.ArgumentParser(description="Print the nodes' parameter tables.",
                                     allow_abbrev=False)
    parser.add_argument('node', nargs='?', choices=NODE_KINDS, help='one node (text table)')
    parser.add_argument('--markdown', action='store_true',
                        help='all tables as Markdown (docs/parameters.md)')
    args = parser.parse_args(argv)
    if args.markdown or args.node is None:
        print(markdown(), end='')
    else:
        print(table_of(args.node).text())
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
