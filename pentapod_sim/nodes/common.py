"""
Shared pieces of the testbed nodes: QoS constants, stamps, spinning, main().

Every node declares its parameters from its ``Params`` class
(:class:`pentapod_sim.nodes.testbed_node.TestbedNode`); :func:`run_node` prints them for
``--help`` and each error once.

Every node spins with ``spin_once`` loops on rclpy's EventsExecutor (about 5x faster per
round trip than the default executor here; its ``spin()`` hung in tests, ``spin_once`` does
not), falling back to the SingleThreadedExecutor if it is missing.
"""
from __future__ import annotations

import gc
import os
import sys
import time
from typing import Callable
import weakref

from builtin_interfaces.msg import Time
import rclpy
from rclpy.duration import Duration
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.impl.implementation_singleton import rclpy_implementation
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions
from rclpy.utilities import remove_ros_args

from pentapod_sim import exits, interface, shutdown
from pentapod_sim.errors import ConfigError, RunError
from pentapod_sim.nodes.testbed_node import usage
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


#: Publishers whose acknowledgements a node already waited for (:func:`wait_for_acks`: the
#: plant's outputs and status, a composition's sources' outlets), which the end of the process
#: does not wait for again (:func:`wait_for_end_acks`).
_awaited: weakref.WeakSet = weakref.WeakSet()


def wait_for_acks(node, publishers, timeout: float, bound: str = '',
                  remember: bool = True) -> None:
    """
    Wait until every subscriber acknowledged every message of ``publishers`` (reliable QoS).

    Waits in slices of at most 0.1 s and ends early when a topic has no subscriber left (a
    subscriber that died), or after ``timeout`` [s] in all (a warning naming ``bound``, the
    limit that set it; ``ack_timeout`` by default). rclpy's ``Publisher.wait_for_all_acked``
    returns at once for a best-effort publisher and holds the GIL while it waits (hence the
    slices). ``remember``: leave ``publishers`` out of :func:`wait_for_end_acks` from now on.
    """
    publishers = list(publishers)
    if remember:
        _awaited.update(publishers)
    end = time.monotonic() + timeout
    for pub in publishers:
        while pub.get_subscription_count():
            left = end - time.monotonic()
            if pub.wait_for_all_acked(Duration(seconds=min(0.1, max(left, 0.0)))):
                break
            if time.monotonic() >= end:
                node.get_logger().warning(
                    f'{pub.topic_name}: not every message acknowledged within '
                    + (bound or f'ack_timeout = {timeout:g} s'))
                return


#: Wall time [s] a process waits in all, at its end (finished, failed or stopped by a signal),
#: for its nodes' messages to be acknowledged by their reliable subscribers
#: (:func:`wait_for_end_acks`). A writer that goes takes with it what a subscriber has not
#: taken from its socket yet (the subscriber drops the data of a writer it saw leave) and what
#: it must still repair: a recorder draining a loaded run's last steps missed a separate
#: source's last 2-3 answers. Repairs and acknowledgements wait for the writer's next
#: heartbeat. The package's local profile (config/dds/loopback.xml) sends one every 0.1 s, so
#: with a running subscriber the wait takes less than 0.1 s (0.007-0.098 s measured; a source
#: process exited 0.17-0.32 s after the group's SIGINT instead of 0.25-2.75 s:
#: docs/recording.md, "Order of stopping"). The bound is for any other profile (a network),
#: with Fast DDS's default period of 3 s: a running subscriber then acknowledged a writer's
#: last message 1.9-3.0 s after it was sent in a run (0.6-1.7 s after bursts of 0.5-1.5 s),
#: and with a bound of 1 s the recorder frozen for 0.45 s around the stop in test_stopping.py
#: still missed 32-60 steps of each source (4 of 4 runs). So: that period and 0.5 s, for a
#: subscriber that runs again within about 0.5 s of the stop; less than the 5 s the scenario
#: runner grants a node to end after its SIGINT (:func:`pentapod_sim.scenario.runner.stop`).
#: A subscriber that is gone ends the wait (no subscriber left); one that hangs holds it this
#: long at most.
END_ACK_WAIT = 3.5


