"""
Plant node: integrates the modal plant and exchanges outputs and forces over ROS 2.

Every step k it publishes /clock and the state topics (y_k, stamp t_k), then applies the
forces of its sources (/pentapod/forces/<source>) as u_k and steps x_{k+1} = A_d x_k + B_d u_k
(``substeps`` exact ZOH substeps: :mod:`pentapod_sim.sim.multirate`, :mod:`.fullrate`). Timing
``lockstep`` waits for every source's answer to step k (deterministic; a silent source stops the
run naming it); ``realtime`` paces steps by the wall clock, holds the newest force of each
source and reports the achieved rate, lateness percentiles and overruns. Before step 0 it
checks the sampled loop with its sources' linear models (``loop_check``,
:mod:`pentapod_sim.nodes.loop_check`); during the run it publishes its run status every
``status_period`` s (:mod:`.run_status`). See docs/nodes.md.
"""
from __future__ import annotations

import array
import time

import numpy as np
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState

from pentapod_sim import interface, shutdown
from pentapod_sim.errors import ConfigError, RunError
from pentapod_sim.interface import CLOCK, force_topic, stamp_ns, state_layouts, step_of
from pentapod_sim.nodes import loop_check
from pentapod_sim.nodes.answer_poll import AnswerPoller
from pentapod_sim.nodes.common import (
    FORCE_SUB_QOS,
    GRAPH_CHECK_PERIOD,
    run_node,
    set_stamp,
    shared_topic_error,
    spin_until,
    stamp_to_ns,
    STATE_QOS,
    subscribers_of,
    wait_for_acks,
)
from pentapod_sim.nodes.fullrate import FullRateOutputs
from pentapod_sim.nodes.local_bus import Outlet
from pentapod_sim.nodes.parameter_tables import PlantParams
from pentapod_sim.nodes.realtime_loop import run_realtime
from pentapod_sim.nodes.run_status import RunStatusPublisher
from pentapod_sim.nodes.testbed_node import TestbedNode
from pentapod_sim.plant.build import load_or_build_model
from pentapod_sim.sim.multirate import MultiRatePlant
from pentapod_sim.sim.stepping import ForceMixer, parse_sources
from pentapod_sim.sim.trace import Trace


