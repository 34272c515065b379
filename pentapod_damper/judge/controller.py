"""
The controller under judgement: how it is given, and what its runs add to a scenario.

Four ways to name it (``judge --help``):

* ``pkg.module:Class``: a node class of the user's own package, run composed with the plant
  (in one process, bit for bit the run of separate processes); its parameters from
  ``--params FILE`` (a ROS 2 parameter file with one section, or a plain mapping);
* a scenario (a shipped name such as ``tcp_damping`` or a file): its force sources other than
  exciters, with their sections, run composed (a built-in law, or the user's ``node_class``);
* ``--command 'CMD ...'``: a command line the judge starts for every run, in the run's ROS
  domain, as its own process (the testbed's nodes run as separate processes too);
* ``--node NAME``: a node already running, on the domain of ``ROS_DOMAIN_ID`` (0 if unset);
  it answers every run the judge starts, so its state carries over from run to run.

The source name (``/pentapod/forces/<source>``) and the ports it answers are given
(``--source``, ``--ports``), taken from the node's parameters, or learned from the first
recording (the names of its answers).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
import shlex
from typing import Any

from pentapod_sim import registry
from pentapod_sim.errors import ConfigError
from pentapod_sim.parameters import load_class, NODE_CLASS, NodeParams, params_of
from pentapod_sim.registry import SOURCE
from pentapod_sim.scenario.files import executable_of, read_scenario, resolve
from pentapod_sim.schema import read_mapping

#: Node kinds of a scenario that excite rather than control.
EXCITERS = ('exciter', 'disturbance')
#: Node name (and default source name) of a controller given as a class or command.
DEFAULT_NAME = 'controller'


@dataclass(frozen=True)
class Controller:
    """
    A controller and how a run starts it.

    Attributes
    ----------
    label : str
        Its name in the report.
    how : str
        ``class``, ``scenario``, ``command`` or ``node`` (``baseline`` for none).
    nodes : dict
        Scenario sections it adds: node name -> parameters (``node_class`` included).
    sources : tuple of str
        Its force sources' names.
    command : tuple of str
        The command line started for every run (``how == 'command'``).
    ports, sensors : tuple of str
        Input ports it answers and output ports it reads, if known (else learned).
    """

    label: str
    how: str
    nodes: dict[str, dict[str, Any]] = field(default_factory=dict)
    sources: tuple[str, ...] = ()
    command: tuple[str, ...] = ()
    ports: tuple[str, ...] = ()
    sensors: tuple[str, ...] = ()

    @property
    def composed(self) -> bool:
        """Its runs may run every node in one process."""
        return self.how in ('class', 'scenario', 'baseline')

    @property
    def slug(self) -> str:
        """A file-name-safe form of the label."""
        return ''.join(c if c.isalnum() or c in '-_' else '_' for c in self.label)


BASELINE = Controller('baseline', 'baseline')


def _params_file(path: str | None) -> dict[str, Any]:
    """Parameters of ``--params``: a ROS 2 parameter file with one section, or a mapping."""
    if not path:
        return {}
    doc = read_mapping(path)
    sections = {k: v for k, v in doc.items() if isinstance(v, dict) and 'ros__parameters' in v}
    if not sections:
        return dict(doc)
    own = [k for k in sections if not str(k).startswith('/')]
    if len(own) > 1:
        raise ConfigError(f'{path}: {len(own)} node sections ({", ".join(map(str, own))}); '
                          'give a file with the one section of your controller')
    merged: dict[str, Any] = {}
    for key in [k for k in sections if str(k).startswith('/')] + own:   # own entries win
        merged.update(sections[key]['ros__parameters'])
    return merged


def _topic_name(label: str) -> str:
    """A source name (a ROS name token) from a label: ``LabDamper`` -> ``labdamper``."""
    text = ''.join(c if c.isalnum() else '_' for c in label.lower()).strip('_')
    return text if text and text[0].isalpha() else DEFAULT_NAME


def from_class(target: str, params_file: str | None = None, source: str | None = None,
               ports: tuple[str, ...] = (), sensors: tuple[str, ...] = (),
               label: str | None = None) -> Controller:
    """
    A node class ``module:Class`` with its parameters (checked now if it declares ``Params``).

    Raises
    ------
    ConfigError
        If the class cannot be loaded or a parameter is wrong (naming it).
    """
    kind = next((k.name for k in registry.NODES if k.node == target), None)
    cls = load_class(target)
    params = _params_file(params_file)
    label = label or target.split(':')[-1]
    # two controllers of --compare answer on distinct topics unless told otherwise
    name = source or str(params.get('source_name') or _topic_name(label))
    schema = getattr(cls, 'Params', None)
    if isinstance(schema, type) and issubclass(schema, NodeParams):
        if any(p.field == 'source_name' for p in schema.ros_params()):
            params['source_name'] = name
        schema.build(params, f'{target} with {params_file or "its defaults"}')
    else:           # a plain node gets it as an override; it uses it if it declares it
        params['source_name'] = name
    return Controller(label, 'class',
                      {name: {**params, NODE_CLASS: kind or target}}, (name,), (),
                      tuple(ports), tuple(sensors))


def from_scenario(scenario: str | Path, ports: tuple[str, ...] = (),
                  sensors: tuple[str, ...] = ()) -> Controller:
    """The force sources of a scenario other than exciters (ConfigError if it has none)."""
    path = resolve(scenario)
    parsed = read_scenario(path)
    nodes: dict[str, dict[str, Any]] = {}
    sources = []
    for node in parsed.nodes:
        if node.role != SOURCE or node.kind in EXCITERS:
            continue
        section = {k: v for k, v in node.section().items()
                   if k not in ('sample_rate', 'wait_for_subscribers')}
        if node.named_class:
            section[NODE_CLASS] = node.kind or node.node_class
        nodes[node.name] = section
        sources.append(str(section.get('source_name') or node.name))
    if not nodes:
        raise ConfigError(f'scenario {path} has no controller (no force source other than '
                          'an exciter)')
    label = path.stem if path.parent.name == 'scenarios' or str(scenario) == path.stem \
        else str(scenario)
    return Controller(Path(label).stem, 'scenario', nodes, tuple(sources), (), tuple(ports),
                      tuple(sensors))


def from_command(command: str, source: str | None, ports: tuple[str, ...] = (),
                 sensors: tuple[str, ...] = ()) -> Controller:
    """A command line the judge starts for every run (``--source`` names its answers)."""
    argv = tuple(shlex.split(command))
    if not argv:
        raise ConfigError('--command is empty')
    name = source or DEFAULT_NAME
    return Controller(name, 'command', {}, (name,), argv, tuple(ports), tuple(sensors))


def from_node(node: str, source: str | None, ports: tuple[str, ...] = (),
              sensors: tuple[str, ...] = ()) -> Controller:
    """A node that already runs (its answers on ``/pentapod/forces/<source or node>``)."""
    return Controller(node, 'node', {}, (source or node,), (), tuple(ports), tuple(sensors))


def parse(spec: str, params_file: str | None = None, source: str | None = None,
          ports: tuple[str, ...] = (), sensors: tuple[str, ...] = ()) -> Controller:
    """``module:Class``, a node kind or a scenario (name or file); see the module docstring."""
    kinds = {k.name: k for k in registry.NODES if k.role == SOURCE}
    if spec in kinds and spec not in EXCITERS and not Path(spec).exists():
        return from_class(kinds[spec].node, params_file, source, ports, sensors, spec)
    if ':' in spec and not Path(spec).exists():
        return from_class(spec, params_file, source, ports, sensors)
    if params_file or source:
        raise ConfigError(f'{spec!r} is a scenario: its file holds the parameters and source '
                          'names (--params and --source are for a class or a command)')
    return from_scenario(spec, ports, sensors)


def law_ports(ctrl: Controller, dt: float) -> tuple[str, ...]:
    """
    Input ports of a controller whose nodes say which laws they run, without a run.

    Each node's parameter class builds its laws (``loop_laws``, as the offline analyses of a
    scenario do: :mod:`pentapod_sim.scenario.laws`); () if one of them cannot say (a plain
    node: its ports are learned from its first recording, or given with ``--ports``).
    """
    ports: list[str] = []
    for name, section in ctrl.nodes.items():
        try:
            target = str(section.get(NODE_CLASS) or executable_of(name))
            cls: Any = load_class(target) if ':' in target else None
            schema = cls.Params if cls is not None else params_of(target)
            params = {k: v for k, v in section.items() if k != NODE_CLASS}
            built: Any = schema.build(params, f'node {name!r}')
            laws = built.loop_laws(dt)
        except (AttributeError, ConfigError, KeyError):
            return ()
        ports += [p for law in laws for p in law.actuator_ports]
    return tuple(dict.fromkeys(ports))
