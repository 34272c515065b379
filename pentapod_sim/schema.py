"""
One validation style for every configuration file: dataclasses whose fields say what they hold.

A schema is a frozen dataclass. Each field is declared with :func:`spec`, whose metadata keeps

- ``unit``: SI unit of the value (``'-'`` for a pure number or text),
- ``rule``: ``'positive'`` (> 0), ``'non-negative'`` (>= 0) or ``'any'``, and optionally
  ``bounds`` (an interval), ``choices`` (admissible texts), ``length`` / ``min_length`` (of a
  list or mapping), ``broadcast`` (one number may stand for a list of ``length`` equal ones),
- ``description``: what the value means,
- ``pre``: a function applied to the YAML value before it is checked (e.g. ``'all'`` -> every
  port name),
- ``read_only`` and ``keys``: facts of node parameters (:mod:`pentapod_sim.parameters`): whether
  a running node may be given a new value, and which list parameter names the keys of a mapping.

Field types: ``bool``, ``int``, ``float``, ``str``, a nested schema, ``tuple[T, ...]`` (a YAML
list), ``dict[str, T]`` (a YAML mapping with free keys), ``T | None`` (with default ``None``) and
``float | tuple[float, ...]`` (one number or a list). A field with a default may be left out.
A field whose unit is ``rad`` may also be given in degrees as ``<name>_deg``.

:func:`build` makes a schema instance from a parsed YAML mapping and refuses unknown keys
(naming the closest known one), missing keys, wrong types and values against the rule (naming
the value and its unit). A schema's ``__post_init__`` may add cross-field checks by raising
:class:`~pentapod_sim.errors.ConfigError`. :func:`load` reads a YAML file first. Every error
is one line that starts with the file, then the key path, e.g.
``config/reduction.yaml: relevance[1].measur: unknown key; did you mean 'measure'?``.
"""
from __future__ import annotations

from dataclasses import field, fields, is_dataclass, MISSING
import difflib
import math
import os
from pathlib import Path
import types
import typing

import yaml

from pentapod_sim.errors import ConfigError

#: A field's metadata (:func:`spec`).
Meta = typing.Mapping[str, typing.Any]

POSITIVE = 'positive'
NON_NEGATIVE = 'non-negative'
ANY = 'any'
_RULES: dict[str, tuple[typing.Callable[[float], bool], str]] = {
    POSITIVE: (lambda v: v > 0.0, 'must be > 0'),
    NON_NEGATIVE: (lambda v: v >= 0.0, 'must be >= 0'),
    ANY: (lambda v: True, '')}
#: Up to this many choices are listed in full in an error message.
_LIST_CHOICES = 8


def spec(unit: str = '-', rule: str = ANY, *, description: str = '',
         default: typing.Any = MISSING, default_factory: typing.Any = MISSING,
         length: int | None = None,
         min_length: int | None = None, broadcast: bool = False,
         bounds: tuple[float, float] | None = None, closed: tuple[bool, bool] = (True, True),
         choices: typing.Sequence[str] | None = None,
         pre: typing.Callable[[typing.Any], typing.Any] | None = None,
         read_only: bool = True, keys: str | None = None) -> typing.Any:
    """
    Declare a schema field with its unit, rule and description.

    Parameters
    ----------
    unit : str
        SI unit of the value or of each item ('-' if none).
    rule : {'positive', 'non-negative', 'any'}
        Sign rule of a number (of each item of a list).
    description : str
        What the value means (shown with a missing key).
    default, default_factory : optional
        Value (or its maker) when the key is left out; without them the key is required.
    length, min_length : int, optional
        Exact or least number of items of a list or mapping.
    broadcast : bool
        One number stands for ``length`` equal items.
    bounds : (float, float), optional
        Interval of admissible numbers; ``closed`` says whether each end belongs to it.
    choices : sequence of str, optional
        Admissible texts (of the value, or of each item of a list).
    pre : callable, optional
        Applied to the YAML value before it is checked.
    read_only : bool
        A node parameter a running node reads once (False: settable while it runs).
    keys : str, optional
        A node parameter mapping whose keys are the entries of the list parameter ``keys``.
    """
    if rule not in _RULES:
        raise ValueError(f'unknown rule {rule!r}')
    meta = {'unit': unit, 'rule': rule, 'description': description, 'length': length,
            'min_length': min_length, 'broadcast': broadcast, 'bounds': bounds,
            'closed': closed, 'choices': tuple(choices) if choices is not None else None,
            'pre': pre, 'read_only': read_only, 'keys': keys}
    return field(default=default, default_factory=default_factory, metadata=meta)


