"""
The plant's timings without ROS: a fake clock and a scripted exchange, every step determined.

:class:`Scripted` stands in for the plant node's exchange and executor. Each source answers
every step after a fixed latency (its answer is then queued in the "executor"), one event per
``spin``, as rclpy's ``spin_once`` runs one. A stall freezes the plant inside a step's answer
wait: the clock jumps, the answers due meanwhile are queued, and that ``spin`` returns without
running them, as a wait that timed out while the process had no CPU does. The forces are the
closed loop's: the exciter a function of k, the damper ``-b v`` of the published y_k, so an
answer in time gives the lockstep trace bit for bit.
"""
import heapq
import math

import numpy as np
import pytest

from fixtures.demo_model import demo_model
from pentapod_sim.errors import RunError
from pentapod_sim.sim.realtime import ANSWER_WINDOW, RealTime
from pentapod_sim.sim.stepping import DiscretePlant, ForceMixer, ForceSource
from pentapod_sim.sim.timing import GRAPH_CHECK_PERIOD, Lockstep, Waits

DT = 1e-3
TICK = 1e-6              # the fake clock advances this much per reading [s]
GAIN = 2000.0            # the damper's b [N s/m]
WAITS = Waits(startup_timeout=10.0, source_timeout=0.05, resend_period=0.01)


class FakeClock:
    """A monotonic clock that advances TICK per reading (busy polls end) and jumps on demand."""

    def __init__(self):
        self.now = 0.0

    def __call__(self) -> float:
        self.now += TICK
        return self.now


class Log:
    def __init__(self):
        self.lines = []

    def info(self, message):
        self.lines.append(('info', message))

    def warning(self, message):
        self.lines.append(('warning', message))


def exciter_force(k: int) -> float:
    return 50.0 * math.sin(0.37 * k) + 20.0


class Scripted:
    """
    The exchange of a plant with an exciter and a TCP damper, driven by a fake clock.

    ``latency``: source -> answer time after a publish [s]; ``stalls``: step -> how long the
    plant stalls inside that step's answer wait [s]; ``leaves``: source -> step from which its
    publisher is gone (it answers no more).
    """

    def __init__(self, core, mixer, clock, exact, latency, stalls=None, leaves=None,
                 answers=True):
        self.core, self.mixer, self.clock, self.exact = core, mixer, clock, exact
        self.latency, self.stalls, self.leaves = latency, stalls or {}, leaves or {}
        self.answers = answers
        self.queue = []              # (arrival, seq, source, step, efforts)
        self.seq = 0
        self.stall = 0.0             # armed by a publish of a stalling step
        self.published, self.resent = [], []
        self.y, self.u = {}, {}
        self.vx = core.output_names.index('tcp_velocity_x')

    def answer(self, source, k, y):
        if source == 'exciter':
            return ['tcp_force_x'], [exciter_force(k)]
        return ['tcp_force_x'], [-GAIN * y[self.vx]]

    def publish(self, k, y):
        self.published.append((k, self.clock.now))
        if self.answers:
            for source, latency in self.latency.items():
                if k < self.leaves.get(source, math.inf):
                    names, efforts = self.answer(source, k, y)
                    heapq.heappush(self.queue, (self.clock.now + latency, self.seq, source, k,
                                                names, efforts))
                    self.seq += 1
        self.stall = self.stalls.get(k, 0.0)

    def resend(self, k, y):
        self.resent.append((k, self.clock.now))

    def _run_one(self):
        _, _, source, k, names, efforts = heapq.heappop(self.queue)
        self.mixer.submit(source, names, efforts, k, self.core.k, exact=self.exact)

    def spin(self, timeout):
        if self.stall and timeout > 0:      # the plant loses its CPU inside this wait
            self.clock.now += self.stall
            self.stall = 0.0
            return                          # woke past the wait's end; nothing run yet
        now = self.clock.now
        if self.queue and self.queue[0][0] <= now:
            self._run_one()
        elif self.queue and self.queue[0][0] <= now + timeout:
            self.clock.now = self.queue[0][0]
            self._run_one()
        else:
            self.clock.now = now + timeout

    def poll(self, k):
        pass

    def gone(self):
        return [s for s, k in self.leaves.items() if self.core.k >= k]

    def record(self, k, y, u):
        self.y[k], self.u[k] = y.copy(), u.copy()

    def stepped(self):
        pass

    def buffers(self):
        return []


