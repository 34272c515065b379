"""
Node parameters: one frozen dataclass per node, declared like every configuration file (ROS-free).

A node's parameters are the fields of a :class:`NodeParams` dataclass, each made with
:func:`param`, the node flavour of :func:`pentapod_sim.schema.spec`: type (the annotation),
default, unit, range or choices, read-only flag and description. That one declaration gives

- the node's ROS 2 declarations and its typed values ``node.params``
  (:class:`pentapod_sim.nodes.testbed_node.TestbedNode`),
- the check of a scenario file before any node starts (:meth:`NodeParams.build`, the same
  checks as every configuration file: :func:`pentapod_sim.schema.build`),
- the parameter file a run writes (:meth:`NodeParams.ros_values`),
- ``--help`` (:func:`help_text`) and docs/parameters.md (:mod:`pentapod_sim.reference`).

Types: ``bool``, ``int``, ``float``, ``str``, ``tuple[T, ...]`` of these (a ROS 2 array) and
``dict[str, tuple[str, ...]]`` with ``keys='<list parameter>'``: one parameter per entry of that
list (``source_ports.<source>``). An integer is taken for a float. ROS 2 cannot type an empty
list, so a list whose default is empty is declared as ``['']``, ``[0]`` or ``[0.0]``; these
entries mean "none" in any value of it.
"""
from __future__ import annotations

import array
import dataclasses
import difflib
import functools
import importlib
import typing
from typing import Any, ClassVar, Iterable, Mapping, Self

from pentapod_sim import registry, schema
from pentapod_sim.errors import ConfigError

#: Parameters every rclpy node declares itself; a parameter file may set them for any node.
ROS_NODE_PARAMETERS = ('use_sim_time', 'start_type_description_service')
#: Scenario-file parameter naming the node class of a node (``module:Class`` or a node kind).
NODE_CLASS = 'node_class'
_ROS_TYPES = {bool: 'bool', int: 'integer', float: 'double', str: 'string'}
_NONE_MARK = {'string[]': '', 'integer[]': 0, 'double[]': 0.0}


def param(default: Any, description: str, unit: str = '', *,
          bounds: tuple[float, float] | None = None, choices: Iterable[str] | None = None,
          read_only: bool = True, keys: str | None = None) -> Any:
    """
    Declare a node parameter (a :func:`pentapod_sim.schema.spec` field).

    Parameters
    ----------
    default : bool, int, float, str, sequence or mapping
        Default value (a list becomes a tuple, a mapping is copied per instance).
    description : str
        Meaning, without the unit.
    unit : str
        SI unit ('' if none).
    bounds : (float, float), optional
        Closed range of a number (of every element of a list).
    choices : iterable of str, optional
        Admissible texts (of the value or of every element).
    read_only : bool
        True: read once at start; False: may be set while the node runs.
    keys : str, optional
        For a mapping: the list parameter whose entries are its keys.
    """
    extra: dict[str, Any] = {}
    if isinstance(default, Mapping):
        items = dict(default)
        extra['default_factory'] = lambda: dict(items)
    else:
        extra['default'] = tuple(default) if isinstance(default, list) else default
    return schema.spec(unit or '-', description=description, bounds=bounds,
                       choices=None if choices is None else tuple(choices),
                       read_only=read_only, keys=keys, **extra)


@dataclasses.dataclass(frozen=True)
class RosParam:
    """One ROS 2 parameter of a :class:`NodeParams` class (a field, or a mapping's pattern)."""

    name: str
    field: str
    type: str
    default: Any
    unit: str
    range: str
    read_only: bool
    description: str
    bounds: tuple[float, float] | None
    keys: str | None

    @property
    def is_array(self) -> bool:
        """True for the ROS 2 array types."""
        return self.type.endswith('[]')

    @property
    def none_mark(self) -> Any:
        """The entry declared for an empty default list (None for other parameters)."""
        return _NONE_MARK.get(self.type) if self.is_array and not self.default else None

    def ros_value(self, value: Any) -> Any:
        """A typed value as ROS 2 takes it: a list (the "none" mark for an empty one)."""
        if not self.is_array:
            return value
        items = list(value)
        return items if items or self.none_mark is None else [self.none_mark]

    def full_description(self) -> str:
        """Description with the unit, as the ROS parameter descriptor states it."""
        return f'{self.description} [{self.unit}]' if self.unit else self.description