def internal(default: typing.Any = '') -> typing.Any:
    """A field the file does not set (e.g. the file's name)."""
    return field(default=default, metadata={'internal': True})


def closest(name: str, known: typing.Iterable[str]) -> str | None:
    """The known name closest to ``name`` (``difflib``), or None if none is close."""
    match = difflib.get_close_matches(str(name), [str(k) for k in known], n=1, cutoff=0.6)
    return match[0] if match else None


def _join(path: str, key: typing.Any) -> str:
    return f'{path}.{key}' if path else str(key)


def _show(value: typing.Any, unit: str) -> str:
    text = repr(value)
    text = text if len(text) <= 80 else text[:76] + ' ...'
    return f'{text} {unit}' if unit not in ('', '-') else text


def _fail(path: str, value: typing.Any, unit: str, problem: str) -> typing.NoReturn:
    raise ConfigError(f'{path} = {_show(value, unit)}: {problem}')


def check_choice(value: typing.Any, choices: typing.Sequence[str], path: str,
                 what: str = 'value') -> str:
    """
    Return ``value`` if it is one of ``choices``.

    Raises
    ------
    ConfigError
        Naming the key path, the value and the closest choice (and all if there are few).
    """
    if isinstance(value, str) and value in choices:
        return value
    near = closest(value, choices) if isinstance(value, str) else None
    hint = f"; did you mean '{near}'?" if near else ''
    if len(choices) <= _LIST_CHOICES:
        _fail(path, value, '-', f'must be one of {", ".join(map(str, choices))}{hint}')
    _fail(path, value, '-', f'not a known {what}{hint}')


def _num(value: float) -> str:
    return str(value) if isinstance(value, int) else f'{value:g}'


def range_text(meta: typing.Mapping[str, typing.Any]) -> str:
    """The admissible values of a field as text: choices, interval or sign, item count."""
    parts = []
    if meta.get('choices'):
        parts.append('one of ' + ', '.join(meta['choices']))
    if meta.get('bounds') is not None:
        (lo, hi), (lo_in, hi_in) = meta['bounds'], meta.get('closed', (True, True))
        parts.append(f'{"[" if lo_in else "("}{_num(lo)}, {_num(hi)}{"]" if hi_in else ")"}')
    elif meta.get('rule', ANY) != ANY:
        parts.append({POSITIVE: '> 0', NON_NEGATIVE: '>= 0'}[meta['rule']])
    if meta.get('length') is not None:
        parts.append(f'{meta["length"]} items')
    elif meta.get('min_length'):
        parts.append(f'at least {meta["min_length"]} item{"s" if meta["min_length"] > 1 else ""}')
    return '; '.join(parts)


