"""
Shared pieces of the testbed nodes: QoS constants, parameters, stamps, spinning, main().

Every node declares its parameters from its table (:mod:`pentapod_sim.parameters`) with
:func:`declare_table`, which refuses unknown override names; :func:`run_node` prints the
table for ``--help`` and each error once.

Every node spins with ``spin_once`` loops on rclpy's EventsExecutor (about 5x faster per
round trip than the default executor here; its ``spin()`` hung in tests, ``spin_once`` does
not), falling back to the SingleThreadedExecutor if it is missing.
"""
from __future__ import annotations

import gc
import math
import os
import sys
import time
from typing import Callable

from builtin_interfaces.msg import Time
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor, ParameterType
import rclpy
from rclpy.duration import Duration
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.impl.implementation_singleton import rclpy_implementation
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions
from rclpy.utilities import remove_ros_args

from pentapod_sim import interface, shutdown
from pentapod_sim.errors import ConfigError, RunError
from pentapod_sim.nodes.overrides import override_origins
from pentapod_sim.parameters import all_tables, Param, ParameterTable, Values
from pentapod_sim.scenario import network

RCLError = rclpy_implementation.RCLError


def qos(kind: str, fresh: bool = False) -> QoSProfile:
    """
    Rclpy QoS profile of a class of topics of :data:`pentapod_sim.interface.QOS`.

    ``fresh``: a subscription that wants only what is published after it matched (volatile),
    also where the writers keep their history for late readers (transient local).
    """
    spec = interface.QOS[kind]
    durability = 'volatile' if fresh else spec.durability
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=spec.depth,
                      reliability=ReliabilityPolicy[spec.reliability.upper()],
                      durability=DurabilityPolicy[durability.upper()])


#: Plant outputs (states, /clock): reliable, deep enough that lockstep never drops a step;
#: the writers keep their history for a late recorder (``interface.STREAM_DURABILITY``).
STATE_QOS = qos('state')
#: Forces from sources: reliable; a source sends one message per step.
FORCE_QOS = qos('force')
#: Diagnostics streams (PMA state, excitation): reliable, deep.
INFO_QOS = qos('info')
#: Subscriptions of the lockstep loop itself (sources to states, plant to forces): the steps
#: published from now on, none of a writer's history.
STATE_SUB_QOS = qos('state', fresh=True)
FORCE_SUB_QOS = qos('force', fresh=True)

_TYPES = {'bool': ParameterType.PARAMETER_BOOL, 'int': ParameterType.PARAMETER_INTEGER,
          'float': ParameterType.PARAMETER_DOUBLE, 'str': ParameterType.PARAMETER_STRING,
          'double[]': ParameterType.PARAMETER_DOUBLE_ARRAY,
          'integer[]': ParameterType.PARAMETER_INTEGER_ARRAY,
          'string[]': ParameterType.PARAMETER_STRING_ARRAY}
_INT64 = 2 ** 63 - 1
#: The arguments run_node gave rclpy.init (None: a node started otherwise; sys.argv is used).
_process_args: list[str] | None = None


def descriptor(param: Param) -> ParameterDescriptor:
    """ROS parameter descriptor of a table entry: type, description with unit, range."""
    desc = ParameterDescriptor(type=_TYPES[param.type], read_only=param.read_only,
                               description=param.full_description(),
                               additional_constraints=param.range_text())
    if param.type == 'float' and (param.low is not None or param.high is not None):
        desc.floating_point_range = [FloatingPointRange(
            from_value=-math.inf if param.low is None else float(param.low),
            to_value=math.inf if param.high is None else float(param.high), step=0.0)]
    elif param.type == 'int' and (param.low is not None or param.high is not None):
        desc.integer_range = [IntegerRange(
            from_value=-_INT64 if param.low is None else int(param.low),
            to_value=_INT64 if param.high is None else int(param.high), step=1)]
    return desc


def node_args(cli_args=None) -> list[str]:
    """Command-line arguments that reached a node: the process's and its own ``cli_args``."""
    process = sys.argv if _process_args is None else _process_args
    return list(process) + list(cli_args or [])