def _ros_type(hint: Any, name: str) -> str:
    """ROS 2 type name of a field annotation (TypeError for what ROS 2 cannot hold)."""
    if hint in _ROS_TYPES:
        return _ROS_TYPES[hint]
    args = typing.get_args(hint)
    if typing.get_origin(hint) is tuple and len(args) == 2 and args[1] is Ellipsis \
            and args[0] in _ROS_TYPES:
        return _ROS_TYPES[args[0]] + '[]'
    if typing.get_origin(hint) is dict and args[0] is str:
        return _ros_type(args[1], name)
    raise TypeError(f'parameter {name!r}: type {hint!r} is not a ROS 2 parameter type')


class NodeParams:
    """
    Base of the parameter dataclasses of nodes (``@dataclass(frozen=True)`` subclasses).

    The class docstring says what the node does (``--help``, docs/parameters.md).
    """

    __dataclass_fields__: ClassVar[dict[str, Any]]

    @classmethod
    def ros_params(cls) -> tuple[RosParam, ...]:
        """The ROS 2 parameters of the class: its own fields first, then inherited ones."""
        return _ros_params(typing.cast(typing.Hashable, cls))

    @classmethod
    def build(cls, values: Mapping[str, Any], source: str,
              defaults: Mapping[str, Any] | None = None) -> Self:
        """
        The typed parameters from ROS 2 values (a parameter file section, overrides).

        Parameters
        ----------
        values : mapping
            Parameter name -> value; nested mappings are joined with '.' as ROS 2 does.
        source : str
            Where the values come from (``node 'plant'``, a file and node), for errors.
        defaults : mapping, optional
            Defaults known only at run time (e.g. ``source_name``: the node's name).

        Raises
        ------
        ConfigError
            ``<source>: unknown parameter 'x'; did you mean 'y'?`` or
            ``<source>: parameter <name> = <value> <unit>: <problem>``.
        """
        data: dict[str, Any] = dict(defaults or {})
        known = {p.name.split('.')[0]: p for p in cls.ros_params()}
        for name, value in flatten(values).items():
            if name in ROS_NODE_PARAMETERS or name == NODE_CLASS:
                continue
            head, _, key = name.partition('.')
            spec_ = known.get(head)
            if spec_ is None or bool(key) != (spec_.keys is not None):
                raise unknown(cls, name, source)
            value = _from_ros(spec_, value)
            if key:
                data.setdefault(head, {})[key] = value
            else:
                data[head] = value
        try:
            built = schema.build(cls, data, '')
        except ConfigError as err:
            raise ConfigError(f'{source}: parameter {err}') from None
        for p in cls.ros_params():
            if p.keys is None:
                continue
            entries, mapping = getattr(built, p.keys), getattr(built, p.field)
            for key in mapping:
                if key not in entries:
                    raise ConfigError(f"{source}: parameter '{p.field}.{key}' names no "
                                      f'{p.keys.removesuffix("s")} of parameter {p.keys!r} = '
                                      f'{list(entries)}')
            # one entry per key, the default for those not given
            built = dataclasses.replace(built, **{p.field: {
                key: mapping.get(key, p.default) for key in entries}})
        return typing.cast(Self, built)

    def ros_values(self, names: Iterable[str] | None = None) -> dict[str, Any]:
        """
        The values as ROS 2 parameters (flat names, lists, "none" marks), e.g. for a file.

        ``names`` (field names) limits them; a mapping gives one parameter per entry of its
        ``keys`` list.
        """
        chosen = None if names is None else set(names)
        out: dict[str, Any] = {}
        for p in self.ros_params():
            if chosen is not None and p.field not in chosen:
                continue
            value = getattr(self, p.field)
            if p.keys is None:
                out[p.name] = p.ros_value(value)
                continue
            for key in getattr(self, p.keys):
                out[f'{p.field}.{key}'] = p.ros_value(value.get(key, ()))
        return out

    def plain(self, names: Iterable[str] | None = None) -> dict[str, Any]:
        """The values as a YAML section holds them: lists, a mapping as a nested mapping."""
        chosen = None if names is None else set(names)
        out = {}
        for f in dataclasses.fields(typing.cast(Any, self)):
            if chosen is None or f.name in chosen:
                out[f.name] = _plain(getattr(self, f.name))
        return out


