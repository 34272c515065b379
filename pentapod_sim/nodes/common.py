"""
Shared pieces of the testbed nodes: QoS constants, parameters, stamps, spinning, main().

Every node spins with ``spin_once`` loops on rclpy's EventsExecutor (about 5x faster per
round trip than the default executor here; its ``spin()`` hung in tests, ``spin_once`` does
not), falling back to the SingleThreadedExecutor if it is missing.
"""
from __future__ import annotations

import logging
import os
import sys
import time
from typing import Callable

from builtin_interfaces.msg import Time
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor, ParameterType
import rclpy
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from pentapod_sim import interface
from pentapod_sim.errors import ConfigError, RunError


def qos(kind: str) -> QoSProfile:
    """Rclpy QoS profile of a class of topics of :data:`pentapod_sim.interface.QOS`."""
    spec = interface.QOS[kind]
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=spec.depth,
                      reliability=ReliabilityPolicy[spec.reliability.upper()],
                      durability=DurabilityPolicy[spec.durability.upper()])


#: Plant outputs (states, /clock): reliable, deep enough that lockstep never drops a step.
STATE_QOS = qos('state')
#: Forces from sources: reliable; a source sends one message per step.
FORCE_QOS = qos('force')
#: Diagnostics streams (PMA state, excitation): reliable, deep.
INFO_QOS = qos('info')

_TYPES = {bool: ParameterType.PARAMETER_BOOL, int: ParameterType.PARAMETER_INTEGER,
          float: ParameterType.PARAMETER_DOUBLE, str: ParameterType.PARAMETER_STRING}
_ARRAY_TYPES = {'double[]': ParameterType.PARAMETER_DOUBLE_ARRAY,
                'string[]': ParameterType.PARAMETER_STRING_ARRAY,
                'integer[]': ParameterType.PARAMETER_INTEGER_ARRAY}


def declare(node, name: str, default, description: str, *, read_only: bool = False,
            low: float | None = None, high: float | None = None, array: str | None = None):
    """
    Declare a parameter with a descriptor and return its value.

    Parameters
    ----------
    node : rclpy.node.Node
        The node.
    name : str
        Parameter name.
    default : bool, int, float, str or list
        Default value (fixes the type).
    description : str
        Meaning and unit.
    read_only : bool
        True for parameters that define the model or wiring.
    low, high : float, optional
        Allowed range (rclpy enforces it; a violation raises naming the parameter).
    array : {'double[]', 'string[]', 'integer[]'}, optional
        Array type when the default is a list.
    """
    ptype = _ARRAY_TYPES[array] if array else _TYPES[type(default)]
    desc = ParameterDescriptor(description=description, read_only=read_only, type=ptype)
    if low is not None and isinstance(default, float):
        desc.floating_point_range = [FloatingPointRange(from_value=float(low),
                                                        to_value=float(high), step=0.0)]
    elif low is not None and isinstance(default, int):
        desc.integer_range = [IntegerRange(from_value=int(low), to_value=int(high), step=1)]
    try:
        return node.declare_parameter(name, default, desc).value
    except Exception as err:  # rclpy raises several types for bad overrides
        raise ConfigError(f'parameter {name!r} of node {node.get_name()!r}: {err}') from None


def stamp_msg(ns: int) -> Time:
    """builtin_interfaces/Time from integer nanoseconds."""
    return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def stamp_to_ns(stamp: Time) -> int:
    """Integer nanoseconds of a builtin_interfaces/Time."""
    return stamp.sec * 1_000_000_000 + stamp.nanosec


def make_executor(context=None):
    """EventsExecutor if rclpy has it, else SingleThreadedExecutor (optional context).

    ``PENTAPOD_EXECUTOR=single`` in the environment selects the SingleThreadedExecutor.
    """
    if os.environ.get('PENTAPOD_EXECUTOR', 'events') == 'single':
        return SingleThreadedExecutor(context=context)
    try:
        from rclpy.experimental import EventsExecutor
        return EventsExecutor(context=context)
    except ImportError:  # older rclpy
        return SingleThreadedExecutor(context=context)


def subscribers_of(node, publisher) -> tuple[set, bool]:
    """
    Names of the nodes subscribed to a publisher's topic, and whether all are matched.

    The names come from the ROS graph; ``matched`` is True when the publisher's DDS
    matches cover every subscription the graph shows, i.e. a message published now reaches
    each of them.
    """
    graph = node.get_subscriptions_info_by_topic(publisher.topic_name)
    return {info.node_name for info in graph}, publisher.get_subscription_count() >= len(graph)


def spin_until(executor, done: Callable[[], bool], timeout: float,
               poll: float = 0.05) -> bool:
    """Spin until ``done()`` or ``timeout`` [s] of wall time; return ``done()``."""
    end = time.monotonic() + timeout
    while not done():
        left = end - time.monotonic()
        if left <= 0:
            return done()
        executor.spin_once(timeout_sec=min(poll, left))
    return True


def run_node(factory: Callable[..., object], argv=None, run: Callable | None = None) -> int:
    """
    Jazzy-style main: init, build the node, spin or ``run(node, executor)``, clean shutdown.

    Returns 0 on a clean end (also SIGINT), 1 with a logged message on ConfigError/RunError.
    """
    rclpy.init(args=sys.argv if argv is None else argv)
    node = None
    code = 0
    try:
        node = factory()
        executor = make_executor()
        executor.add_node(node)
        if run is not None:
            run(node, executor)
        else:
            while rclpy.ok():
                executor.spin_once(timeout_sec=0.1)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except (ConfigError, RunError, ValueError, KeyError) as err:
        logging.getLogger('pentapod').error('%s', err)
        print(f'error: {err}', file=sys.stderr)
        code = 1
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return code
