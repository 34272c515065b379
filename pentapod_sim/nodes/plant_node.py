"""
Plant node: integrates the modal plant and exchanges outputs and forces over ROS 2.

Every step k it publishes /clock and the state topics (y_k, stamp t_k), then applies the
forces of its sources (/pentapod/forces/<source>) as u_k and steps x_{k+1} = A_d x_k + B_d u_k
(``substeps`` exact ZOH substeps: :mod:`pentapod_sim.sim.multirate`). The node is the ROS
adapter; the parts each have their module:

* when to stop waiting for answers is the timing (parameter ``timing``):
  :class:`~pentapod_sim.sim.timing.Lockstep` or :class:`~pentapod_sim.sim.realtime.RealTime`,
  ROS-free, run over :class:`~pentapod_sim.nodes.plant_exchange.PlantExchange`;
* the per-step publishers: :mod:`.plant_outputs` (with :mod:`.fullrate`); the force
  subscriptions and graph checks: :mod:`.force_inputs`; polling for answers in separate
  processes: :mod:`.answer_poll`; the in-process hand-off of a composed run: :mod:`.local_bus`;
* the truncation check before step 0: :mod:`.loop_check`; the run status every
  ``status_period`` s: :mod:`.run_status`.

See docs/nodes.md and docs/interface.md.
"""
from __future__ import annotations

import time

from pentapod_sim import interface, shutdown
from pentapod_sim.errors import ConfigError, PortError, RunError
from pentapod_sim.nodes.answer_poll import AnswerPoller
from pentapod_sim.nodes.common import (
    run_node,
    wait_for_acks,
)
from pentapod_sim.nodes.force_inputs import ForceInputs
from pentapod_sim.nodes.local_bus import Drain, LocalBus, Outlet
from pentapod_sim.nodes.loop_check import ModelCollector, TruncationCheck
from pentapod_sim.nodes.parameter_tables import PlantParams
from pentapod_sim.nodes.plant_exchange import PlantExchange
from pentapod_sim.nodes.plant_outputs import PlantOutputs
from pentapod_sim.nodes.run_status import RunStatusPublisher
from pentapod_sim.nodes.testbed_node import TestbedNode
from pentapod_sim.nodes.writers import WriterCheck
from pentapod_sim.plant.build import load_or_build_model
from pentapod_sim.plant.drives import drive_set, DriveSet, with_drives
from pentapod_sim.sim.multirate import MultiRatePlant
from pentapod_sim.sim.periodic_state import load_initial_state
from pentapod_sim.sim.realtime import RealTime
from pentapod_sim.sim.stepping import ForceMixer, parse_sources
from pentapod_sim.sim.timing import Lockstep, Timing, Waits
from pentapod_sim.sim.trace import Trace


