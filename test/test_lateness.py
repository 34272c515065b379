"""Timing statistics of a paced run: periodic reports cover the steps since the last one."""
import numpy as np

from pentapod_sim.sim.lateness import fault_in, LatenessStats


def test_reports_cover_the_steps_since_the_previous_report():
    dt = 1e-3
    stats = LatenessStats(10, dt)
    for k in range(1, 10):
        stats.add(k, k * 1e-4)             # step k is k * 100 us late
    stats.missed(3, 1)
    stats.missed(7, 2)
    first = stats.report(5, 0.005, 0.0)    # steps 1-4 started at 1, 2, 3, 4 ms
    assert 'p50 250 us' in first and 'max 400 us' in first
    assert '1000.0 Hz achieved' in first   # 4 steps in the 4 ms since step 1 started
    assert '1 steps with a missed deadline in 4 steps' in first
    second = stats.report(10, 0.015, 0.0)  # steps 5-9 in the 10 ms since the first report
    assert 'p50 700 us' in second and 'max 900 us' in second
    assert '500.0 Hz achieved' in second
    assert '1 steps with a missed deadline in 5 steps' in second
    whole = stats.as_dict(10, 0.01)        # the final figures still cover every step
    assert whole['missed_steps'] == 2 and whole['missed_answers'] == 3
    assert whole['lateness_max'] == 9 * 1e-4


def test_fault_in_writes_every_array_and_skips_none():
    arrays = [np.full(5, 7.0), np.full((3, 2), 1, dtype=np.int64)]
    fault_in(arrays[0], None, arrays[1])
    assert all(not a.any() for a in arrays)
