"""
Scenario files: the one parser of config/scenarios/*.yaml, and the one parameter file of a run.

A scenario is an ordinary ROS 2 parameter file: one ``<node_name>: ros__parameters:`` section
per node plus an optional ``/**`` section shared by all (e.g. ``sample_rate``). A node runs the
node kind (:data:`pentapod_sim.registry.NODES`) its name starts with (the longest matching
prefix), or the class its section names with ``node_class: module:Class`` (a controller of the
user's own package) or ``node_class: <kind>``.

:func:`read_scenario` checks every node section against the node's parameter class
(:class:`pentapod_sim.parameters.NodeParams`): an unknown name is refused naming the closest
known one, a bad value naming the node, the parameter and the value. A ``/**`` name must be
declared by some node kind (or a class of the scenario); it reaches the nodes that declare it,
a node whose class has no ``Params`` gets all of them. The result is typed: each
:class:`ScenarioNode` holds its parameter values. A run writes them as one parameter file
(:meth:`Scenario.document`: one resolved section per node, no ``/**``) or hands them to the
nodes of a composed run as parameter overrides.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Iterable, Mapping

import yaml

from pentapod_sim import registry
from pentapod_sim.errors import ConfigError
from pentapod_sim.parameters import (
    declares,
    did_you_mean,
    flatten,
    kinds_declaring,
    load_class,
    NODE_CLASS,
    NodeParams,
    params_of,
)
from pentapod_sim.paths import scenario_dir
from pentapod_sim.schema import read_mapping

#: Module that runs a node class of a user's package as its own process.
COMPONENT_MODULE = registry.COMMANDS['component'].split(':')[0]


@dataclass(frozen=True)
class ScenarioNode:
    """
    A node of a scenario with its parameter values.

    Attributes
    ----------
    name : str
        Node name.
    kind : str or None
        Its node kind (:data:`pentapod_sim.registry.NODES`); None for a user's class.
    node_class : str
        ``module:Class`` of the node.
    role : str
        Role in the run (:data:`pentapod_sim.registry.PLANT`, ``SOURCE``, ...).
    params : NodeParams or dict
        Typed values (defaults for those not given), or the given mapping of a class without
        ``Params``.
    given : tuple of str
        Names of the parameters the scenario sets (only these are written and handed over).
    named_class : bool
        True if the section names its class (``node_class``).
    """

    name: str
    kind: str | None
    node_class: str
    role: str
    params: Any
    given: tuple[str, ...]
    named_class: bool = False

    @property
    def executable(self) -> str:
        """Executable of the node: its kind, or ``component`` for a user's class."""
        return self.kind or 'component'

    @property
    def module(self) -> str:
        """Python module started with ``python -m`` for this node."""
        return self.node_class.split(':')[0] if self.kind else COMPONENT_MODULE

    def section(self) -> dict[str, Any]:
        """The given parameters as a YAML section holds them (lists, nested mappings)."""
        if isinstance(self.params, NodeParams):
            return self.params.plain(self.given)
        return dict(self.params)

    def ros_values(self) -> dict[str, Any]:
        """The given parameters as ROS 2 takes them (flat names, "none" marks for [])."""
        if isinstance(self.params, NodeParams):
            return self.params.ros_values(self.given)
        return flatten(self.params)

    def with_params(self, source: str, **changes: Any) -> ScenarioNode:
        """This node with parameters changed (checked like the file; ``source`` names it)."""
        merged = {**self.section(), **changes}
        given = self.given + tuple(k.split('.')[0] for k in changes if k not in self.given)
        params = type(self.params).build(merged, source) if isinstance(
            self.params, NodeParams) else merged
        return replace(self, params=params, given=given)


