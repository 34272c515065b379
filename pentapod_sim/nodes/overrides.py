"""
Where a node's parameter overrides come from: its own rules or a shared wildcard section.

rclpy merges every override that applies to a node (``-p`` rules, the node's own sections of
``--params-file`` files and wildcard sections such as ``/**``) into one dict and does not keep
the origin. A node refuses names it does not declare, except names that reach it only through
a wildcard section: such a section serves every node of a scenario (``sample_rate`` in
``/**`` also reaches the damper, which has none). This module reads the same command line
rcl read and sorts the names by origin. ROS-free.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Iterator, Mapping, Sequence

import yaml

from pentapod_sim.parameters import flatten

#: rcl arguments that take a value (the value is skipped).
_WITH_VALUE = ('-r', '--remap', '-e', '--enclave', '--log-level', '--log-config-file',
               '--log-file-name')


@dataclass
class OverrideOrigins:
    """Names of parameters set for one node, by origin."""

    own: set[str] = field(default_factory=set)       # -p rules, the node's own sections
    shared: set[str] = field(default_factory=set)    # wildcard sections (``/**``, ``/*``)


def _sections(doc: Mapping, prefix: str = '') -> Iterator[tuple[str, Mapping]]:
    """(node path, parameters) of every ``ros__parameters`` section of a parameter file."""
    for key, body in doc.items():
        if not isinstance(body, dict):
            continue
        path = f'{prefix}/{str(key).strip("/")}'
        if isinstance(body.get('ros__parameters'), dict):
            yield path, body['ros__parameters']
        yield from _sections({k: v for k, v in body.items() if k != 'ros__parameters'}, path)


def _rules(args: Sequence[str]) -> tuple[list[str], list[str]]:
    """The ``-p`` rules and ``--params-file`` paths inside ``--ros-args`` blocks."""
    params, files = [], []
    inside = False
    tokens = iter(args)
    for token in tokens:
        if token == '--ros-args':
            inside = True
        elif token == '--':
            inside = False
        elif inside and token in ('-p', '--param'):
            params.append(next(tokens, ''))
        elif inside and token == '--params-file':
            files.append(next(tokens, ''))
        elif inside and token in _WITH_VALUE:
            next(tokens, None)
    return params, files


def override_origins(args: Sequence[str], node_name: str, node_path: str) -> OverrideOrigins:
    """
    Sort the parameter names a command line sets for one node by origin.

    Parameters
    ----------
    args : sequence of str
        Command-line arguments as given to rcl (process and node arguments).
    node_name, node_path : str
        The node's name and fully qualified name (``/ns/name``).
    """
    origins = OverrideOrigins()
    params, files = _rules(args)
    for rule in params:
        target, _, _ = rule.partition(':=')
        prefix, _, name = target.rpartition(':')
        if not prefix or prefix.strip('/') in (node_name, node_path.strip('/')):
            origins.own.add(name)
        elif '*' in prefix:
            origins.shared.add(name)
    for path in files:
        try:
            with open(path, encoding='utf-8') as stream:
                doc = yaml.safe_load(stream)
        except (OSError, yaml.YAMLError):
            continue                           # rcl reported it already
        if not isinstance(doc, dict):
            continue
        for section, values in _sections(doc):
            if '*' in section:
                origins.shared.update(flatten(values))
            elif section == node_path or section.rsplit('/', 1)[-1] == node_name:
                origins.own.update(flatten(values))
    return origins
