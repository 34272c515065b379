"""
A composed run: every node of a scenario in one process, on one executor.

rclpy has no component container, so this module is one: it reads the scenario once
(:func:`pentapod_sim.scenario.files.read_scenario`), builds the same node classes that run as
separate processes (the registry's, :data:`pentapod_sim.registry.NODES`, and a user's class a
section names with ``node_class: module:Class``), each with its section's name and its checked
values as parameter overrides, adds them all to one executor and runs the plant's loop. The
plant and its in-process lockstep sources hand their per-step messages to each other directly,
without DDS (:mod:`pentapod_sim.nodes.local_bus`): the sources answer inside the
plant's publish, a recorder in the composition takes these topics from the hand-off too
(and writes the bytes DDS would have delivered), and DDS carries a message only to subscribers
outside that hand-off (the live view, other processes). The arithmetic and the values are the
same, so the traces and bags equal those of the separate-process run bit for bit. Stop
signals, exit codes and errors behave as for a single node
(:func:`pentapod_sim.nodes.common.run_node`)::

    python -m pentapod_sim.nodes.composed SCENARIO
"""
from __future__ import annotations

import argparse
import sys

from rclpy.parameter import Parameter

from pentapod_sim import shutdown
from pentapod_sim.errors import ConfigError
from pentapod_sim.nodes import local_bus, plant_node
from pentapod_sim.nodes.common import run_node, spin_until
from pentapod_sim.parameters import load_class
from pentapod_sim.registry import PLANT
from pentapod_sim.scenario.files import read_scenario, resolve, Scenario


class Composition:
    """The nodes of one scenario in this process; the plant is the one that runs the loop."""

    def __init__(self, scenario: Scenario):
        self.nodes = []
        self.plant = None
        for node in scenario.nodes:
            overrides = [Parameter(name, value=value)
                         for name, value in node.ros_values().items()]
            made = load_class(node.node_class)(
                cli_args=['--ros-args', '-r', f'__node:={node.name}'],
                parameter_overrides=overrides)
            self.nodes.append(made)
            if node.role == PLANT:
                self.plant = made
        self.bus = None

    def add_to(self, executor) -> None:
        """Hand-off (:func:`.local_bus.connect`), every node to ``executor``, servers started."""
        if self.plant is not None:
            self.bus = local_bus.connect(self.plant, self.nodes, executor)
        for node in self.nodes:
            executor.add_node(node)
            if hasattr(node, 'start_component'):      # the live view's WebSocket server
                node.start_component()

    def destroy_node(self) -> None:
        """Close what needs closing (a recorder's bag), then destroy every node."""
        for node in self.nodes:
            if hasattr(node, 'close'):
                node.close()
            node.destroy_node()


#: Wall time [s] the in-process deliveries queued at the end of a run may take (also after a
#: stop signal: a recorder in the composition then still gets every step the plant ran).
FINAL_DRAIN = 2.0
#: Wall time [s] spun after that for DDS deliveries inside the process (run status, ...).
END_SETTLE = 0.5


def run(composition: Composition, executor) -> None:
    """Run the plant's loop on the executor holding every node, then let the others drain."""
    plant = composition.plant
    try:
        plant_node.run(plant, executor)
    finally:
        plant.flush_bus(executor, FINAL_DRAIN)
    if not shutdown.requested():
        # deliveries still queued in-process: until every recorder drained the announced end
        # (at most the time rclpy's DDS deliveries need), else that time
        recorders = [n for n in composition.nodes if hasattr(n, 'done')]
        spin_until(executor, lambda: bool(recorders) and all(n.done() for n in recorders),
                   END_SETTLE)


def main(argv=None) -> int:
    """
    Entry point: ``python -m pentapod_sim.nodes.composed SCENARIO``.

    Exit codes as :func:`pentapod_sim.nodes.common.run_node`: 0 finished, 1 error (one
    line), 128 + signal number after a clean stop.
    """
    argv = list(sys.argv if argv is None else argv)
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0],
                                     allow_abbrev=False)
    parser.add_argument('scenario', help='scenario name (config/scenarios) or YAML file')
    args = parser.parse_args(argv[1:])
    try:
        scenario = read_scenario(resolve(args.scenario))
    except ConfigError as err:
        print(f'error: {err}', file=sys.stderr)
        return 1
    return run_node(lambda: Composition(scenario), argv[:1], run)


if __name__ == '__main__':
    raise SystemExit(main())
