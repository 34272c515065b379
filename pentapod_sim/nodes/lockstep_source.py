"""
Base class of force-source nodes that answer every plant step (lockstep contract).

A source subscribes to the state topics that carry its sensor ports (or to /clock if it has
none), waits until it holds every needed message of one stamp t_k, computes u_k with
:meth:`LockstepSource.compute` and publishes it on /pentapod/forces/<source_name> with the
same stamp. It publishes the linear model of its law once on
/pentapod/controller_models/<source_name> for the plant's truncation check
(:meth:`LockstepSource.linear_model`, :mod:`pentapod_sim.nodes.source_model`). A re-published
step (same stamp, same state again) gets the cached answer, so stateful laws advance exactly
once per step; a message of the answered stamp with another state is refused ('conflict'): the
cached answer belongs to the state it was computed from. Messages with NaN/Inf or a missing
joint are rejected, counted and warned about.

The state topics it reads have one writer, the plant (:mod:`pentapod_sim.nodes.writers`): a
message is taken only while its subscription has one matched publisher, and the graph's
publishers are checked at the first message and every ``CHECK_PERIOD`` s; a second writer stops
the source (exit code 1) naming both by DDS participant and host. No message from the plant for
``plant_stall_timeout`` s of wall time during its run (counted from its run announcement once
its writer is matched, if no step came yet) stops the source with exit code 4, naming the
plant (:class:`pentapod_sim.errors.PlantStalledError`). A parameter set during the run is
logged with old and new value and the step from which it acts, and published stamped with that
step on /pentapod/parameter_changes/<source_name>
(:data:`pentapod_sim.interface.PARAMETER_CHANGE_PREFIX`) for the recorder; a law publishes its
new linear model. In a composed
run the plant's messages and the answers pass in-process (:meth:`LockstepSource.use_bus`,
:mod:`pentapod_sim.nodes.local_bus`). Stopped after the plant's run ended, a source says so and
exits 0 (:class:`pentapod_sim.nodes.run_status.PlantRunWatch`).
"""
from __future__ import annotations

import array
import math
import time
from typing import Sequence

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
import numpy as np
from rclpy.clock import Clock as RosClock
from rclpy.clock import ClockType
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import String

from pentapod_sim import shutdown
from pentapod_sim.errors import ConfigError, PlantStalledError, RunError
from pentapod_sim.interface import (
    CLOCK,
    force_topic,
    PARAMETER_CHANGE_PREFIX,
    port_location,
    stamp_ns,
    step_of,
)
from pentapod_sim.nodes.common import (
    FORCE_QOS,
    INFO_QOS,
    qos,
    set_stamp,
    stamp_to_ns,
    STATE_SUB_QOS,
    subscribers_of,
)
from pentapod_sim.nodes.local_bus import LocalBus, Outlet
from pentapod_sim.nodes.run_status import PlantRunWatch
from pentapod_sim.nodes.source_model import model_text, publish_model
from pentapod_sim.nodes.testbed_node import TestbedNode
from pentapod_sim.nodes.writers import Writer, WriterCheck, writers_text

#: Wall time [s] between two looks of a source at the time since the plant's last message.
STALL_CHECK_PERIOD = 0.25