def _plain(value: Any) -> Any:
    if isinstance(value, tuple):
        return list(value)
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    return value


def _from_ros(p: RosParam, value: Any) -> Any:
    """A value of a file or of rclpy as the schema checks it: lists without "none" marks."""
    if not p.is_array:
        return value
    if value is None:                      # an empty list in a ROS 2 parameter file
        return []
    if isinstance(value, (array.array, tuple)):
        value = list(value)
    if isinstance(value, list) and p.none_mark is not None:
        value = [v for v in value if type(v) is bool or v != p.none_mark]
    return value


@functools.cache
def _ros_params(key: typing.Hashable) -> tuple[RosParam, ...]:
    cls = typing.cast(type, key)
    hints = typing.get_type_hints(cls)
    own = [f for f in dataclasses.fields(cls) if f.name in cls.__dict__.get('__annotations__', {})]
    fields = own + [f for f in dataclasses.fields(cls) if f not in own]
    out = []
    for f in fields:
        meta = f.metadata
        keys = meta.get('keys')
        factory = f.default_factory
        default = f.default if f.default is not dataclasses.MISSING else (
            factory() if callable(factory) else None)
        name = f.name if keys is None else f'{f.name}.<{keys.removesuffix("s")}>'
        out.append(RosParam(name, f.name, _ros_type(hints[f.name], f.name),
                            () if keys is not None else default,
                            '' if meta.get('unit', '-') == '-' else meta['unit'],
                            schema.range_text(meta), meta.get('read_only', True),
                            meta.get('description', ''), meta.get('bounds'), keys))
    return tuple(out)


def flatten(params: Mapping[str, Any], prefix: str = '') -> dict[str, Any]:
    """Parameters of a ``ros__parameters`` mapping by full name (nested names joined by '.')."""
    flat: dict[str, Any] = {}
    for key, value in params.items():
        if isinstance(value, Mapping):
            flat.update(flatten(value, f'{prefix}{key}.'))
        else:
            flat[f'{prefix}{key}'] = value
    return flat


def declares(cls: type[NodeParams], name: str) -> bool:
    """True if the class has a parameter ``name`` (a mapping's ``field.<key>`` included)."""
    head, _, key = name.partition('.')
    return any(p.field == head and bool(key) == (p.keys is not None) for p in cls.ros_params())


def did_you_mean(name: str, known: Iterable[str]) -> str:
    """'; did you mean X?' for the nearest known name, or the list of known names."""
    known = list(known)
    close = difflib.get_close_matches(name, known, n=1, cutoff=0.6)
    if close:
        return f'; did you mean {close[0]!r}?'
    return f' (known: {", ".join(sorted(known))})'


def unknown(cls: type[NodeParams], name: str, source: str) -> ConfigError:
    """The error of a parameter the class does not have, naming the closest one."""
    return ConfigError(f'{source}: unknown parameter {name!r}'
                       f'{did_you_mean(name, [p.name for p in cls.ros_params()])}')


