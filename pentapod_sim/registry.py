"""
The package's nodes, commands and configuration files, each listed once.

A node kind is one :class:`NodeKind`: its executable name (``ros2 run pentapod_testbed <name>``;
a scenario node whose name starts with it runs it), its node class, its parameter class (a
frozen dataclass of :func:`pentapod_sim.parameters.param` fields in a ROS-free module) and its
role in a run. Everything else derives from this list: setup.py's console scripts and
``lib/pentapod_testbed`` launchers (setup.py reads this file without importing the package; a
node's entry point is its module's ``main``), the scenario runner's node kinds, the launch
file, composed runs, ``--help`` and docs/parameters.md. A node class of a user's own package
needs no entry here: a scenario names it with ``node_class: module:Class``
(docs/nodes.md, "Your own controller").

This file imports only the standard library (setup.py runs it with :func:`runpy.run_path`).
"""
from dataclasses import dataclass

#: Roles of a node in a run: the plant runs the loop and is started last; sources answer its
#: steps; a recorder is drained before the sources stop; a view only watches.
PLANT, SOURCE, RECORDER, VIEW = 'plant', 'source', 'recorder', 'view'


@dataclass(frozen=True)
class NodeKind:
    """
    One node executable.

    Attributes
    ----------
    name : str
        Executable name; scenario node names starting with it run it.
    node : str
        ``module:Class`` of the rclpy node.
    params : str
        ``module:Class`` of its parameters (ROS-free, so scenario files are checked without ROS).
    role : str
        :data:`PLANT`, :data:`SOURCE`, :data:`RECORDER` or :data:`VIEW`.
    """

    name: str
    node: str
    params: str
    role: str = SOURCE

    @property
    def module(self) -> str:
        """Python module of the node (``python -m`` runs it)."""
        return self.node.split(':')[0]

    @property
    def entry_point(self) -> str:
        """``module:function`` of its console script: the node module's ``main``."""
        return f'{self.module}:main'


NODES = (
    NodeKind('plant', 'pentapod_sim.nodes.plant_node:PlantNode',
             'pentapod_sim.nodes.parameter_tables:PlantParams', PLANT),
    NodeKind('exciter', 'pentapod_sim.nodes.exciter_node:ExciterNode',
             'pentapod_sim.nodes.parameter_tables:ExciterParams'),
    NodeKind('cutting', 'pentapod_sim.nodes.cutting_node:CuttingNode',
             'pentapod_sim.nodes.parameter_tables:CuttingParams'),
    NodeKind('disturbance', 'pentapod_sim.nodes.disturbance_node:DisturbanceNode',
             'pentapod_sim.nodes.parameter_tables:DisturbanceParams'),
    NodeKind('recorder', 'pentapod_sim.nodes.recorder_node:RecorderNode',
             'pentapod_sim.nodes.parameter_tables:RecorderParams', RECORDER),
    NodeKind('live_view', 'pentapod_sim.nodes.live_view_node:LiveViewNode',
             'pentapod_sim.live.params:LiveViewParams', VIEW),
    NodeKind('damper', 'pentapod_damper.nodes.damper_node:DamperNode',
             'pentapod_damper.node_parameters:DamperParams'),
    NodeKind('pma', 'pentapod_damper.nodes.pma_node:PmaNode',
             'pentapod_damper.node_parameters:PmaParams'),
    NodeKind('example_controller', 'pentapod_damper.nodes.example_controller:ExampleController',
             'pentapod_damper.node_parameters:ExampleControllerParams'),
)

#: Executables that are not nodes: name -> ``module:function``.
COMMANDS = {
    'scenario': 'pentapod_sim.scenario.runner:main',
    'component': 'pentapod_sim.nodes.component:main',
    'modes': 'pentapod_sim.cli.modes:main',
    'statespace': 'pentapod_sim.cli.statespace:main',
    'analyze': 'pentapod_sim.cli.analyze:main',
    'calibrate': 'pentapod_sim.cli.calibrate:main',
    'study': 'pentapod_damper.study.__main__:main',
    'judge': 'pentapod_damper.judge.__main__:main',
    'sweep': 'pentapod_damper.sweep.__main__:main',
}

#: Files validated by a schema (:mod:`pentapod_sim.schema`): name -> ``module:Class`` of the
#: schema, in the order docs/config.md documents them. The first six are in config/; the
#: others are files a user brings (FE import, damping, calibration).
CONFIG_FILES = {
    'machine.yaml': 'pentapod_sim.fe.machine_data:MachineParams',
    'positions.yaml': 'pentapod_sim.fe.machine_data:PositionsFile',
    'reduction.yaml': 'pentapod_sim.plant.config:ReductionConfig',
    'machining.yaml': 'pentapod_sim.machining.materials:MachiningTable',
    'study.yaml': 'pentapod_damper.study.config:StudyFile',
    'judge.yaml': 'pentapod_damper.judge.config:JudgeConfig',
    'FE model description (modes --fe-model FILE.yaml)':
        'pentapod_sim.fe.imported.description:FEDescription',
    'damping file (damping.yaml, reduction.yaml damping_file)':
        'pentapod_sim.plant.damping_file:DampingFile',
    'calibration settings (calibrate --settings FILE.yaml)':
        'pentapod_sim.analysis.calibration.settings:CalibrationSettings',
}


def executables() -> dict[str, str]:
    """Every console script: name -> ``module:function`` (nodes first)."""
    return {**{kind.name: kind.entry_point for kind in NODES}, **COMMANDS}


def node_kind(name: str) -> NodeKind:
    """The node kind called ``name`` (KeyError if there is none)."""
    for kind in NODES:
        if kind.name == name:
            return kind
    raise KeyError(name)
