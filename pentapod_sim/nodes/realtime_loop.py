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


def run_realtime(node, executor, trace) -> LatenessStats:
    """
    Wall-clock periods with the lockstep contract kept whenever an answer is in time.

    Period k starts at ``t0 + k dt``: the plant publishes y_k, then takes in answers until
    every source answered step k or the period ends (the deadline). In time, u_k answers
    y_k exactly as in lockstep, so a run without misses equals the lockstep run bit for
    bit. A source that missed the deadline keeps its last force for step k and the miss is
    counted; a source whose publisher left the graph gets ``lost_source_policy`` (zero or
    hold) with a warning. Step 0 waits for every source as in lockstep (discovery).
    """
    core, mixer, dt = node.core, node.mixer, node.dt
    stats = LatenessStats(node.n_steps, dt)
    node.run_lockstep(executor, trace, n_steps=1)
    fault_in(trace.y, trace.u, trace.full, stats.lateness, stats.misses)
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
        deadline = start + dt
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
