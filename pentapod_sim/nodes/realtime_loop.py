"""
The plant's real-time run (``timing: realtime``): steps paced by the wall clock.

The lockstep contract is kept whenever an answer comes in time; a missed deadline holds the
source's last force and is counted (:class:`~pentapod_sim.nodes.realtime_stats.LatenessStats`).
Functions of a :class:`~pentapod_sim.nodes.plant_node.PlantNode`; docs/nodes.md.
"""
from __future__ import annotations

import time

from pentapod_sim import shutdown
from pentapod_sim.nodes.common import GRAPH_CHECK_PERIOD
from pentapod_sim.nodes.realtime_stats import fault_in, LatenessStats, POLL_AHEAD

#: A step that began late waits for its answers until this many periods after it began. A
#: plant that stalled (the machine took its CPU for a few ms) starts its next steps late and
#: catches up; with the period's end as the only deadline, every catch-up step counted as
#: missed by its sources, which had no time to answer, and ran on held forces (1 kHz
#: exchange, separate processes: about half the misses of a run, 13 in a row after an 11 ms
#: stall). A late step then gains about half a period on the clock. Only while the sources
#: answer most steps that began on time: where they cannot keep up anyway (5 kHz in separate
#: processes, a round trip longer than the period) the wait only kept the plant behind the
#: clock (4,929 of 5,000 steps/s, lateness p50 11 ms).
ANSWER_WINDOW = 0.5


def run_realtime(node, executor, trace) -> LatenessStats:
    """
    Wall-clock periods with the lockstep contract kept whenever an answer is in time.

    Period k starts at ``t0 + k dt``: the plant publishes y_k, then takes in answers until
    every source answered step k or the deadline passes: the period's end, or
    :data:`ANSWER_WINDOW` periods after the step began if that is later and the sources
    answered most of the last steps that began on time (a plant that fell behind the clock
    catches up without taking the sources' time to answer). In time, u_k
    answers y_k exactly as in lockstep, so a run without misses equals the lockstep run bit
    for bit. A source that missed the deadline keeps its last force for step k and the miss
    is counted; a source whose publisher left the graph gets ``lost_source_policy`` (zero or
    hold) with a warning. Step 0 waits for every source as in lockstep (discovery).
    """
    core, mixer, dt = node.core, node.mixer, node.dt
    stats = LatenessStats(node.n_steps, dt)
    fault_in(trace.y, trace.u, trace.full, stats.lateness, stats.misses)   # before step 0
    node.run_lockstep(executor, trace, n_steps=1)
    t0 = time.monotonic() - dt
    next_report = t0 + node.params.report_period
    next_check = t0 + GRAPH_CHECK_PERIOD
    answered = 1.0
    for k in range(1, node.n_steps):
        if shutdown.requested():
            break
        start = t0 + k * dt
        now = time.monotonic()
        while now < start:   # sleep in the executor, poll the clock for the last POLL_AHEAD
            if start - now > POLL_AHEAD:
                executor.spin_once(timeout_sec=start - POLL_AHEAD - now)
            now = time.monotonic()
        stats.add(k, now - start)
        began = now
        y = core.outputs()
        node.publish_outputs(y)
        on_time = began + ANSWER_WINDOW * dt <= start + dt
        # a late step still gives the sources time if they mostly answer steps begun on time
        deadline = (start + dt if on_time or answered < 0.5 else
                    began + ANSWER_WINDOW * dt)
        while mixer.missing(k) and now < deadline:
            executor.spin_once(timeout_sec=deadline - now)
            now = time.monotonic()
        # answers that arrived while the plant itself had no CPU (stopped inside this wait, so
        # it woke past the deadline) came in time: take them before counting a miss
        for _ in mixer.missing(k):
            executor.spin_once(timeout_sec=0.0)
        late = [s for s in mixer.missing(k) if s not in node.lost]
        if on_time:        # share of answered steps, over about the last 10 begun on time
            answered += 0.1 * ((not late) - answered)
        for source in late:
            node.misses[source] += 1
        stats.missed(k, len(late))
        u = mixer.total()
        node.fullrate.record(k, y, u, trace)
        core.advance(u)
        if node.drain is not None:
            node.drain.tick(executor)
        if now > next_check:
            watch_lost_sources(node)
            next_check = now + GRAPH_CHECK_PERIOD
        if now > next_report:
            node.get_logger().info('realtime, last period: ' + stats.report(k + 1, now, t0))
            next_report = now + node.params.report_period
    stats.elapsed = time.monotonic() - t0
    return stats


def watch_lost_sources(node) -> None:
    """Realtime: apply ``lost_source_policy`` to sources whose publisher left, warn once."""
    for source in node.check_sources():
        if source in node.lost:
            continue
        node.lost.add(source)
        if node.params.lost_source_policy == 'zero':
            node.mixer.drop(source)
        node.get_logger().warning(
            f'force source {source!r} left the ROS graph at step {node.core.k}; its force '
            f'is {"set to zero" if node.params.lost_source_policy == "zero" else "held"} '
            '(lost_source_policy)')