@dataclass(frozen=True)
class Scenario:
    """
    A parsed scenario file: its nodes, sources first and the plant last.

    Attributes
    ----------
    path : Path
        The file it was read from (or will be written to).
    nodes : tuple of ScenarioNode
        Its nodes.
    """

    path: Path
    nodes: tuple[ScenarioNode, ...]

    @property
    def sections(self) -> dict[str, dict[str, Any]]:
        """Node name -> the parameters the scenario gives it (own and ``/**``), checked."""
        return {n.name: n.section() for n in self.nodes}

    @property
    def plant(self) -> ScenarioNode:
        """The plant node."""
        return self.of_role(registry.PLANT)[0]

    def of_kind(self, kind: str) -> list[ScenarioNode]:
        """Nodes of the node kind ``kind``."""
        return [n for n in self.nodes if n.kind == kind]

    def of_role(self, role: str) -> list[ScenarioNode]:
        """Nodes of one role (:data:`pentapod_sim.registry.PLANT`, ``RECORDER``, ...)."""
        return [n for n in self.nodes if n.role == role]

    def node(self, name: str) -> ScenarioNode:
        """The node called ``name``."""
        for node in self.nodes:
            if node.name == name:
                return node
        raise ConfigError(f'scenario {self.path}: no node {name!r}'
                          f'{did_you_mean(name, [n.name for n in self.nodes])}')

    def with_params(self, name: str, **changes: Any) -> Scenario:
        """The scenario with parameters of node ``name`` changed (checked)."""
        new = self.node(name).with_params(f'{self.path}: node {name!r} with {changes}',
                                          **changes)
        return replace(self, nodes=tuple(new if n.name == name else n for n in self.nodes))

    def with_node(self, name: str, params: Mapping[str, Any], node_class: str | None = None
                  ) -> Scenario:
        """
        The scenario with the node ``name`` set to ``params`` alone, checked like a file's.

        A node of that name is replaced in its place; a new one comes before the plant.
        """
        node = _node(name, dict(params), {}, node_class, f'{self.path}: node {name!r}')
        names = [n.name for n in self.nodes]
        nodes = list(self.nodes)
        if name in names:
            nodes[names.index(name)] = node
        else:
            nodes.append(node)
        return _ordered(self.path, nodes)

    def without(self, names: Iterable[str]) -> Scenario:
        """The scenario without the nodes ``names``."""
        drop = set(names)
        return replace(self, nodes=tuple(n for n in self.nodes if n.name not in drop))

    def document(self) -> dict[str, Any]:
        """The run's parameter file: one resolved section per node (no ``/**``)."""
        doc = {}
        for node in self.nodes:
            values = node.ros_values()
            if node.named_class:
                values[NODE_CLASS] = node.kind if node.kind else node.node_class
            doc[node.name] = {'ros__parameters': values}
        return doc

    def write(self, path: Path) -> Path:
        """Write :meth:`document` to ``path`` (strings quoted for rcl); return the path."""
        Path(path).write_text(dump_params(self.document()), encoding='utf-8')
        return Path(path)


def scenario_names() -> list[str]:
    """Names of the shipped scenarios."""
    folder = scenario_dir()
    return sorted(p.stem for p in folder.glob('*.yaml')) if folder.is_dir() else []


def resolve(scenario: str | Path) -> Path:
    """Path of a scenario file given a path or a shipped scenario's name (ConfigError)."""
    path = Path(scenario)
    if path.is_file():
        return path
    cand = scenario_dir() / f'{scenario}.yaml'
    if cand.is_file():
        return cand
    raise ConfigError(f'scenario {str(scenario)!r} is neither a file nor one of: '
                      f'{", ".join(scenario_names())}')


def executable_of(node_name: str) -> str:
    """Node kind of a scenario node by the longest matching name prefix."""
    kinds = sorted((k.name for k in registry.NODES), key=len, reverse=True)
    for prefix in kinds:
        if node_name.startswith(prefix):
            return prefix
    raise ConfigError(f'node {node_name!r}: name must start with one of '
                      f'{", ".join(k.name for k in registry.NODES)}, or its section must name '
                      f'its class ({NODE_CLASS}: module:Class)')


