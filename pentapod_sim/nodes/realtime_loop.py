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

#: The least time a source has to answer y_k, in exchange periods after y_k went out. A plant
#: that stalled (the machine took its CPU for a few ms) starts its next steps late and catches
#: up; with the period's end as the only deadline, every catch-up step counted as missed by
#: its sources, which had no time to answer, and ran on held forces (1 kHz exchange, separate
#: processes: about half the misses of a run, 13 in a row after an 11 ms stall). Half a
#: period keeps the catch-up going (each step then takes at most half a period past its
#: publish) even if a source stays silent.
ANSWER_WINDOW = 0.5


def run_realtime(node, executor, trace) -> LatenessStats:
    """
    Wall-clock periods with the lockstep contract kept whenever an answer is in time.

    Period k starts at ``t0 + k dt``: the plant publishes y_k, then takes in answers until
    every source answered step k or the deadline passes: the period's end, or
    :data:`ANSWER_WINDOW` periods after y_k went out if that is later (a plant that fell
    behind the clock catches up without taking the sources' time to answer). In time, u_k
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
        y = core.outputs()
        node.publish_outputs(y)
        deadline = max(start + dt, time.monotonic() + ANSWER_WINDOW * dt)
        while mixer.missing(k) and now < deadline:
            executor.spin_once(timeout_sec=deadline - now)
            now = time.monotonic()
        late = [s for s in mixer.missing(k) if s not in node.lost]
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