class PlantNode(TestbedNode):
    """Discrete modal plant as a ROS 2 node (parameters: docs/parameters.md)."""

    Params = PlantParams

    def __init__(self, **kwargs):
        super().__init__('plant', **kwargs)
        ports = self.params.source_ports
        model, origin = load_or_build_model(self.params.model_file, self.params.position,
                                            self.params.model_cache_dir)
        self.model = model
        self.core = MultiRatePlant.from_model(model, self.params.sample_rate,
                                              self.params.substeps, self.params.max_state_norm)
        self.dt = self.core.dt
        self.get_logger().info(f'plant model {origin}: {model.n_modes} modes, '
                               f'{len(model.input_names)} inputs, {len(model.output_names)} '
                               f'outputs, dt = {self.dt:.6g} s, {self.core.substeps} substep(s)')
        self.mixer = ForceMixer(self.core.input_names, parse_sources(self.params.sources, ports),
                                max_effort=self.params.max_effort)
        self.lost: set[str] = set()       # sources whose publisher left the graph
        self._shared_seen: dict[str, float] = {}   # force topic -> first seen shared [s]
        self.misses: dict[str, int] = dict.fromkeys(self.mixer.sources, 0)
        self.n_steps = self._n_steps()
        self.clock_pub = self.create_publisher(Clock, CLOCK, STATE_QOS)
        self.layouts = state_layouts(self.core.output_names)
        self.state_pubs = [(self.create_publisher(JointState, lay.topic, STATE_QOS), lay)
                           for lay in self.layouts]
        # in a composition in-process sources get their messages directly (.local_bus)
        self.clock_out = Outlet(self.clock_pub)
        self.state_outs = [(Outlet(pub), lay) for pub, lay in self.state_pubs]
        # one message per topic, refilled every step: building a JointState costs several us
        # (rosidl's checks of every joint name), refilling its arrays and stamp about 1 us;
        # publishing serialises it and in-process callbacks must not keep it (.local_bus)
        self._clock_msg = Clock()
        self._state_msgs = {lay.topic: JointState(name=lay.joints) for lay in self.layouts}
        self.drain = None                 # local_bus.Drain of a composed plant
        self.fullrate = FullRateOutputs(self, self.core)
        self.force_subs = {name: self.create_subscription(
            JointState, force_topic(name),
            lambda msg, name=name: self._on_force(name, msg), FORCE_SUB_QOS)
            for name in self.mixer.sources}
        self.status = RunStatusPublisher(self, self.params.status_period)
        self.poller = AnswerPoller(self, self.params.answer_poll_time
                                   if self.params.timing == 'lockstep' else 0.0)
        self.loop_models = loop_check.ModelCollector(self, self.mixer.sources)
        self._last_warn = {}
        self._next_refresh = 0.0

    def _n_steps(self) -> int:
        """Steps of the run from ``steps`` or ``duration``."""
        if self.params.steps > 0:
            return int(self.params.steps)
        n = int(round(self.params.duration / self.dt))
        if n <= 0:
            raise ConfigError(f"parameters 'steps' = 0 and 'duration' = {self.params.duration} "
                              's give no step')
        return n

    # -- communication ---------------------------------------------------------------------
    def outlets(self) -> list[Outlet]:
        """The per-step outputs with in-process hand-off (/clock, the state topics)."""
        return [self.clock_out] + [out for out, _ in self.state_outs]

    def refresh_subscribers(self) -> None:
        """Note which output topics have subscribers (publishing costs ~80 us each here)."""
        self._active = [(out, lay) for out, lay in self.state_outs if out.refresh()]
        self._clock_active = self.clock_out.refresh()
        self.fullrate.refresh()
        self.poller.refresh(self.output_topics(), [force_topic(s) for s in self.mixer.sources])
        self._next_refresh = time.monotonic() + 0.25

    def publish_outputs(self, y: np.ndarray) -> None:
        """Publish /clock and the state topics of step k (topics with subscribers only)."""
        if time.monotonic() > self._next_refresh:
            self.refresh_subscribers()
        ns = stamp_ns(self.core.k, self.dt)
        if self._clock_active:
            set_stamp(self._clock_msg.clock, ns)
            self.clock_out.publish(self._clock_msg)
        for out, lay in self._active:
            pos, vel = lay.values(y)
            msg = self._state_msgs[lay.topic]
            msg.position = array.array('d', pos.tobytes())
            msg.velocity = array.array('d', vel.tobytes())
            set_stamp(msg.header.stamp, ns)
            out.publish(msg)

    def _on_force(self, source: str, msg: JointState) -> None:
        """Validate a force message; warn (throttled) and count rejects."""
        step = step_of(stamp_to_ns(msg.header.stamp), self.dt)
        reason = self.mixer.submit(source, msg.name, msg.effort, step, self.core.k,
                                   exact=self.params.timing == 'lockstep')
        if reason is not None:
            kind = reason.split(':')[0]
            if reason.startswith(('stale', 'duplicate:')):
                return  # repeated answers to re-published steps, or late ones, are expected
            now = time.monotonic()
            if now - self._last_warn.get((source, kind), -1e9) > 1.0:
                self._last_warn[(source, kind)] = now
                self.get_logger().warning(f'rejected message from source {source!r}: {reason} '
                                          f'({self.mixer.rejected[(source, kind)]} so far)')

    def announce(self, state: str, periodic: bool = False) -> None:
        """Publish the run status (docs/recording.md): state, steps run, per-step topics."""
        if not self.context.ok():
            return    # after a signal nothing can be published any more
        if state == interface.RUN_RUNNING and not periodic:
            self.refresh_subscribers()
        topics = ([self.clock_pub.topic_name] if self._clock_active else []) + [
            pub.topic_name for pub, _ in self._active] + self.fullrate.active_topics() + [
            force_topic(s) for s in self.mixer.sources]
        self.status.publish(state, topics)

    # -- runs ------------------------------------------------------------------------------
    def wait_for_sources(self, executor) -> None:
        """Wait until every source topic has a publisher (RunError names the missing)."""
        def missing():
            return [s for s in self.mixer.sources
                    if self.count_publishers(force_topic(s)) == 0]
        if not spin_until(executor, lambda: not missing() or shutdown.requested(),
                          self.params.startup_timeout):
            raise RunError(f'force source(s) {", ".join(missing())} did not appear within '
                           f'startup_timeout = {self.params.startup_timeout} s')
        self.check_sources()
        self.poller.prepare()

    def check_sources(self) -> list[str]:
        """
        Refuse shared force topics; return the sources whose publisher left the graph.

        Raises
        ------
        RunError
            If a force topic has more than one publisher and ``shared_source_topics`` is
            false; the message names the topic and every publishing node
            (:func:`~pentapod_sim.nodes.common.shared_topic_error`).
        """
        gone = []
        for name in self.mixer.sources:
            infos = self.get_publishers_info_by_topic(force_topic(name))
            if len(infos) > 1 and not self.params.shared_source_topics:
                if error := shared_topic_error(force_topic(name), infos, self._shared_seen):
                    raise RunError(error)
            if not infos:
                gone.append(name)
        return gone

    def output_topics(self) -> list[str]:
        """Topics the plant publishes every step: /clock, the state topics, the full-rate one."""
        return [self.clock_pub.topic_name] + [pub.topic_name for pub, _ in self.state_pubs] + (
            [self.fullrate.pub.topic_name] if self.fullrate.pub is not None else [])

    def wait_for_subscribers(self, executor) -> None:
        """
        Wait until each node of ``wait_for_subscribers`` subscribes to an output topic.

        Then spin ``subscriber_settle`` seconds more, so that the node's other subscriptions
        (to this plant and to the sources) are matched too: a recorder started with the run
        thus receives step 0. RunError names a node that did not appear. A stop signal ends
        the wait at once.
        """
        wanted = self.params.wait_for_subscribers

        pubs = [self.clock_pub] + [pub for pub, _ in self.state_pubs] + self.fullrate.publishers

        def missing():
            seen, unmatched = set(), []
            for pub in pubs:
                names, matched = subscribers_of(self, pub)
                seen |= names
                if not matched:
                    unmatched.append(pub.topic_name)
            return [n for n in wanted if n not in seen] + [f'match on {t}' for t in unmatched]
        if not wanted:
            return
        self.get_logger().info(f'waiting for subscriber node(s) {", ".join(wanted)} '
                               f'(startup_timeout = {self.params.startup_timeout} s)')
        if not spin_until(executor, lambda: not missing() or shutdown.requested(),
                          self.params.startup_timeout):
            raise RunError(f'subscriber node(s) {", ".join(missing())} did not appear within '
                           f'startup_timeout = {self.params.startup_timeout} s')
        spin_until(executor, shutdown.requested, self.params.subscriber_settle)
        self.refresh_subscribers()

    def wait_for_acks(self) -> None:
        """Wait until every subscriber acknowledged every output (``ack_timeout``)."""
        wait_for_acks(self, [self.clock_pub, *(p for p, _ in self.state_pubs),
                             *self.fullrate.publishers], self.params.ack_timeout)

    def run_lockstep(self, executor, trace, n_steps: int | None = None) -> None:
        """
        Each step: publish y_k, wait for every source's u_k, advance.

        The graph is checked every ``GRAPH_CHECK_PERIOD`` seconds of wall time as well: a
        second publisher on a force topic discovered after the start still ends the run.
        """
        core, mixer = self.core, self.mixer
        resend, timeout = self.params.resend_period, self.params.source_timeout
        next_check = time.monotonic() + GRAPH_CHECK_PERIOD
        for k in range(self.n_steps if n_steps is None else n_steps):
            if shutdown.requested():
                return
            y = core.outputs()
            self.publish_outputs(y)
            start = last_sent = time.monotonic()
            if start > next_check:
                self.check_sources()
                next_check = start + GRAPH_CHECK_PERIOD
            limit = self.params.startup_timeout if k == 0 else timeout
            if k > 0 and self.poller.active:
                self.poller.poll(k)
            while mixer.missing(k):
                executor.spin_once(timeout_sec=resend / 4)
                if shutdown.requested():
                    return
                now = time.monotonic()
                if now - start > limit:
                    raise RunError(f'force source(s) {", ".join(mixer.missing(k))} silent '
                                   f'for {now - start:.3g} s at step {k} (t = '
                                   f'{core.time:.6g} s); source_timeout = {timeout} s')
                if now - last_sent > resend:
                    gone = [s for s in self.check_sources() if s in mixer.missing(k)]
                    if gone:
                        raise RunError(f'force source(s) {", ".join(gone)} left the ROS graph '
                                       f'(no publisher on {force_topic(gone[0])}) at step {k} '
                                       f'(t = {core.time:.6g} s)')
                    self.refresh_subscribers()
                    self.publish_outputs(y)
                    last_sent = now
            u = mixer.total()
            self.fullrate.record(k, y, u, trace)
            core.advance(u)
            if self.drain is not None:
                self.drain.tick(executor)
            elif self.poller.active:
                self.poller.tick(executor)