def declare_param(node, table: ParameterTable, name: str, default=None):
    """
    Declare one parameter of ``table`` and return its value as the node uses it.

    ``name`` may be an instance of a placeholder name (``source_ports.damper``). A value the
    table refuses raises ConfigError naming the node, the parameter and the value.
    """
    param = table[name]
    value = param.default if default is None else default
    override = node._parameter_overrides.get(name)
    where = f'node {node.get_name()!r}'
    # rclpy types a parameter by its default and takes [] for a byte array: an empty list is
    # declared as its "none" mark ([''] or [0]), an override as itself (once checked)
    empty = [param.none_mark] if param.none_mark is not None else value
    try:
        if override is not None and override.value is None and param.is_array:
            # an empty list in a parameter file arrives untyped: it is the empty list
            declared = node.declare_parameter(name, empty, descriptor(param),
                                              ignore_override=True)
        else:
            if override is not None:
                table.check({name: override.value}, where)
                value = override.value
            declared = node.declare_parameter(name, empty if value == [] else value,
                                              descriptor(param))
    except ConfigError:
        raise
    except Exception as err:  # rclpy raises several types for bad overrides
        raise ConfigError(f'{where}: parameter {name!r}: {err}') from None
    return param.clean(declared.value)


def declare_table(node, table: ParameterTable, args=None, defaults=None) -> Values:
    """
    Declare every plain parameter of ``table`` on ``node`` and return the typed values.

    First every override given to the node (``-p``, ``--params-file``, constructor) is
    checked: a name the table does not know is refused with a ConfigError naming the closest
    known one, unless it reaches the node only through a wildcard section (``/**``) and some
    node executable declares it (see :mod:`pentapod_sim.nodes.overrides`).

    Parameters
    ----------
    node : rclpy.node.Node
        The node, created with ``allow_undeclared_parameters=False`` (rclpy's default).
    table : ParameterTable
        Its parameters.
    args : sequence of str, optional
        The command line the overrides came from (default :func:`node_args`).
    defaults : dict, optional
        Defaults known only at run time (``source_name``: the node's name).
    """
    refuse_unknown_overrides(node, table, node_args() if args is None else args)
    defaults = defaults or {}
    return Values(table, {p.name: declare_param(node, table, p.name, defaults.get(p.name))
                          for p in table if p.pattern is None})


def refuse_unknown_overrides(node, table: ParameterTable, args) -> None:
    """
    ConfigError for an override the node does not know (see :func:`declare_table`).

    rclpy keeps the overrides of a node in ``Node._parameter_overrides`` (filled from rcl
    in the constructor; there is no public getter). With ``allow_undeclared_parameters=False``
    rclpy silently drops overrides that are never declared, so they are compared here with
    the table and the parameters rclpy declared itself (``use_sim_time``, ...).
    """
    unknown = [name for name in node._parameter_overrides
               if name not in table and not node.has_parameter(name)]
    if not unknown:
        return
    origins = override_origins(args, node.get_name(), node.get_fully_qualified_name())
    for name in unknown:
        if name in origins.shared and name not in origins.own and any(
                name in other for other in all_tables().values()):
            continue                    # a shared /** entry meant for other nodes
        raise table.unknown(name, f'node {node.get_name()!r}')


def freeze_start_up() -> None:
    """
    Collect the start-up garbage once, then take every object alive now out of the collector.

    A node's loop allocates few containers, but a collection of an older generation re-scans
    every tracked object there: the ~135,000 objects of the imports, the model and the nodes.
    Such a generation-1 collection took 1-5 ms here (a missed deadline at a 1 kHz exchange);
    a composed 30,000-step run saw one in its loop. Frozen (:func:`gc.freeze`), they are no
    longer scanned and the same run saw a single generation-0 collection (51-91 us).
    :func:`run_node` calls this once the node is built.
    """
    gc.collect()
    gc.freeze()


def set_stamp(stamp: Time, ns: int) -> None:
    """Fill a builtin_interfaces/Time in place from integer nanoseconds (pre-built messages)."""
    stamp.sec, stamp.nanosec = divmod(ns, 1_000_000_000)


def stamp_msg(ns: int) -> Time:
    """builtin_interfaces/Time from integer nanoseconds."""
    stamp = Time()
    set_stamp(stamp, ns)
    return stamp


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


#: Wall time [s] between two checks of the plant's force topics' publishers during a run.
GRAPH_CHECK_PERIOD = 0.25
#: Wall time [s] a second publisher on a force topic gets to be discovered by node name.
NAME_DISCOVERY = 2.0
_UNKNOWN_NAME = '_NODE_NAME_UNKNOWN_'