def plant():
    core = DiscretePlant(demo_model(4, seed=3).discretize(DT))
    mixer = ForceMixer(core.input_names, [ForceSource('exciter'), ForceSource('damper')])
    return core, mixer


def lockstep_run(n, **script):
    core, mixer = plant()
    clock = FakeClock()
    exchange = Scripted(core, mixer, clock, True, **script)
    Lockstep(core, mixer, n, WAITS, clock, lambda: False).run(exchange)
    return core, exchange


def realtime_run(n, **script):
    core, mixer = plant()
    clock, log = FakeClock(), Log()
    exchange = Scripted(core, mixer, clock, False, **script)
    timing = RealTime(core, mixer, n, WAITS, report_period=1e9, lost_policy='zero', log=log,
                      clock=clock, stopped=lambda: False)
    timing.run(exchange)
    return timing, exchange, log


def stacked(record, n):
    return np.array([record[k] for k in range(n)])


def test_lockstep_applies_each_answer_to_the_step_it_answers():
    """The run equals the loop stepped by hand with u_k = exciter(k) - b v_k(y_k)."""
    n = 200
    core, exchange = lockstep_run(n, latency={'exciter': 3e-4, 'damper': 7e-4})
    ref, _ = plant()
    vx = ref.output_names.index('tcp_velocity_x')
    fx = ref.input_names.index('tcp_force_x')
    for k in range(n):
        y = ref.outputs()
        u = np.zeros(len(ref.input_names))
        u[fx] = exciter_force(k) + -GAIN * y[vx]
        assert np.array_equal(exchange.y[k], y) and np.array_equal(exchange.u[k], u), k
        ref.advance(u)
    assert core.k == n and np.array_equal(core.x, ref.x)
    assert np.any(stacked(exchange.u, n))


def test_lockstep_resends_a_step_then_names_the_silent_source():
    """No answer: y_k again every resend_period, RunError after source_timeout naming it."""
    core, mixer = plant()
    clock = FakeClock()
    exchange = Scripted(core, mixer, clock, True, latency={'exciter': 1e-4, 'damper': 1e-4},
                        leaves={'damper': 1})
    exchange.gone = lambda: []              # still in the graph, only silent
    with pytest.raises(RunError, match=r'force source\(s\) damper silent for 0.05.* s at '
                                       r'step 1 \(t = 0.001 s\); source_timeout = 0.05 s'):
        Lockstep(core, mixer, 5, WAITS, clock, lambda: False).run(exchange)
    start = dict(exchange.published)[1]
    times = [t - start for k, t in exchange.resent if k == 1]
    # every resend_period (checked once per spin of resend_period / 4), the last one before
    # the timeout
    assert len(times) == 4 and WAITS.resend_period < times[0] < 1.25 * WAITS.resend_period
    assert np.allclose(np.diff(times), WAITS.resend_period, rtol=0, atol=50 * TICK), times
    assert core.k == 1


def test_lockstep_names_a_source_that_left_the_graph():
    with pytest.raises(RunError, match=r'damper left the ROS graph \(no publisher on '
                                       r'/pentapod/forces/damper\) at step 3'):
        lockstep_run(10, latency={'exciter': 1e-4, 'damper': 1e-4}, leaves={'damper': 3})


class FreezingClock(FakeClock):
    """
    A clock whose reading ``at`` (counted from :meth:`arm`) takes ``freeze`` s.

    The process was frozen (SIGSTOP) right at that reading; ``on_wake`` runs as it is continued,
    as the stop signal the scenario runner sends with its SIGCONT is delivered then.
    """

    def __init__(self, freeze, on_wake):
        super().__init__()
        self.freeze, self.on_wake, self.left = freeze, on_wake, None

    def arm(self, at):
        self.left = at

    def __call__(self):
        if self.left is not None:
            self.left -= 1
            if self.left == 0:
                self.now += self.freeze
                self.on_wake()
        return super().__call__()