def summary(cls: type, whole: bool = False) -> str:
    """First paragraph of the class docstring (``whole``: all of it), on one line."""
    text = (cls.__doc__ or '').strip()
    return ' '.join((text if whole else text.split('\n\n')[0]).split())


def load_class(target: str) -> type:
    """The class of a ``module:Class`` text (ConfigError naming a bad one)."""
    module, _, name = target.partition(':')
    try:
        return typing.cast(type, getattr(importlib.import_module(module), name))
    except (ImportError, AttributeError, ValueError) as err:
        raise ConfigError(f'node class {target!r}: {err}') from None


def params_of(kind: str) -> type[NodeParams]:
    """The parameter class of a node kind of :data:`pentapod_sim.registry.NODES`."""
    try:
        return typing.cast(type[NodeParams], load_class(registry.node_kind(kind).params))
    except KeyError:
        raise ConfigError(f'{kind!r} is not a node kind; node kinds: '
                          f'{", ".join(k.name for k in registry.NODES)}') from None


def kinds_declaring(name: str) -> list[str]:
    """The node kinds whose parameters include ``name``."""
    return [k.name for k in registry.NODES if declares(params_of(k.name), name)]


def help_text(cls: type[NodeParams]) -> str:
    """The parameters as plain text (``--help``)."""
    lines = []
    for p in cls.ros_params():
        facts = [p.type, f'default {show(p.default)}']
        facts += [f'unit {p.unit}'] if p.unit else []
        facts += [p.range] if p.range else []
        facts.append('read-only' if p.read_only else 'settable while running')
        lines += [f'  {p.name} ({"; ".join(facts)})', f'      {p.description}']
    return '\n'.join(lines)


def show(value: Any) -> str:
    """A value as it is written in a parameter file."""
    if isinstance(value, bool):
        return str(value).lower()
    if isinstance(value, (list, tuple)):
        return '[' + ', '.join(show(v) for v in value) + ']'
    return repr(value)


def sample_time(sample_rate: float) -> float:
    """Sample time [s] of a sample rate [Hz]: the one place it is derived."""
    return 1.0 / sample_rate


@dataclasses.dataclass(frozen=True)
class Sampled(NodeParams):
    """Parameters of a node that works at the plant's sample rate."""

    sample_rate: float = param(5000.0, "plant sample rate (every node of a run: the plant's)",
                               'Hz', bounds=(1.0, 1.0e6))

    @property
    def dt(self) -> float:
        """Sample time [s] (:func:`sample_time`)."""
        return sample_time(self.sample_rate)


@dataclasses.dataclass(frozen=True)
class SourceParams(NodeParams):
    """Parameters of every lockstep force source (:mod:`pentapod_sim.nodes.lockstep_source`)."""

    source_name: str = param('', "publishes forces on /pentapod/forces/<source_name>; empty: "
                             "the node's name (the declared default)")
    wait_for_subscribers: tuple[str, ...] = param(
        (), "node names (e.g. a recorder) that must be subscribed and matched to this node's "
        'information topics before it answers step 0 (the plant re-sends step 0 meanwhile)')

    def loop_laws(self, dt: float | None = None) -> list[Any]:
        """
        The control laws the node closes around the plant, built as it runs them.

        For offline analyses of a scenario (its sampled closed loop, the lobes of
        ``statespace lobes``; :mod:`pentapod_sim.scenario.laws`): laws with ``sensor_ports``,
        ``actuator_ports`` and a linear model (``discrete_model()`` or ``linear_gain()``,
        :func:`pentapod_sim.sim.controllers.controller_of`), sampled with ``dt`` [s] (default:
        the node's own sample time); an empty list for a node that closes no loop.

        Raises
        ------
        ConfigError
            Here, for a node class that does not say: its law cannot be modelled offline.
        """
        raise ConfigError(f'{type(self).__name__} does not say which laws it runs '
                          '(no loop_laws method): it cannot be modelled offline')