def wait_for_end_acks(node) -> None:
    """
    Wait up to :data:`END_ACK_WAIT` s for the acknowledgement of every publisher of ``node``.

    For a composition (a ``nodes`` attribute), of each of its nodes. Publishers already waited
    for by :func:`wait_for_acks` (the plant's, with its own ``ack_timeout``) are left out;
    nothing is waited for once the node's context is shut down.
    """
    start = time.monotonic()
    end = start + END_ACK_WAIT
    for each in getattr(node, 'nodes', [node]):
        if not each.context.ok():
            continue
        pubs = [pub for pub in each.publishers if pub not in _awaited]
        wait_for_acks(each, pubs, max(0.0, end - time.monotonic()),
                      f'END_ACK_WAIT = {END_ACK_WAIT:g} s', remember=False)
        each.get_logger().debug(
            f'end wait for acknowledgements: {time.monotonic() - start:.3f} s')


def wants_help(args) -> bool:
    """True if the non-ROS arguments ask for help (``-h``, ``--help``)."""
    return any(a in ('-h', '--help') for a in remove_ros_args(list(args))[1:])


def run_node(factory: Callable[..., object], argv=None, run: Callable | None = None, *,
             executor: Callable = make_executor) -> int:
    """
    Jazzy-style main: init, build the node, spin or ``run(node, executor)``, clean shutdown.

    For a node class ``factory``, ``--help`` prints its usage and parameters and starts
    nothing. Returns 0 on a clean end,
    1 after printing one ``error: ...`` line on a ConfigError/RunError (a RunError subclass
    gives its own ``exit_code``: 3 a failed recording, 4 a stalled plant;
    :mod:`pentapod_sim.exits`), and 128 + the signal
    number after a clean stop on SIGINT, SIGTERM or SIGHUP (:mod:`pentapod_sim.shutdown`),
    unless the node's ``stopped_after_run_end()`` says (and logs) that the plant's run had
    ended before the signal: a source stopped after the run it served is a clean end, 0
    (:class:`pentapod_sim.nodes.run_status.PlantRunWatch`). A process stopped while work it
    gave up on still runs (a truncation check's LAPACK) exits with that code here instead of
    returning (:func:`pentapod_sim.shutdown.finish`). However it ends, the nodes' messages
    are acknowledged by their subscribers before the nodes are destroyed, for at most
    :data:`END_ACK_WAIT` s (:func:`wait_for_end_acks`).
    """
    args = list(sys.argv if argv is None else argv)
    try:
        if isinstance(factory, type) and wants_help(args):
            print(usage(factory))
            return 0
    except RCLError as err:            # e.g. a parameter file rcl cannot parse
        print(f'error: {str(err).splitlines()[0]}', file=sys.stderr)
        return 1
    try:                    # DDS on the loopback unless opened (docs/nodes.md, "Isolation")
        network.prepare_process()
    except (ConfigError, RunError) as err:
        print(f'error: {err}', file=sys.stderr)
        return 1
    # SIGINT/SIGTERM/SIGHUP only request a stop (pentapod_sim.shutdown); rclpy's own handlers
    # would invalidate the context at once, so a node could neither finish its step nor
    # publish, write its files or wait for acknowledgements.
    shutdown.install()
    shutdown.follow_ros2_run()          # SIGTERM to `ros2 run` reaches the node too
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    node = None
    code = 0
    served = False           # stopped after the plant's run it served had ended
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
                if getattr(node, 'failure', None) is not None:     # TestbedNode.fail
                    raise node.failure
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except (ConfigError, RunError, ValueError, KeyError) as err:
        print(f'error: {err}', file=sys.stderr)
        code = getattr(err, 'exit_code', exits.ERROR)     # pentapod_sim.exits
    finally:
        if node is not None:
            after_end = getattr(node, 'stopped_after_run_end', None)
            served = code == 0 and shutdown.requested() and callable(after_end) and after_end()
            wait_for_end_acks(node)     # a subscriber still draining gets the last messages
            node.destroy_node()
        rclpy.try_shutdown()
        shutdown.ignore_from_now()      # stopped: a late second signal must not kill it
    if served:
        return shutdown.finish(0)
    if code == 0 and shutdown.requested():
        print(f'stopped by {shutdown.signal_name()}', file=sys.stderr)
        code = shutdown.exit_code()
    return shutdown.finish(code)     # or exits now, if work given up on the stop still runs