def test_a_plant_frozen_in_its_wait_and_stopped_on_waking_stops_on_the_request():
    """
    The race of test_run_ends' stalled plant (CI, 2026-12-05): SIGINT + SIGCONT after 5.7 s.

    The damper answers no more from step 3 (it saw the plant stall and ended). The plant is
    frozen at the clock reading right after the first spin of step 3's wait, longer than
    source_timeout, and the stop request arrives as it wakes. It stops on the request, step 3
    not advanced; it does not call the damper silent for the frozen time.
    """
    core, mixer = plant()
    requested = []
    clock = FreezingClock(freeze=100 * WAITS.source_timeout, on_wake=lambda: requested.append(1))
    exchange = Scripted(core, mixer, clock, True, latency={'exciter': 1e-4, 'damper': 1e-4},
                        leaves={'damper': 3})
    exchange.gone = lambda: []              # still in the graph, only silent
    publish = exchange.publish

    def publish_and_arm(k, y):
        publish(k, y)
        if k == 3:
            clock.arm(2)              # 1: the wait's start, 2: after its first spin
    exchange.publish = publish_and_arm
    Lockstep(core, mixer, 10, WAITS, clock, lambda: bool(requested)).run(exchange)
    assert requested and core.k == 3
    assert clock.now > dict(exchange.published)[3] + 100 * WAITS.source_timeout  # it froze


def test_answers_queued_while_a_lockstep_plant_was_frozen_are_taken_not_called_silent():
    """
    A lockstep plant frozen inside a step's wait for longer than source_timeout runs on.

    Frozen 4 source_timeouts inside step 20's wait, both answers queued meanwhile: on waking
    the plant takes them and runs on; the trace is that of the run without the freeze.
    """
    n, k = 40, 20
    _, frozen = lockstep_run(n, latency={'exciter': 3e-4, 'damper': 3e-4},
                             stalls={k: 4 * WAITS.source_timeout})
    published = dict(frozen.published)
    assert published[k + 1] - published[k] > 4 * WAITS.source_timeout
    _, lock = lockstep_run(n, latency={'exciter': 3e-4, 'damper': 3e-4})
    assert np.array_equal(stacked(frozen.u, n), stacked(lock.u, n))
    assert np.array_equal(stacked(frozen.y, n), stacked(lock.y, n))


def test_answers_delivered_while_the_plant_was_stalled_in_its_wait_are_taken():
    """
    The race of a SIGSTOP inside step 40's answer wait (CI, fixed in main's 3a289d5).

    Both answers arrive 0.3 ms after the publish, while the plant has no CPU; it wakes 5 ms
    later, past the deadline, with the answers queued. They came in time: no miss, and u_40
    answers y_40 as in lockstep.
    """
    n, k = 60, 40
    timing, exchange, _ = realtime_run(n, latency={'exciter': 3e-4, 'damper': 3e-4},
                                       stalls={k: 5e-3})
    published = dict(exchange.published)
    assert published[k + 1] - published[k] > 5e-3          # the stall happened in step k
    assert timing.misses == {'exciter': 0, 'damper': 0}
    assert timing.deadline_misses() == 0 and not timing.stats.misses.any()
    _, lock = lockstep_run(n, latency={'exciter': 3e-4, 'damper': 3e-4})
    assert np.array_equal(stacked(exchange.u, n), stacked(lock.u, n))
    assert np.array_equal(stacked(exchange.y, n), stacked(lock.y, n))


def test_a_stalled_plant_catches_up_half_a_period_a_step_without_misses():
    """
    After a stall of 10.3 periods each late step still waits for its answers.

    The answers take 0.4 periods, less than the ANSWER_WINDOW of half a period, so every one is
    in time; a late step begins as soon as the previous one got its answers, so the plant
    gains 0.6 periods per step on the clock, then runs on time again. The trace is lockstep's.
    """
    n, k, stall, latency = 120, 30, 10.3 * DT, 0.4 * DT
    timing, exchange, _ = realtime_run(n, latency={'exciter': latency, 'damper': latency},
                                       stalls={k: stall})
    late = timing.stats.lateness
    assert late[:k + 1].max() < 0.01 * DT
    # step k began on time and ended `stall` later: step k + 1 is stall - dt late
    assert late[k + 1] == pytest.approx(stall - DT, abs=20 * TICK)
    behind = np.flatnonzero(late > ANSWER_WINDOW * DT)
    assert behind[0] == k + 1 and np.array_equal(behind, np.arange(k + 1, behind[-1] + 1))
    assert np.allclose(np.diff(late[k + 1:behind[-1] + 2]), latency - DT, rtol=0,
                       atol=20 * TICK)
    assert late[behind[-1] + 2:].max() < 0.01 * DT          # on time again
    assert timing.deadline_misses() == 0
    _, lock = lockstep_run(n, latency={'exciter': latency, 'damper': latency})
    assert np.array_equal(stacked(exchange.u, n), stacked(lock.u, n))


