"""
Launch a testbed scenario: ``ros2 launch pentapod_testbed testbed.launch.py scenario:=<name>``.

The scenario is a ROS parameter file of config/scenarios (or a path), read and checked by the
runner's parser (:func:`pentapod_sim.scenario.files.read_scenario`). Every node of it becomes
one Node of package pentapod_testbed: its node kind's executable, or the ``component``
executable for a class its section names (``node_class: module:Class``), with its checked
parameters (its own section and the ``/**`` entries it declares). The launch ends when the
plant and every recorder have ended.

Recording (docs/recording.md): a shipped scenario's recorder writes the run to
``out/bags/<scenario>-<UTC time>/`` and stops by itself once it holds every step; the launch
ends after the plant and every recorder have ended. ``record:=false`` leaves the recorders out
(and takes them from the nodes' ``wait_for_subscribers``); ``bag:=PATH`` records to the folder
PATH; ``record:=true`` adds a recorder to a scenario that has none.

Like the runner, the launch isolates its nodes (:mod:`pentapod_sim.scenario.domain`): unless
set in the environment (or by ``domain_id:=``), ``ROS_AUTOMATIC_DISCOVERY_RANGE`` is
LOCALHOST and ``ROS_DOMAIN_ID`` a free domain, reserved while ``ros2 launch`` runs.
"""
import os
from pathlib import Path

from launch.actions import (
    DeclareLaunchArgument,
    EmitEvent,
    LogInfo,
    OpaqueFunction,
    RegisterEventHandler,
    SetEnvironmentVariable,
)
from launch.event_handlers import OnProcessExit
from launch.events import Shutdown
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

from launch import LaunchDescription
from pentapod_sim.errors import ConfigError
from pentapod_sim.registry import PLANT, RECORDER
from pentapod_sim.scenario.domain import DOMAIN_VAR, isolation, RANGE_VAR
from pentapod_sim.scenario.files import read_scenario, resolve

#: Domain leases of this launch process: the lock files stay locked until it exits.
_LEASES = []


def _isolation(context):
    """SetEnvironmentVariable actions for discovery range and domain (user values kept)."""
    chosen = LaunchConfiguration('domain_id').perform(context) or None
    changes, lease = isolation(os.environ, chosen)
    if lease is not None:
        _LEASES.append(lease)
    merged = {**os.environ, **changes}
    return [SetEnvironmentVariable(name, value) for name, value in changes.items()] + [
        LogInfo(msg=f'{DOMAIN_VAR}={merged[DOMAIN_VAR]}, '
                    f'{RANGE_VAR}={merged.get(RANGE_VAR, "(unset)")}')]


def _flag(context, name: str) -> bool:
    """A true/false launch argument (ConfigError names a bad value)."""
    value = LaunchConfiguration(name).perform(context).strip().lower()
    if value not in ('true', 'false'):
        raise ConfigError(f"launch argument {name}:={value!r}: use 'true' or 'false'")
    return value == 'true'


def _without_recorders(scenario):
    """The scenario without its recorders, their names taken from the others' waits."""
    recorders = {n.name for n in scenario.of_role(RECORDER)}
    scenario = scenario.without(recorders)
    for node in scenario.nodes:
        wait = getattr(node.params, 'wait_for_subscribers', ())
        if set(wait) & recorders:
            scenario = scenario.with_params(node.name, wait_for_subscribers=[
                n for n in wait if n not in recorders])
    return scenario


def _nodes(context):
    """Nodes of the chosen scenario; shut the launch down when the plant and recorders end."""
    path = resolve(LaunchConfiguration('scenario').perform(context))
    scenario = read_scenario(path)
    overrides = {}
    for key in ('steps', 'duration'):
        value = LaunchConfiguration(key).perform(context)
        if value:
            overrides[key] = int(value) if key == 'steps' else float(value)
    if overrides:
        scenario = scenario.with_params(scenario.plant.name, **overrides)
    record, bag = _flag(context, 'record'), LaunchConfiguration('bag').perform(context)
    recorder = {'bag_name': f'{Path(path).stem}-{{utc}}'}
    if bag:
        recorder = {'output_dir': str(Path(bag).parent), 'bag_name': Path(bag).name}
    if not record:
        scenario = _without_recorders(scenario)
    elif not scenario.of_role(RECORDER):
        scenario = scenario.with_node('recorder', recorder)
    elif bag:
        for node in scenario.of_role(RECORDER):
            scenario = scenario.with_params(node.name, **recorder)
    actions, awaited = [], []
    for node in scenario.nodes:
        action = Node(package='pentapod_testbed', executable=node.executable, name=node.name,
                      arguments=[] if node.kind else [node.node_class],
                      parameters=[node.ros_values()], output='screen')
        actions.append(action)
        if node.role in (PLANT, RECORDER):
            awaited.append(action)
    if _flag(context, 'live') and not scenario.of_kind('live_view'):
        port = LaunchConfiguration('live_port').perform(context)
        actions.append(Node(package='pentapod_testbed', executable='live_view', name='live_view',
                            parameters=[{'port': int(port)}], output='screen'))
    ended = set()

    def on_exit(event, _context, action_name):
        ended.add(action_name)
        if len(ended) == len(awaited):
            return [EmitEvent(event=Shutdown(reason='plant and recorders finished'))]
        return []
    for action in awaited:       # sources live until the recorders hold every step
        actions.append(RegisterEventHandler(OnProcessExit(
            target_action=action,
            on_exit=lambda event, ctx, name=id(action): on_exit(event, ctx, name))))
    return actions


def generate_launch_description():
    """Arguments: scenario, steps, duration (plant overrides), record, bag, live, domain_id."""
    return LaunchDescription([
        DeclareLaunchArgument('scenario', default_value='baseline',
                              description='scenario name (config/scenarios) or YAML path'),
        DeclareLaunchArgument('steps', default_value='', description='plant steps override'),
        DeclareLaunchArgument('duration', default_value='',
                              description='plant duration override [s]'),
        DeclareLaunchArgument('record', default_value='true',
                              description='true: record the run (docs/recording.md); false: '
                              "leave the scenario's recorders out"),
        DeclareLaunchArgument('bag', default_value='',
                              description='bag folder of the recording (default: the '
                              "scenario's, out/bags/<scenario>-<UTC time>)"),
        DeclareLaunchArgument('live', default_value='false',
                              description='true: serve the run to Foxglove over WebSocket '
                              '(live_view node, docs/live_view.md)'),
        DeclareLaunchArgument('live_port', default_value='8765',
                              description='WebSocket port of the live view (127.0.0.1)'),
        DeclareLaunchArgument('domain_id', default_value='',
                              description='ROS_DOMAIN_ID of the nodes (default: the '
                              "environment's, else a free domain reserved for the launch)"),
        OpaqueFunction(function=_isolation),
        OpaqueFunction(function=_nodes),
    ])