class PlantNode(TestbedNode):
    """Discrete modal plant as a ROS 2 node (parameters: docs/parameters.md)."""

    Params = PlantParams

    def __init__(self, **kwargs):
        super().__init__('plant', **kwargs)
        p = self.params
        ports = p.source_ports
        self.model, origin = load_or_build_model(p.model_file, p.position, p.model_cache_dir)
        self.drives = self._drives()
        self.core = MultiRatePlant.from_model(
            with_drives(self.model, self.drives), p.sample_rate, p.substeps, p.max_state_norm)
        self.get_logger().info(
            f'plant model {origin}: {self.model.n_modes} modes, {len(self.core.input_names)} '
            f'inputs, {len(self.core.output_names)} outputs, dt = {self.core.dt:.6g} s, '
            f'{self.core.substeps} substep(s)'
            + ('' if self.drives is None else f", feed drives' rotors of "
               f'{self.drives.describe()}'))
        self.initial_state = 'rest'
        if p.initial_state_file:
            self.core.reset(*load_initial_state(p.initial_state_file, self.core.n_states,
                                                len(self.core.input_names)))
            self.initial_state = f'file {p.initial_state_file}'
            self.get_logger().info(f'starting from the state in {p.initial_state_file}, not '
                                   'from rest')
        self.mixer = ForceMixer(self.core.input_names, parse_sources(p.sources, ports),
                                max_effort=p.max_effort)
        self.n_steps = self._n_steps()
        lockstep = p.timing == 'lockstep'
        self.outputs = PlantOutputs(self, self.core, self.mixer, p.display_batch_period)
        # one writer per topic (pentapod_sim.nodes.writers): the force topics it reads, and
        # the per-step outputs and run status it writes itself (a second writer there would
        # feed the sources and the recorder a state that is not the plant's)
        self.writers = WriterCheck(self)
        self.inputs = ForceInputs(self, self.core, self.mixer, exact=lockstep,
                                  shared_ok=p.shared_source_topics, writers=self.writers)
        self.poller = AnswerPoller(self, self.inputs, p.answer_poll_time if lockstep else 0.0)
        self.status = RunStatusPublisher(self, self.core.dt, p.status_period,
                                         lambda: self.announce(interface.RUN_RUNNING, True),
                                         self.initial_state, 'none' if self.drives is None
                                         else self.drives.describe())
        for topic in self.outputs.topics() + [interface.RUN_STATUS]:
            self.writers.watch(topic)
        self.loop_check = TruncationCheck(
            ModelCollector(self, self.mixer.sources, lambda: self.core.k), self.model,
            self.core.dt, p.loop_check, p.sample_rate, p.loop_check_f_min, p.model_cache_dir,
            self.get_logger(), self.drives)
        waits = Waits(p.startup_timeout, p.source_timeout, p.resend_period)
        self.timing: Timing = (
            Lockstep(self.core, self.mixer, self.n_steps, waits) if lockstep else
            RealTime(self.core, self.mixer, self.n_steps, waits, report_period=p.report_period,
                     lost_policy=p.lost_source_policy, log=self.get_logger()))
        self.bus_drain: Drain | None = None   # a composed plant's (join_bus)

    def _drives(self) -> DriveSet | None:
        """The feed drives of parameter ``drives`` (ConfigError naming the bad value)."""
        p = self.params
        try:
            drives = drive_set(p.drives, p.drive_struts)
            if drives is not None:
                drives.on(self.model)   # the model has the drive ports
        except (ConfigError, PortError) as err:
            why = err.args[0] if isinstance(err, PortError) else err
            raise ConfigError(f"parameter 'drives' = {p.drives!r} (drive_struts "
                              f'{list(p.drive_struts)}): {why}') from None
        return drives

    def _n_steps(self) -> int:
        """Steps of the run from ``steps`` or ``duration``."""
        if self.params.steps > 0:
            return int(self.params.steps)
        n = int(round(self.params.duration / self.core.dt))
        if n <= 0:
            raise ConfigError(f"parameters 'steps' = 0 and 'duration' = {self.params.duration} "
                              's give no step')
        return n

    # -- composition (pentapod_sim.nodes.local_bus) ----------------------------------------
    def own_sources(self, names: list[str]) -> list[str]:
        """Those of ``names`` that are sources of this plant."""
        return [n for n in names if n in self.mixer.sources]

    def join_bus(self, bus: LocalBus, sources: list[str], source_outlets=()) -> None:
        """
        Take the in-process ``sources``' answers from ``bus``, hand the outputs to it.

        ``source_outlets``: those sources' outlets, whose subscribers outside the process the
        plant waits for before step 0 and after the run, as for its own outputs.
        """
        self.inputs.take_from(bus, sources)
        self.outputs.attach(bus, source_outlets)
        self.bus_drain = Drain(self)
        self.poller.in_composition()

    def outlets(self) -> list[Outlet]:
        """The per-step outlets (/clock, the state topics) a composition hands over."""
        return self.outputs.outlets()

    def flush_bus(self, executor, limit: float) -> None:
        """A composed plant: run the in-process deliveries still queued, at most ``limit`` s."""
        if self.bus_drain is not None and self.context.ok():
            self.bus_drain.flush(executor, limit)

    # -- communication ---------------------------------------------------------------------
    def refresh(self) -> None:
        """Look at the subscribers: which outputs to publish, whether polling pays."""
        self.outputs.refresh()
        self.poller.refresh(self.outputs.topics(), self.inputs.topics(), self.core.k)

    def announce(self, state: str, periodic: bool = False) -> None:
        """Publish the run status (docs/recording.md): state, steps run, per-step topics."""
        if not self.context.ok():
            return    # after a signal nothing can be published any more
        if state == interface.RUN_RUNNING and not periodic:
            self.refresh()
        self.status.publish(state, self.core.k,
                            self.outputs.active_topics() + self.inputs.topics(),
                            self.timing.deadline_misses(), sum(self.mixer.rejected.values()),
                            ','.join(f'{source}/{reason}={count}' for (source, reason), count
                                     in sorted(self.mixer.rejected.items())))

    def wait_for_acks(self) -> None:
        """Wait until every subscriber acknowledged every output and status (``ack_timeout``)."""
        wait_for_acks(self, self.outputs.acknowledged_publishers() + self.status.publishers(),
                      self.params.ack_timeout)

    # -- the run ---------------------------------------------------------------------------
    def start_up(self, executor) -> None:
        """Wait for the sources, check the loop, wait for ``wait_for_subscribers``."""
        p = self.params
        self.inputs.wait_for_publishers(executor, p.startup_timeout)
        self.poller.prepare()
        self.loop_check.at_start(executor)
        self.outputs.wait_for_subscribers(executor, p.wait_for_subscribers, p.startup_timeout,
                                          p.subscriber_settle)

    def run(self, executor) -> None:
        """
        Start up, run the configured number of steps, log a summary.

        However the run ends (finished, stopped by a signal, an error), the steps run are
        acknowledged, summarised and written to ``output_file``.
        """
        p, log = self.params, self.get_logger()
        trace = Trace(self.n_steps, self.core, bool(p.output_file))
        self.start_up(executor)
        if isinstance(self.timing, RealTime):     # pages written before the run is announced
            self.timing.prepare(trace.buffers())
        polling = self.inputs.on_dds() and p.timing == 'lockstep'
        if not shutdown.requested():     # else stopped during start-up: no run to announce
            self.announce(interface.RUN_RUNNING)
            log.info(f'{p.timing} run of {self.n_steps} steps with sources '
                     f'{list(self.mixer.sources) or "none"}'
                     + (f'; {self.poller.describe()}' if polling else ''))
        self.poller.start(log_changes=polling)
        figures: dict = {}
        end = 'finished'
        wall = time.monotonic()
        self.status.start(self.core.k)
        try:
            self.timing.run(PlantExchange(self.outputs, self.inputs, self.poller,
                                          self.bus_drain, executor, trace, self.refresh,
                                          self.loop_check.during_run))
            figures = self.timing.figures()
            if (line := self.timing.summary()) is not None:
                log.info(line)
        except RunError as err:
            end = f'error: {err}'
            raise
        finally:
            wall = time.monotonic() - wall
            self.status.stop()
            self.outputs.flush()
            if shutdown.requested():
                end = f'stopped by {shutdown.signal_name()}'
            self.announce(interface.RUN_FINISHED if self.core.k == self.n_steps
                          else interface.RUN_STOPPED)
            self.wait_for_acks()
            polled = self.poller.polled_steps()
            log.info(f'{end}: ran {self.core.k} of {self.n_steps} steps in {wall:.3f} s wall '
                     f'({self.core.k / max(wall, 1e-9):.0f} steps/s); '
                     + (f'answers of {polled} steps polled; ' if polled else '')
                     + self.mixer.reject_summary())
            if p.timing == 'lockstep':      # however the run ended
                figures['answers_polled'] = polled
            if p.output_file:
                trace.save(p.output_file, self.core, self.mixer, self.n_steps,
                           dict(figures, wall_time=wall, end=end))


def run(node: PlantNode, executor) -> None:
    """The plant's run on ``executor`` (:meth:`PlantNode.run`; run_node's ``run``)."""
    node.run(executor)


def main(argv=None) -> int:
    """Entry point of ``ros2 run pentapod_testbed plant``."""
    return run_node(PlantNode, argv, run)


if __name__ == '__main__':
    raise SystemExit(main())