def test_sources_that_cannot_keep_up_get_no_answer_window():
    """
    Sources that answer 1.5 periods late miss every deadline: a late step does not wait.

    Once the share of answered steps among those begun on time is below one half, the plant
    that stalled catches up a whole period a step instead of half a period.
    """
    n, k, latency = 120, 40, 1.5 * DT
    timing, exchange, _ = realtime_run(n, latency={'exciter': latency, 'damper': latency},
                                       stalls={k: 5.2 * DT})
    late = timing.stats.lateness
    assert timing.stats.misses[1:].min() == 2              # every step, both sources
    assert timing.misses == {'exciter': n - 1, 'damper': n - 1}
    behind = np.flatnonzero(late > 0.01 * DT)
    assert behind[0] == k + 1 and len(behind) == 5         # 4.2, 3.2, ... 0.2 periods late
    assert np.allclose(np.diff(late[k + 1:k + 6]), -DT, rtol=0, atol=20 * TICK)
    # they ran on the newest answers in by then: those to step k, queued during the stall
    fx, vx = (exchange.core.input_names.index('tcp_force_x'),
              exchange.core.output_names.index('tcp_velocity_x'))
    for j in range(k + 1, k + 6):
        assert exchange.u[j][fx] == exciter_force(k) + -GAIN * exchange.y[k][vx], j


def test_a_source_that_left_is_zeroed_and_no_longer_counted_as_missing():
    """``lost_source_policy`` zero: counted as missing only until the graph check sees it."""
    n, leaves = 600, 100
    timing, exchange, log = realtime_run(n, latency={'exciter': 2e-4, 'damper': 2e-4},
                                         leaves={'damper': leaves})
    warned = [m for level, m in log.lines if level == 'warning']
    assert len(warned) == 1 and "force source 'damper' left the ROS graph" in warned[0]
    seen = int(warned[0].split('at step ')[1].split(';')[0])
    # graph checks every GRAPH_CHECK_PERIOD of wall time, the first one after step 0
    assert leaves < seen <= leaves + GRAPH_CHECK_PERIOD / DT + 2
    assert timing.misses == {'exciter': 0, 'damper': seen - leaves}
    assert timing.lost == {'damper'}
    fx = exchange.core.input_names.index('tcp_force_x')
    for j in range(seen, n):             # the damper's force is zero, the exciter's applied
        assert exchange.u[j][fx] == exciter_force(j), j
    figures = timing.figures()
    assert figures['missed_steps'] == seen - leaves
    assert np.array_equal(np.flatnonzero(figures['missed_per_step']),
                          np.arange(leaves, seen))


def test_answers_rejected_until_the_timeout_end_the_run_as_rejected_not_silent():
    """Every answer of the damper above max_effort: the end names it rejected, with why."""
    core = DiscretePlant(demo_model(4, seed=3).discretize(DT))
    mixer = ForceMixer(core.input_names, [ForceSource('exciter'), ForceSource('damper')],
                       max_effort=1e3)
    clock = FakeClock()
    exchange = Scripted(core, mixer, clock, True, latency={'exciter': 1e-4, 'damper': 1e-4})
    exchange.answer = lambda source, k, y: (['tcp_force_x'],
                                            [exciter_force(k) if source == 'exciter' else 1e5])
    with pytest.raises(RunError) as err:
        Lockstep(core, mixer, 5, WAITS, clock, lambda: False).run(exchange)
    text = str(err.value)
    assert 'force source damper rejected' in text and 'limit' in text, text
    assert 'silent' not in text, text
    assert core.k == 0 and mixer.rejected[('damper', 'limit')] == 1