def run(node: PlantNode, executor) -> None:
    """
    Wait for the sources, run the configured number of steps, log a summary.

    However the run ends (finished, stopped by a signal, an error), the steps run are
    acknowledged, summarised and written to ``output_file``.
    """
    trace = Trace(node.n_steps, node.core, bool(node.params.output_file))
    node.wait_for_sources(executor)
    loop_check.check_at_start(node, executor)
    node.wait_for_subscribers(executor)
    polling = bool(node.force_subs) and node.params.timing == 'lockstep'
    if not shutdown.requested():     # else stopped during start-up: no run to announce
        node.announce(interface.RUN_RUNNING)
        node.get_logger().info(f'{node.params.timing} run of {node.n_steps} steps with '
                               f'sources {list(node.mixer.sources) or "none"}' + (
                                   f'; {node.poller.describe()}' if polling else ''))
    node.poller.running = polling
    extra = {}
    end = 'finished'
    wall = time.monotonic()
    node.status.start()
    try:
        if node.params.timing == 'lockstep':
            node.run_lockstep(executor, trace)
        else:
            stats = run_realtime(node, executor, trace)
            node.get_logger().info('realtime final: ' + stats.summary(node.core.k,
                                                                       stats.elapsed))
            extra = dict(stats.as_dict(node.core.k), misses_per_source=str(node.misses),
                         missed_per_step=stats.misses[:node.core.k],
                         lateness_per_step=stats.lateness[:node.core.k])
    except RunError as err:
        end = f'error: {err}'
        raise
    finally:
        wall = time.monotonic() - wall
        node.status.stop()
        node.fullrate.flush()
        if shutdown.requested():
            end = f'stopped by {shutdown.signal_name()}'
        node.announce(interface.RUN_FINISHED if node.core.k == node.n_steps
                      else interface.RUN_STOPPED)
        node.wait_for_acks()
        polled = (f'answers of {node.poller.polled} steps polled; ' if node.poller.polled
                  else '')
        node.get_logger().info(f'{end}: ran {node.core.k} of {node.n_steps} steps in '
                               f'{wall:.3f} s wall ({node.core.k / max(wall, 1e-9):.0f} '
                               f'steps/s); ' + polled + node.mixer.reject_summary())
        if node.params.timing == 'lockstep':      # however the run ended
            extra['answers_polled'] = node.poller.polled
        if node.params.output_file:
            trace.save(node.params.output_file, node.core, node.mixer, node.n_steps,
                       dict(extra, wall_time=wall, end=end))


def main(argv=None) -> int:
    """Entry point of ``ros2 run pentapod_testbed plant``."""
    return run_node(PlantNode, argv, run)


if __name__ == '__main__':
    raise SystemExit(main())