class LockstepSource(TestbedNode):
    """
    A node that answers each plant step with forces on some input ports.

    Subclasses set ``Params`` (a subclass of
    :class:`pentapod_sim.parameters.SourceParams`), find the values in ``self.params``, call
    :meth:`setup` and implement :meth:`compute`.
    """

    def __init__(self, default_name: str, **kwargs):
        super().__init__(default_name, **kwargs)
        self.source_name = self.params.source_name or self.get_name()
        self.wait_for = self.params.wait_for_subscribers
        self.info_outs: list[Outlet] = []   # diagnostic publishers (info_outlet)
        self.rejected = {}
        self.answered = 0
        self._last_warn = 0.0
        self.plant_run = PlantRunWatch(self)
        self.writers = WriterCheck(self)
        self.last_heard: float | None = None     # wall time of the plant's last message
        self.create_timer(STALL_CHECK_PERIOD, self._check_stall,
                          clock=RosClock(clock_type=ClockType.STEADY_TIME))
        self.change_pub = None                   # parameter changes (created by setup)

    def param_defaults(self) -> dict:
        """``source_name`` defaults to the node's name."""
        return {'source_name': self.get_name()}

    def setup(self, sensor_ports: Sequence[str], actuator_ports: Sequence[str]) -> None:
        """Create the subscriptions for the sensors and the force publisher."""
        self.sensor_ports = list(sensor_ports)
        self.actuator_ports = list(actuator_ports)
        # topic -> list of (slot in the sensor vector, joint name, field)
        self.needs: dict[str, list[tuple[int, str, str]]] = {}
        for slot, port in enumerate(self.sensor_ports):
            topic, joint, field = port_location(port)
            self.needs.setdefault(topic, []).append((slot, joint, field))
        self._pending: dict[int, dict[str, object]] = {}
        # topic -> (joint names of the last message, [(slot, index in the message, field)])
        self._picks: dict[str, tuple[list, list]] = {}
        self._last = (-1, None)   # (stamp ns, published message)
        self._answered: dict = {}   # topic -> the state message the cached answer is for
        self.force_pub = self.create_publisher(JointState, force_topic(self.source_name),
                                               FORCE_QOS)
        self.force_out = Outlet(self.force_pub, always_remote=True)
        # building a message costs several us (rosidl's checks): the answer is built once and
        # refilled; publishing serialises it and in-process callbacks must not keep it
        self._answer = JointState(name=self.actuator_ports)
        self.subs = [self.create_subscription(
            Clock if t == CLOCK else JointState, t,
            lambda msg, t=t: self._on_dds_state(t, msg), STATE_SUB_QOS)
            for t in self.state_topics()]
        self._sub_of = dict(zip(self.state_topics(), self.subs))
        for t in self.state_topics():
            self.writers.watch(t)
        self.model_pub = publish_model(self, self.source_name, self.model_text())
        self.change_pub = self.create_publisher(
            DiagnosticArray, PARAMETER_CHANGE_PREFIX + self.source_name, qos('change'))

    def state_topics(self) -> list[str]:
        """The plant's topics this source answers: those of its sensors, else /clock."""
        return list(self.needs) or [CLOCK]

    def use_bus(self, bus: LocalBus) -> None:
        """
        Take the plant's messages from ``bus`` instead of DDS, answer through it too.

        A composed run's hand-off (:func:`pentapod_sim.nodes.local_bus.connect`): the state
        subscriptions go, the answers still go out on DDS while someone subscribes there.
        """
        for sub in self.subs:
            self.destroy_subscription(sub)
        self.subs = []
        self.writers.topics.clear()     # in-process: nothing foreign reaches the bus
        for topic in self.state_topics():
            bus.subscribe(topic, lambda msg, t=topic: self._on_state(t, msg))
        self.force_out.attach(bus)
        for out in self.info_outs:
            out.attach(bus)

    def info_outlet(self, msg_type, topic: str) -> Outlet:
        """
        A per-step diagnostic publisher (``INFO_QOS``) as an outlet.

        It publishes on DDS every time, or, once :meth:`use_bus` attached it to a composition's
        bus, hands its messages to the in-process callbacks (a recorder) and publishes on DDS
        only while another node subscribes. Its publisher counts for ``wait_for_subscribers``.
        """
        out = Outlet(self.create_publisher(msg_type, topic, INFO_QOS), always_remote=True)
        self.info_outs.append(out)
        return out

    def outlets(self) -> list[Outlet]:
        """The per-step outlets: the force answer, then the diagnostics."""
        return [self.force_out, *self.info_outs]

    def linear_model(self):
        """
        The law as a DiscreteController on its ports, for the plant's truncation check.

        Raises
        ------
        ConfigError
            Saying why the law has none (the plant then names the source as unchecked).
        """
        raise ConfigError(f'{type(self).__name__} offers no linear model')

    def model_text(self) -> str:
        """Text of the model message (``no feedback`` for a source without sensors)."""
        return model_text(self.linear_model, feedback=bool(self.sensor_ports))

    def publish_model(self) -> None:
        """Publish the current model again (e.g. after a gain changed)."""
        self.model_pub.publish(String(data=self.model_text()))

    def stopped_after_run_end(self) -> bool:
        """After a stop signal: True (logged) if the plant's run had ended before it came."""
        return self.plant_run.explains_stop()

    def compute(self, stamp_ns: int, sensors: np.ndarray) -> np.ndarray:
        """Return efforts for ``actuator_ports`` at this step (N or N m)."""
        raise NotImplementedError

    def reset(self) -> None:
        """Hook: back to the initial controller state (a new plant run started)."""

    def after_publish(self, stamp, efforts: np.ndarray) -> None:
        """Hook for extra publications (diagnostics) after a step was answered."""

    def _reject(self, reason: str) -> None:
        """Count and warn (at most once a second) about a bad state message."""
        kind = reason.split(':')[0]
        self.rejected[kind] = self.rejected.get(kind, 0) + 1
        now = time.monotonic()
        if now - self._last_warn > 1.0:
            self._last_warn = now
            self.get_logger().warning(f'rejected state message: {reason} '
                                      f'({self.rejected[kind]} so far)')

    def subscribers_ready(self) -> bool:
        """True once every ``wait_for_subscribers`` node is matched on every info topic."""
        for out in self.info_outs:
            names, matched = subscribers_of(self, out.pub)
            if not matched or any(n not in names for n in self.wait_for):
                return False
        return True

    def _on_state(self, topic: str, msg) -> None:
        """Collect the messages of one stamp; answer when all needed topics are in."""
        stamp = msg.clock if topic == CLOCK else msg.header.stamp
        ns = stamp_to_ns(stamp)
        self.last_heard = time.monotonic()
        if ns == self._last[0]:
            answered = self._answered.get(topic)
            if answered is None or answered == msg:
                self.force_out.publish(self._last[1])   # a re-published step: same answer
            else:       # not the state the answer was computed from: not the plant's step
                self._reject(f'conflict: a second, different message on {topic} for the '
                             f'answered stamp {ns} ns')
            return
        if ns < self._last[0]:
            # the plant only re-sends its current step, so time going back means a new run
            self.get_logger().info(f'stamp went back to {ns} ns: new plant run, resetting')
            self._last = (-1, None)
            self._pending.clear()
            self.reset()
        if self.answered == 0 and self.wait_for and not self.subscribers_ready():
            return   # not answering yet: the plant re-sends this step after resend_period
        if len(self.needs) > 1:              # wait for the step's message on every topic
            pending = self._pending.setdefault(ns, {})
            pending[topic] = msg
            if len(pending) < len(self.needs):
                return
            del self._pending[ns]
            for old in [s for s in self._pending if s < ns]:
                del self._pending[old]
        else:
            pending = {topic: msg}
        self._answered = pending if self.subs else {}    # bus messages are refilled objects
        sensors = np.empty(len(self.sensor_ports))
        for t, msg_t in pending.items():
            if t != CLOCK and not self._extract(t, msg_t, sensors):
                return
        efforts = np.asarray(self.compute(ns, sensors), dtype=float)
        out = self._answer                 # one message object, refilled every step
        out.effort = array.array('d', efforts.tobytes())
        set_stamp(out.header.stamp, ns)
        self.force_out.publish(out)
        self._last = (ns, out)
        self.answered += 1
        self.after_publish(out.header.stamp, efforts)

    def _on_dds_state(self, topic: str, msg) -> None:
        """A state message from DDS: taken only from the topic's one writer (RunError else)."""
        writers = self.writers
        try:
            if writers.due():
                writers.check()
            if writers.message_ok(topic, self._sub_of[topic]):
                self._on_state(topic, msg)
            elif writers.due():
                writers.check()
        except RunError as err:
            self.fail(err)

    def _check_stall(self) -> None:
        """PlantStalledError once the plant, during its run, was silent plant_stall_timeout s."""
        limit = self.params.plant_stall_timeout
        if self.last_heard is None and self.plant_run.running and self.subs and all(
                sub.get_publisher_count() for sub in self.subs):
            # the plant announced its run and DDS matched its writer, yet no step came (a
            # plant stopped right after its start): its silence counts from here
            self.last_heard = time.monotonic()
        if (limit <= 0 or self.last_heard is None or self.plant_run.ended is not None
                or self.failure is not None or time.monotonic() - self.last_heard <= limit):
            return
        shutdown.deliver()
        if shutdown.requested():      # frozen and continued with a stop signal: a clean stop
            return
        plant = writers_text(w for t in self.writers.topics
                             for w in map(Writer.of, self.get_publishers_info_by_topic(t)))
        self.fail(PlantStalledError(
            f'the plant stalled: no message from it for {limit:g} s of wall time during its run '
            f'(plant_stall_timeout; last answered stamp {self._last[0]} ns, -1: none); its '
            'writer: '
            f'{plant or "gone from the graph"}'))

    def on_params_changed(self, old, new, names: Sequence[str]) -> None:
        """Log each change with the step it acts from; publish it stamped; the new model."""
        ns = self._last[0]
        step = step_of(ns, self.params.dt) + 1 if ns >= 0 else 0
        when = f'from step {step} (t = {step * self.params.dt:.6g} s)'
        status = DiagnosticStatus(name=self.get_fully_qualified_name(), message='changed')
        for name in names:
            before, after = old.ros_values().get(name), new.ros_values().get(name)
            self.get_logger().warning(f'parameter {name} changed during the run: {before!r} -> '
                                      f'{after!r}, acting {when}')
            status.values += [KeyValue(key=f'{name}.old', value=repr(before)),
                              KeyValue(key=f'{name}.new', value=repr(after))]
        status.values.append(KeyValue(key='step', value=str(step)))
        if self.change_pub is not None:
            msg = DiagnosticArray(status=[status])
            set_stamp(msg.header.stamp, stamp_ns(step, self.params.dt))
            self.change_pub.publish(msg)
            self.publish_model()

    def _extract(self, topic: str, msg: JointState, sensors: np.ndarray) -> bool:
        """Fill this topic's sensor slots; reject the step if a joint or value is bad."""
        # per step the names are only compared with the last message's (a list comparison:
        # a few us less than hashing them, every step, for a per-step path that runs
        # cache-cold; docs/nodes.md "Where a lockstep step's time goes"); the plant's
        # in-process messages keep their name list, which the identity test passes at once
        names = msg.name
        known = self._picks.get(topic)
        if known is None or (known[0] is not names and known[0] != names):
            index = {n: i for i, n in enumerate(names)}
            missing = [j for _, j, _ in self.needs[topic] if j not in index]
            if missing:
                self._reject(f'missing_joint: {topic} lacks {missing}')
                return False
            known = (names, [(slot, index[j], field) for slot, j, field in self.needs[topic]])
            self._picks[topic] = known
        for slot, i, field in known[1]:
            values = (msg.velocity if field == 'velocity'
                      else msg.effort if field == 'effort' else msg.position)
            if i >= len(values):
                self._reject(f'length: {topic} has {len(values)} {field} values for '
                             f'{len(names)} names')
                return False
            value = values[i]
            if not math.isfinite(value):
                self._reject(f'nonfinite: {topic} at stamp {stamp_to_ns(msg.header.stamp)} ns')
                return False
            sensors[slot] = value
        return True