def _number(value: typing.Any, meta: Meta, path: str, integer: bool) -> float | int:
    """Check a number against its type, sign rule and bounds."""
    unit = meta.get('unit', '-')
    if isinstance(value, str) and not integer:
        try:                            # PyYAML reads 1e8 (no dot) as text
            value = float(value)
        except ValueError:
            pass
    if integer:
        if isinstance(value, bool) or not isinstance(value, int):
            _fail(path, value, unit, 'expected an integer')
    elif isinstance(value, bool) or not isinstance(value, (int, float)):
        _fail(path, value, unit, f'expected a number{f" in {unit}" if unit != "-" else ""}')
    else:
        value = float(value)
        if not math.isfinite(value):
            _fail(path, value, unit, 'not a finite number')
    ok, text = _RULES[meta.get('rule', ANY)]
    if not ok(value):
        _fail(path, value, unit, text)
    if meta.get('bounds') is not None:
        (lo, hi), (lo_in, hi_in) = meta['bounds'], meta['closed']
        if not ((lo <= value if lo_in else lo < value) and (value <= hi if hi_in else value < hi)):
            _fail(path, value, unit, f'must lie in {"[" if lo_in else "("}{lo:g}, {hi:g}'
                                     f'{"]" if hi_in else ")"}')
    return value


def _count(value: typing.Sized, meta: Meta, path: str, kind: str) -> None:
    length, least = meta.get('length'), meta.get('min_length')
    if length is not None and len(value) != length:
        _fail(path, value, '-', f'expected a {kind} of {length} items')
    if least is not None and len(value) < least:
        _fail(path, value, '-', f'expected a {kind} of at least {least} item'
                                f'{"s" if least > 1 else ""}')


def _union(value: typing.Any, args: tuple[typing.Any, ...], meta: Meta, path: str
           ) -> typing.Any:
    if value is None and type(None) in args:
        return None
    options = [a for a in args if a is not type(None)]
    if isinstance(value, (list, tuple)):
        chosen = next((a for a in options if typing.get_origin(a) is tuple or a is tuple), None)
    elif isinstance(value, dict):
        chosen = next((a for a in options if is_dataclass(a) or typing.get_origin(a) is dict),
                      None)
    else:
        chosen = None
    if chosen is not None:
        return _convert(value, chosen, meta, path)
    scalar = next((a for a in options if a in (bool, int, float, str)), options[0])
    return _convert(value, scalar, meta, path)


def _convert(value: typing.Any, hint: typing.Any, meta: Meta, path: str) -> typing.Any:
    """Check ``value`` against the type ``hint`` and the field's metadata; return it typed."""
    origin = typing.get_origin(hint)
    if origin in (typing.Union, types.UnionType):
        return _union(value, typing.get_args(hint), meta, path)
    if isinstance(hint, type) and is_dataclass(hint):
        return _build(hint, value, path)
    if hint is tuple or origin is tuple:
        item = typing.get_args(hint)[0] if typing.get_args(hint) else float
        if meta.get('broadcast') and not isinstance(value, (list, tuple)):
            value = [value] * int(meta['length'])
        if not isinstance(value, (list, tuple)):
            _fail(path, value, meta.get('unit', '-'), 'expected a list')
        _count(value, meta, path, 'list')
        return tuple(_convert(v, item, meta, f'{path}[{k}]') for k, v in enumerate(value))
    if origin is dict:
        item = typing.get_args(hint)[1]
        if not isinstance(value, dict):
            _fail(path, value, '-', 'expected a mapping')
        _count(value, meta, path, 'mapping')
        return {str(k): _convert(v, item, meta, _join(path, k)) for k, v in value.items()}
    if hint is bool:
        if not isinstance(value, bool):
            _fail(path, value, '-', 'expected true or false')
        return value
    if hint is str:
        if isinstance(value, bool):
            _fail(path, value, '-', 'expected a text (YAML reads a bare y, n, yes, no, on, off '
                                    'as true or false: quote it)')
        if not isinstance(value, str):
            _fail(path, value, '-', 'expected a text')
        return check_choice(value, meta['choices'], path) if meta.get('choices') else value
    if hint in (int, float):
        return _number(value, meta, path, hint is int)
    raise TypeError(f'{path}: schema type {hint!r} is not supported')


def _degrees(value: typing.Any) -> typing.Any:
    return tuple(math.radians(v) for v in value) if isinstance(value, tuple) \
        else math.radians(value)


