"""
Launch a testbed scenario: ``ros2 launch pentapod_testbed testbed.launch.py scenario:=<name>``.

The scenario is a ROS parameter file of config/scenarios (or a path). Every node section of
it becomes one Node of package pentapod_testbed; the executable follows from the node name's
prefix exactly as in :mod:`pentapod_sim.scenario.runner` (same parser and table), and every
node gets the whole file as its parameter file (so ``/**`` entries reach all nodes). The
launch ends when the plant ends.

Like the runner, the launch isolates its nodes (:mod:`pentapod_sim.scenario.domain`): unless
set in the environment (or by ``domain_id:=``), ``ROS_AUTOMATIC_DISCOVERY_RANGE`` is
LOCALHOST and ``ROS_DOMAIN_ID`` a free domain, reserved while ``ros2 launch`` runs.
"""
import os

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


def _nodes(context):
    """Nodes of the chosen scenario; shut the launch down when the plant exits."""
    path = resolve(LaunchConfiguration('scenario').perform(context))
    overrides = {}
    for key in ('steps', 'duration'):
        value = LaunchConfiguration(key).perform(context)
        if value:
            overrides[key] = int(value) if key == 'steps' else float(value)
    actions = []
    for node in read_scenario(path).nodes:
        params = [str(path)] + ([overrides] if node.executable == 'plant' and overrides
                                else [])
        action = Node(package='pentapod_testbed', executable=node.executable, name=node.name,
                      parameters=params, output='screen')
        actions.append(action)
        if node.executable == 'plant':
            actions.append(RegisterEventHandler(OnProcessExit(
                target_action=action, on_exit=[EmitEvent(event=Shutdown(
                    reason='plant finished'))])))
    return actions


def generate_launch_description():
    """Arguments: scenario (name or file), steps and duration (plant overrides), domain_id."""
    return LaunchDescription([
        DeclareLaunchArgument('scenario', default_value='baseline',
                              description='scenario name (config/scenarios) or YAML path'),
        DeclareLaunchArgument('steps', default_value='', description='plant steps override'),
        DeclareLaunchArgument('duration', default_value='',
                              description='plant duration override [s]'),
        DeclareLaunchArgument('domain_id', default_value='',
                              description='ROS_DOMAIN_ID of the nodes (default: the '
                              "environment's, else a free domain reserved for the launch)"),
        OpaqueFunction(function=_isolation),
        OpaqueFunction(function=_nodes),
    ])
