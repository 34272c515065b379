"""
The package's executables, listed once: ``ros2 run pentapod_testbed <name>``.

setup.py reads this file (without importing the package) to make the console scripts and the
``lib/pentapod_testbed`` launchers; the scenario runner and the launch file map scenario node
names to executables with :data:`NODE_KINDS`; :func:`pentapod_sim.parameters.table_of` finds a
node executable's parameter table through :data:`PARAMETER_TABLES`. This file imports nothing.
"""

#: executable name -> ``module:function`` of its entry point
EXECUTABLES = {
    'plant': 'pentapod_sim.nodes.plant_node:main',
    'exciter': 'pentapod_sim.nodes.exciter_node:main',
    'recorder': 'pentapod_sim.nodes.recorder_node:main',
    'live_view': 'pentapod_sim.nodes.live_view_node:main',
    'damper': 'pentapod_damper.nodes.damper_node:main',
    'pma': 'pentapod_damper.nodes.pma_node:main',
    'example_controller': 'pentapod_damper.nodes.example_controller:main',
    'scenario': 'pentapod_sim.scenario.runner:main',
    'modes': 'pentapod_sim.cli.modes:main',
    'statespace': 'pentapod_sim.cli.statespace:main',
    'analyze': 'pentapod_sim.cli.analyze:main',
    'calibrate': 'pentapod_sim.cli.calibrate:main',
    'study': 'pentapod_damper.study.__main__:main',
    'sweep': 'pentapod_damper.sweep.__main__:main',
}

#: Node executables a scenario file may use; a node section named ``<kind>...`` runs the
#: executable ``<kind>`` (the longest matching prefix wins).
NODE_KINDS = ('plant', 'exciter', 'recorder', 'live_view', 'damper', 'pma',
              'example_controller')

#: node executable -> ``module:attribute`` of its parameter table
#: (a :class:`pentapod_sim.parameters.ParameterTable` in a ROS-free module)
PARAMETER_TABLES = {
    'plant': 'pentapod_sim.nodes.parameter_tables:PLANT',
    'exciter': 'pentapod_sim.nodes.parameter_tables:EXCITER',
    'recorder': 'pentapod_sim.nodes.parameter_tables:RECORDER',
    'live_view': 'pentapod_sim.live.params:LIVE_VIEW',
    'damper': 'pentapod_damper.node_parameters:DAMPER',
    'pma': 'pentapod_damper.node_parameters:PMA',
    'example_controller': 'pentapod_damper.node_parameters:EXAMPLE_CONTROLLER',
}

#: node executable -> ``module:Class`` of its node, for composed runs (one process)
COMPONENTS = {
    'plant': 'pentapod_sim.nodes.plant_node:PlantNode',
    'exciter': 'pentapod_sim.nodes.exciter_node:ExciterNode',
    'recorder': 'pentapod_sim.nodes.recorder_node:RecorderNode',
    'live_view': 'pentapod_sim.nodes.live_view_node:LiveViewNode',
    'damper': 'pentapod_damper.nodes.damper_node:DamperNode',
    'pma': 'pentapod_damper.nodes.pma_node:PmaNode',
    'example_controller': 'pentapod_damper.nodes.example_controller:ExampleController',
}


def module_of(executable: str) -> str:
    """Python module of an executable (for ``python -m``)."""
    return EXECUTABLES[executable].split(':')[0]