def _build(cls: type, data: typing.Any, path: str) -> typing.Any:
    """Build schema ``cls`` from a mapping, checking every key recursively."""
    if not isinstance(data, dict):
        _fail(path or '<top level>', data, '-', 'expected a mapping of keys')
    hints = typing.get_type_hints(cls)
    own = [f for f in fields(cls) if not f.metadata.get('internal')]
    known = [n for f in own for n in (f.name, f'{f.name}_deg')
             if n == f.name or f.metadata.get('unit') == 'rad']
    for key in data:                    # a misspelt key first: it explains a missing one
        if key not in known:
            near = closest(key, known)
            hint = f"did you mean '{near}'?" if near else f'known keys: {", ".join(known)}'
            raise ConfigError(f'{_join(path, key)}: unknown key; {hint}')
    kwargs = {}
    for fld in own:
        meta, name = fld.metadata, fld.name
        key_path, deg = _join(path, name), f'{name}_deg'
        if deg in data and meta.get('unit') == 'rad':
            if name in data:
                raise ConfigError(f'{key_path}: give either {name} or {deg}, not both')
            bounds = meta.get('bounds') and tuple(map(math.degrees, meta['bounds']))
            value = _convert(data[deg], hints[name], dict(meta, unit='deg', bounds=bounds),
                             _join(path, deg))
            kwargs[name] = _degrees(value)
            continue
        if name not in data:
            if fld.default is not MISSING or fld.default_factory is not MISSING:
                continue
            about = f' ({meta["description"]})' if meta.get('description') else ''
            raise ConfigError(f'{key_path}: missing key{about}')
        value = data[name] if meta.get('pre') is None else meta['pre'](data[name])
        kwargs[name] = _convert(value, hints[name], meta, key_path)
    try:
        return cls(**kwargs)
    except ConfigError as err:          # a cross-field check of __post_init__
        raise ConfigError(f'{path}: {err}' if path else str(err)) from None


def build(cls: type, data: typing.Any, source: str) -> typing.Any:
    """
    Build schema ``cls`` from a parsed YAML mapping.

    Parameters
    ----------
    cls : type
        A dataclass declared with :func:`spec` fields.
    data : object
        The parsed YAML.
    source : str
        The file the data came from (the first word of every error; '' for none).

    Raises
    ------
    ConfigError
        ``<source>: <key path>: <problem>`` for the first problem found.
    """
    try:
        return _build(cls, data, '')
    except ConfigError as err:
        raise ConfigError(f'{source}: {err}' if source else str(err)) from None


def read_mapping(path: str | os.PathLike[str]) -> dict[str, typing.Any]:
    """
    Read a YAML file whose top level is a mapping.

    Raises
    ------
    ConfigError
        If the file cannot be read, is not valid YAML, is empty or is not a mapping; the
        message is one line and names the file (and the line of a YAML error).
    """
    try:
        text = Path(path).read_text(encoding='utf-8')
    except (OSError, UnicodeDecodeError) as err:
        raise ConfigError(f'{path}: cannot read: {err}') from None
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as err:
        mark = getattr(err, 'problem_mark', None)
        where = f':{mark.line + 1}:{mark.column + 1}' if mark is not None else ''
        problem = getattr(err, 'problem', None) or str(err).splitlines()[0]
        raise ConfigError(f'{path}{where}: not valid YAML: {problem}') from None
    if data is None:
        raise ConfigError(f'{path}: the file is empty (expected a mapping of keys)')
    if not isinstance(data, dict):
        raise ConfigError(f'{path}: expected a mapping of keys at the top level, got '
                          f'{type(data).__name__} {data!r:.60}')
    return data


def load(cls: type, path: str | os.PathLike[str]) -> typing.Any:
    """Read the YAML file ``path`` and :func:`build` schema ``cls`` from it."""
    return build(cls, read_mapping(path), str(path))
