"""
Run one node class as its own process: a controller of your own package, without an executable.

    ros2 run pentapod_testbed component your_package.module:YourController [--help]
        [--ros-args -r __node:=NAME --params-file FILE ...]

The class is built like a node of the testbed (:func:`pentapod_sim.nodes.common.run_node`:
stop signals, exit codes, one error line) and spun on one executor; ``--help`` prints its
parameters if it has a ``Params`` class
(:class:`pentapod_sim.nodes.testbed_node.TestbedNode`).
The scenario runner starts a node whose section names ``node_class: module:Class`` this way;
the class's module must be importable (your package installed, or on ``PYTHONPATH``).
"""
from __future__ import annotations

import sys

from rclpy.utilities import remove_ros_args

from pentapod_sim.errors import ConfigError
from pentapod_sim.nodes.common import run_node
from pentapod_sim.parameters import load_class


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``ros2 run pentapod_testbed component module:Class``."""
    argv = list(sys.argv if argv is None else argv)
    targets = [a for a in remove_ros_args(argv)[1:] if not a.startswith('-')]
    if len(targets) != 1 or ':' not in targets[0]:
        print('usage: component module:Class [--help] [--ros-args ...]', file=sys.stderr)
        return 2
    try:
        cls = load_class(targets[0])
    except ConfigError as err:
        print(f'error: {err}', file=sys.stderr)
        return 1
    rest = list(argv)
    rest.remove(targets[0])
    return run_node(cls, rest)


if __name__ == '__main__':
    raise SystemExit(main())