def read_scenario(scenario: str | Path | Scenario) -> Scenario:
    """
    Parse a scenario file (a path or a shipped scenario's name); a Scenario is returned as is.

    Raises
    ------
    ConfigError
        If the file cannot be read, is not a mapping of ``<node>: {ros__parameters: {...}}``,
        names a node of no known kind or a class that cannot be loaded, has a parameter its
        node does not know (naming the closest known one) or a bad value, or has not exactly
        one plant; the message names the file.
    """
    if isinstance(scenario, Scenario):
        return scenario
    path = resolve(scenario)
    doc = read_mapping(path)
    shared = _section(doc.get('/**', {'ros__parameters': {}}), path, '/**')
    source = f"{path}: section '/**'"
    for name, value in flatten(shared).items():          # wrong for a kind that declares it
        for kind in kinds_declaring(name):
            params_of(kind).build({name: value}, f'{source} (for {kind})')
    nodes = []
    for name, body in doc.items():
        if str(name).startswith('/'):
            continue                            # wildcard sections such as /**
        own = _section(body, path, name)
        node_class = own.pop(NODE_CLASS, None)
        nodes.append(_node(str(name), own, shared, node_class, f'{path}: node {name!r}'))
    _check_shared(shared, nodes, source)
    return _ordered(path, nodes)


def _section(body: Any, path: Path, name: Any) -> dict[str, Any]:
    if not isinstance(body, dict) or not isinstance(body.get('ros__parameters'), dict):
        raise ConfigError(f'{path}: section {name!r} has no ros__parameters mapping')
    return dict(body['ros__parameters'])


def _node(name: str, own: dict[str, Any], shared: Mapping[str, Any], node_class: Any,
          source: str) -> ScenarioNode:
    """One node: its class, its role and its checked values (own entries win over /**)."""
    if node_class is not None and not isinstance(node_class, str):
        raise ConfigError(f'{source}: {NODE_CLASS} = {node_class!r} is not a text')
    try:
        kind = executable_of(name) if node_class is None else (
            node_class if ':' not in node_class else None)
        entry = registry.node_kind(kind) if kind else None
    except (ConfigError, KeyError) as err:
        raise ConfigError(f'{source}: {err}' if isinstance(err, ConfigError) else
                          f'{source}: {NODE_CLASS} {node_class!r} is no node kind ('
                          f'{", ".join(k.name for k in registry.NODES)}) nor module:Class'
                          ) from None
    if entry is not None:
        params_cls: Any = params_of(entry.name)
        target, role = entry.node, entry.role
    else:
        params_cls = getattr(load_class(str(node_class)), 'Params', None)
        target, role = str(node_class), registry.SOURCE
    source = f'{source} ({kind or target})'
    if isinstance(params_cls, type) and issubclass(params_cls, NodeParams):
        mine = {k: v for k, v in flatten(shared).items() if declares(params_cls, k)}
        values = {**mine, **flatten(own)}
        params: Any = params_cls.build(values, source)
        named = {k.split('.')[0] for k in values}
        given = tuple(p.field for p in params_cls.ros_params() if p.field in named)
    else:                                   # a class without a parameter schema: unchecked
        params = {**dict(shared), **own}
        given = tuple(params)
    return ScenarioNode(name, kind, target, role, params, given, node_class is not None)


def _ordered(path: Path, nodes: list[ScenarioNode]) -> Scenario:
    """The scenario with its plant last; ConfigError unless it has exactly one."""
    if sum(n.role == registry.PLANT for n in nodes) != 1:
        raise ConfigError(f'scenario file {path} needs exactly one plant node')
    nodes.sort(key=lambda n: n.role == registry.PLANT)
    return Scenario(Path(path), tuple(nodes))


def _check_shared(shared: Mapping[str, Any], nodes: list[ScenarioNode], source: str) -> None:
    """Refuse a shared name that no node kind and no class of the scenario declares."""
    classes = [type(n.params) for n in nodes if isinstance(n.params, NodeParams)]
    for name in flatten(shared):
        if not kinds_declaring(name) and not any(declares(c, name) for c in classes):
            known = sorted({p.name for k in registry.NODES for p in params_of(k.name)
                            .ros_params()})
            raise ConfigError(f'{source}: no node has a parameter {name!r}'
                              f'{did_you_mean(str(name), known)}')


class _QuotingDumper(yaml.SafeDumper):
    """YAML dumper that quotes every string: rcl reads a bare ``y`` or ``n`` as a boolean."""


_QuotingDumper.add_representer(
    str, lambda dumper, value: dumper.represent_scalar('tag:yaml.org,2002:str', value,
                                                       style="'"))


def dump_params(doc: dict[str, Any]) -> str:
    """A ROS 2 parameter file's text with every string quoted (safe for rcl's parser)."""
    return yaml.dump(doc, Dumper=_QuotingDumper, sort_keys=False)