def shared_topic_error(topic: str, infos, first_seen: dict) -> str | None:
    """
    The refusal of a force topic with several publishers, naming every publishing node.

    None while a publisher's node name is still undiscovered, for at most
    :data:`NAME_DISCOVERY` s after ``topic`` was first seen shared (``first_seen``: topic ->
    monotonic time, kept by the caller): a later check then names them.
    """
    now = time.monotonic()
    if (any(i.node_name == _UNKNOWN_NAME for i in infos)
            and now - first_seen.setdefault(topic, now) < NAME_DISCOVERY):
        return None
    nodes = ', '.join(sorted(f'{i.node_namespace.rstrip("/")}/{i.node_name}' for i in infos))
    return (f'force topic {topic} has {len(infos)} publishers ({nodes}); one source per '
            'topic (parameter shared_source_topics allows more)')


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


def wait_for_acks(node, publishers, timeout: float) -> None:
    """
    Wait until every subscriber acknowledged every message of ``publishers`` (reliable QoS).

    Waits in slices of 0.1 s and ends early when a topic has no subscriber left (a
    subscriber that died), or after ``timeout`` [s] in all (warning, parameter ack_timeout).
    """
    end = time.monotonic() + timeout
    for pub in publishers:
        while pub.get_subscription_count():
            if pub.wait_for_all_acked(Duration(seconds=0.1)):
                break
            if time.monotonic() > end:
                node.get_logger().warning(
                    f'{pub.topic_name}: not every message acknowledged within '
                    f'ack_timeout = {timeout} s')
                return


def wants_help(args) -> bool:
    """True if the non-ROS arguments ask for help (``-h``, ``--help``)."""
    return any(a in ('-h', '--help') for a in remove_ros_args(list(args))[1:])


def usage(table: ParameterTable) -> str:
    """``--help`` text of a node executable: usage line, summary and parameter table."""
    return (f'usage: ros2 run pentapod_testbed {table.node} [--ros-args [-p NAME:=VALUE] ... '
            f'[--params-file FILE] ...]\n\n{table.node}: {table.summary}\n\n'
            f'parameters (docs/parameters.md):\n{table.text()}')


def run_node(factory: Callable[..., object], argv=None, run: Callable | None = None, *,
             table: ParameterTable | None = None, executor: Callable = make_executor) -> int:
    """
    Jazzy-style main: init, build the node, spin or ``run(node, executor)``, clean shutdown.

    ``--help`` prints the usage and ``table`` and starts nothing. Returns 0 on a clean end,
    1 after printing one ``error: ...`` line on a ConfigError/RunError, and 128 + the signal
    number after a clean stop on SIGINT, SIGTERM or SIGHUP (:mod:`pentapod_sim.shutdown`).
    """
    global _process_args
    args = list(sys.argv if argv is None else argv)
    try:
        if table is not None and wants_help(args):
            print(usage(table))
            return 0
    except RCLError as err:            # e.g. a parameter file rcl cannot parse
        print(f'error: {str(err).splitlines()[0]}', file=sys.stderr)
        return 1
    _process_args = args
    try:                    # DDS on the loopback unless opened (docs/nodes.md, "Isolation")
        network.prepare_process()
    except (ConfigError, RunError) as err:
        print(f'error: {err}', file=sys.stderr)
        return 1
    # SIGINT/SIGTERM/SIGHUP only request a stop (pentapod_sim.shutdown); rclpy's own handlers
    # would invalidate the context at once, so a node could neither finish its step nor
    # publish, write its files or wait for acknowledgements.
    shutdown.install()
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    node = None
    code = 0
    try:
        node = factory()
        network.check_sockets()             # the participant's sockets exist by now
        spinner = executor()
        if hasattr(node, 'add_to'):          # several nodes (a composed run)
            node.add_to(spinner)
        else:
            spinner.add_node(node)
        freeze_start_up()
        if run is not None:
            run(node, spinner)
        else:
            while rclpy.ok() and not shutdown.requested():
                spinner.spin_once(timeout_sec=0.1)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except (ConfigError, RunError, ValueError, KeyError) as err:
        print(f'error: {err}', file=sys.stderr)
        code = 1
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    if code == 0 and shutdown.requested():
        print(f'stopped by {shutdown.signal_name()}', file=sys.stderr)
        code = shutdown.exit_code()
    return code
