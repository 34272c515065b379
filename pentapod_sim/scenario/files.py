"""
Scenario files: the one parser of config/scenarios/*.yaml and the resolution of their names.

A scenario is an ordinary ROS 2 parameter file: one ``<node_name>: ros__parameters:`` section
per node plus an optional ``/**`` section shared by all (e.g. ``sample_rate``). The executable
of a node follows from its name's prefix (:data:`pentapod_sim.executables.NODE_KINDS`).
Every node section is checked against its executable's parameter table
(:func:`pentapod_sim.parameters.table_of`): an unknown name is refused naming the closest
known one. A ``/**`` name must be known to at least one node executable; it reaches the nodes
that declare it.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from pentapod_sim.errors import ConfigError
from pentapod_sim.executables import module_of, NODE_KINDS
from pentapod_sim.parameters import all_tables, did_you_mean, table_of
from pentapod_sim.paths import scenario_dir
from pentapod_sim.schema import read_mapping


@dataclass(frozen=True)
class ScenarioNode:
    """A node of a scenario: its name, python module and ros2 executable."""

    name: str
    module: str
    executable: str


@dataclass(frozen=True)
class Scenario:
    """
    A parsed scenario file.

    Attributes
    ----------
    path : Path
        The file.
    nodes : list of ScenarioNode
        Its nodes, sources first and the plant last.
    sections : dict
        Parameters of every node: its own section's and those of the ``/**`` section its
        executable declares (its own entries win); checked against its parameter table.
    shared : dict
        The ``/**`` section's parameters.
    """

    path: Path
    nodes: list[ScenarioNode]
    sections: dict[str, dict[str, Any]]
    shared: dict[str, Any] = field(default_factory=dict)

    def of_kind(self, executable: str) -> list[ScenarioNode]:
        """Nodes running ``executable``."""
        return [n for n in self.nodes if n.executable == executable]


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
    """Executable of a scenario node by the longest matching name prefix."""
    for prefix in sorted(NODE_KINDS, key=len, reverse=True):
        if node_name.startswith(prefix):
            return prefix
    raise ConfigError(f'node {node_name!r}: name must start with one of {", ".join(NODE_KINDS)}')


def read_scenario(scenario: str | Path) -> Scenario:
    """
    Parse a scenario file (a path or a shipped scenario's name).

    Raises
    ------
    ConfigError
        If the file cannot be read, is not a mapping of ``<node>: {ros__parameters: {...}}``,
        names a node of no known kind, has a parameter its node does not know (naming the
        closest known one) or a bad value, or has not exactly one plant; the message names
        the file.
    """
    path = resolve(scenario)
    doc = read_mapping(path)        # one line for a file that is no YAML mapping
    shared_section = doc.get('/**') or {}
    if not isinstance(shared_section, dict):
        raise ConfigError(f"{path}: section '/**' is not a mapping")
    shared = shared_section.get('ros__parameters') or {}
    if not isinstance(shared, dict):
        raise ConfigError(f"{path}: section '/**' has no ros__parameters mapping")
    _check_shared(shared, f"{path}: section '/**'")
    sections, nodes = {}, []
    for name, body in doc.items():
        if str(name).startswith('/'):
            continue                            # wildcard sections such as /**
        if not isinstance(body, dict) or not isinstance(body.get('ros__parameters'), dict):
            raise ConfigError(f'{path}: section {name!r} has no ros__parameters mapping')
        try:
            executable = executable_of(name)
        except ConfigError as err:
            raise ConfigError(f'{path}: {err}') from None
        table = table_of(executable)
        own = body['ros__parameters']
        table.check(own, f'{path}: node {name!r} ({executable})')
        sections[name] = {**{k: v for k, v in shared.items() if k in table}, **own}
        nodes.append(ScenarioNode(name, module_of(executable), executable))
    if sum(n.executable == 'plant' for n in nodes) != 1:
        raise ConfigError(f'scenario file {path} needs exactly one plant node')
    nodes.sort(key=lambda n: n.executable == 'plant')
    return Scenario(path, nodes, sections, dict(shared))


def _check_shared(shared: dict, source: str) -> None:
    """Refuse a shared name no node executable knows, or a value wrong for one that does."""
    tables = all_tables().values()
    for name, value in shared.items():
        knowing = [t for t in tables if name in t]
        if not knowing:
            known = sorted({p.name for t in tables for p in t})
            raise ConfigError(f'{source}: no node has a parameter {name!r}'
                              f'{did_you_mean(str(name), known)}')
        for table in knowing:
            table.check({name: value}, f'{source} (for {table.node})')


class _QuotingDumper(yaml.SafeDumper):
    """YAML dumper that quotes every string: rcl reads a bare ``y`` or ``n`` as a boolean."""


_QuotingDumper.add_representer(
    str, lambda dumper, value: dumper.represent_scalar('tag:yaml.org,2002:str', value,
                                                       style="'"))


def dump_params(doc: dict) -> str:
    """A ROS 2 parameter file's text with every string quoted (safe for rcl's parser)."""
    return yaml.dump(doc, Dumper=_QuotingDumper, sort_keys=False)
