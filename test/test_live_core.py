"""The live view's ROS-free parts: envelope, spectrum, status, topic streams, layout file."""
import json
import math
from pathlib import Path
import subprocess
import sys

import numpy as np
from numpy.testing import assert_allclose
import pytest

from fixtures.cdr import encode_joint_state, encode_wrench_stamped
from pentapod_sim import interface
from pentapod_sim.live.envelope import envelope, EnvelopeDownsampler
from pentapod_sim.live.layout import build_layout, layout_json, message_paths
from pentapod_sim.live.spectrum import amplitude_spectrum, RunningSpectrum
from pentapod_sim.live.status import RunStatus, status_index, STATUS_NAMES
from pentapod_sim.live.streams import TopicStream

ROOT = Path(__file__).resolve().parents[1]
HANN_SCALLOP = 10 ** (-1.4236 / 20)   # worst-case Hann amplitude half-way between bins


def test_envelope_keeps_both_extremes_in_the_order_they_occur():
    t = np.arange(5, dtype=np.int64) * 10
    values = np.array([[0.0, 1.0, 5.0, np.nan],
                       [3.0, 0.5, 4.0, np.nan],
                       [-2.0, 2.0, 3.0, np.nan],
                       [1.0, 0.0, 2.0, np.nan],
                       [0.0, 1.5, 1.0, np.nan]])
    (t0, first), (t1, second) = envelope(t, values)
    assert (t0, t1) == (0, 40)
    # column 0: max 3 at k=1 before min -2 at k=2; column 1: max 2 (k=2) before min 0 (k=3);
    # column 2 falls monotonically: its exact first and last samples
    assert_allclose(first[:3], [3.0, 2.0, 5.0])
    assert_allclose(second[:3], [-2.0, 0.0, 1.0])
    assert np.isnan(first[3]) and np.isnan(second[3])
    assert envelope(t[:1], values[:1])[0][0] == 0 and len(envelope(t[:1], values[:1])) == 1


def test_downsampler_in_chunks_equals_one_pass_per_window():
    rng = np.random.default_rng(4)
    stamps = np.cumsum(rng.integers(1, 4, 3000)).astype(np.int64) * 200_000   # gaps = drops
    values = rng.standard_normal((len(stamps), 3))
    period = 5_000_000
    down = EnvelopeDownsampler(period)
    got, start = [], 0
    while start < len(stamps):
        size = int(rng.integers(0, 90))
        got += down.add(stamps[start:start + size], values[start:start + size])
        start += size
    got += down.flush()
    window = stamps // period
    expected = []
    for w in np.unique(window):
        rows = np.flatnonzero(window == w)
        seg = values[rows]
        expected.append((stamps[rows[0]], stamps[rows[-1]], seg.min(0), seg.max(0)))
    pairs = iter(got)
    for t_first, t_last, low, high in expected:
        a = next(pairs)
        b = next(pairs) if t_last != t_first else a
        assert (a[0], b[0]) == (t_first, t_last)
        assert_allclose(np.minimum(a[1], b[1]), low)
        assert_allclose(np.maximum(a[1], b[1]), high)
    assert next(pairs, None) is None
    assert len(got) <= 2 * len(expected) < len(stamps) / 5


@pytest.mark.parametrize('n', [1000, 1001])
def test_sine_on_a_bin_gives_its_amplitude(n):
    dt, amplitude, k0 = 1 / 5000.0, 3e-6, 37
    f0 = k0 / (n * dt)
    t = np.arange(n) * dt
    x = amplitude * np.sin(2 * np.pi * f0 * t + 0.3) + 1e-3       # offset: removed
    f, a = amplitude_spectrum(np.column_stack([x, 2 * x]), dt)
    assert_allclose(f, np.fft.rfftfreq(n, dt))
    assert np.argmax(a[:, 0]) == k0
    assert_allclose(a[k0], [amplitude, 2 * amplitude], rtol=1e-9)
    assert_allclose(a[k0 - 1:k0 + 2:2, 0], amplitude / 2, rtol=1e-9)   # Hann side bins
    assert a[0, 0] < 1e-9 * amplitude


def test_nyquist_tone_of_an_even_length_gives_its_amplitude():
    n, amplitude = 256, 0.7
    x = amplitude * np.cos(np.pi * np.arange(n))     # +A, -A, ...: the Nyquist frequency
    f, a = amplitude_spectrum(x, 1e-3)
    assert f[-1] == 500.0 and a[-1] == pytest.approx(amplitude, rel=1e-12)


def test_sine_between_bins_loses_at_most_the_hann_scalloping():
    n, dt = 2048, 1e-3
    for shift in (0.25, 0.5):
        f0 = (100 + shift) / (n * dt)
        x = np.sin(2 * np.pi * f0 * np.arange(n) * dt)
        f, a = amplitude_spectrum(x, dt)
        assert abs(f[np.argmax(a)] - f0) <= 0.5 / (n * dt)
        assert HANN_SCALLOP * 0.999 <= a.max() <= 1.0


def test_running_spectrum_interpolates_lost_samples():
    n, dt_ns = 512, 200_000
    k = np.arange(3 * n)
    x = 2e-6 * np.sin(2 * np.pi * 50.0 * k * dt_ns * 1e-9)
    keep = np.ones(len(k), dtype=bool)
    keep[np.random.default_rng(1).choice(len(k), 40, replace=False)] = False
    keep[-1] = True
    spec = RunningSpectrum(n)
    for chunk in np.array_split(np.flatnonzero(keep), 7):
        spec.add(k[chunk] * dt_ns, x[chunk, None])
    assert spec.ready() and spec.dt_ns == dt_ns
    f, a = spec.compute()
    _, exact = amplitude_spectrum(x[-n:, None], dt_ns * 1e-9)
    assert np.max(np.abs(a - exact)) < 1e-3 * exact.max()


def test_run_status_step_rate_and_real_time_factor():
    status = RunStatus()
    first = status.report(10.0, 0)
    assert np.isnan(first[status_index('step')])
    dt_ns = 200_000
    status.add(np.arange(0, 1000) * dt_ns)
    status.report(10.0, 0)
    status.add(np.arange(1000, 3000, 2) * dt_ns)   # every other sample lost
    report = dict(zip(STATUS_NAMES, status.report(12.0, 7)))
    assert report['step'] == 2998 and report['sim_time'] == pytest.approx(2998 * 2e-4)
    assert report['steps_per_second'] == pytest.approx(1999 / 2.0)
    assert report['real_time_factor'] == pytest.approx(1999 * 2e-4 / 2.0)
    assert math.isnan(report['deadline_misses']) and math.isnan(report['rejected_messages'])
    assert report['dropped_by_live_view'] == 7


def test_run_status_passes_the_plant_figures_through():
    status = RunStatus()
    dt_ns = 200_000
    status.add(np.arange(0, 1000) * dt_ns)
    status.report(10.0, 0)
    status.add(np.arange(1000, 1200) * dt_ns)
    status.add_plant({'state': 'running', 'steps': '1500', 'dt': '0.0002', 'step_rate': '812.5',
                      'deadline_misses': '4', 'rejected_messages': '2'})
    report = dict(zip(STATUS_NAMES, status.report(11.0, 3)))
    assert report['step'] == 1499                      # the plant is ahead of the view
    assert report['steps_per_second'] == 812.5
    assert (report['deadline_misses'], report['rejected_messages']) == (4, 2)
    assert report['sim_time'] == pytest.approx(1199 * 2e-4)      # from the stamps
    assert report['real_time_factor'] == pytest.approx(200 * 2e-4)
    assert report['dropped_by_live_view'] == 3
    status.add(np.arange(1200, 1700) * dt_ns)
    assert dict(zip(STATUS_NAMES, status.report(12.0, 3)))['step'] == 1699   # view ahead
    status.add_plant({'state': 'running', 'steps': '0', 'step_rate': 'x'})  # new run, old plant
    report = dict(zip(STATUS_NAMES, status.report(13.0, 3)))
    assert report['step'] == 1699 and math.isnan(report['steps_per_second'])
    assert math.isnan(report['deadline_misses']) and math.isnan(report['rejected_messages'])


def test_topic_stream_counts_messages_lost_between_sequence_numbers():
    stream = TopicStream(interface.TCP_STATE, interface.JOINT_STATE, 1_000_000, backlog=100)
    msg = encode_joint_state(0, ['tcp_x'], [1.0], [])
    for sequence in (5, 6, 9, 10, 14):          # joined at 5; 7, 8 and 11-13 never came
        stream.offer(msg, sequence)
    assert stream.dropped == 5 and len(stream.queue) == 5
    for sequence in (1, 2, 4):                  # a new publisher starts again at 1
        stream.offer(msg, sequence)
    assert stream.dropped == 6


def test_topic_stream_drops_resent_steps_and_sees_a_new_run():
    stream = TopicStream(interface.TCP_STATE, interface.JOINT_STATE, 1_000_000, backlog=100)
    names = ['tcp_x', 'tcp_y', 'tcp_z']
    msgs = [encode_joint_state(k * 200_000, names, [k, -k, 0.5], [2.0 * k, 0, 0])
            for k in (0, 0, 0, 1, 2, 2, 3, 4, 5, 6, 1, 2)]           # resends, then a new run
    for m in msgs:
        stream.offer(m)
    parts = stream.process(stream.take())
    assert [p.new_run for p in parts] == [False, False, True]
    assert list(parts[0].samples[0]) == [k * 200_000 for k in range(7)]
    assert_allclose(parts[0].samples[1][:, 0], np.arange(7))
    assert parts[0].samples[1].shape == (7, 6)                # position and velocity columns
    assert list(parts[2].samples[0]) == [200_000, 400_000]
    assert stream.shape.names == names
    assert stream.shape.split(parts[0].samples[1][3]) == {
        'position': [3.0, -3.0, 0.5], 'velocity': [6.0, 0.0, 0.0], 'effort': []}
    for m in msgs:
        stream.backlog = 3
        stream.offer(m)
    assert stream.dropped == len(msgs) - 3
    wrench = TopicStream(interface.EXCITATION, interface.WRENCH_STAMPED, 10, backlog=10)
    wrench.offer(encode_wrench_stamped(5, [1.0, 2.0, 3.0], frame_id='tcp'))
    (part,) = wrench.process(wrench.take())
    assert wrench.shape.frame_id == 'tcp'
    assert_allclose(part.samples[1], [[1, 2, 3, 0, 0, 0]])
    wrench.offer(b'\x00\x01\x00\x00\x01')                         # truncated message
    assert wrench.process(wrench.take()) == [] and wrench.rejected == 1


def test_committed_layout_is_the_generated_one():
    path = ROOT / 'config' / 'foxglove' / 'testbed_layout.json'
    assert path.read_text() == layout_json(), \
        'regenerate: python -m pentapod_sim.live.layout > config/foxglove/testbed_layout.json'
    layout = json.loads(path.read_text())
    panels = set(layout['configById'])
    referenced = json.dumps(layout['layout']) + json.dumps(layout['configById']['Tab!forces'])
    assert all(p in referenced for p in panels if p != 'Tab!forces')
    topics = {p.split('.')[0] for p in message_paths(build_layout())}
    fixed = {interface.TCP_STATE, interface.EXCITATION, interface.PMA_STATE,
             interface.LIVE_STATUS, interface.RUN_STATUS}
    assert fixed <= topics
    assert all(t in fixed or t.startswith((interface.FORCE_PREFIX,
                                           interface.TCP_SPECTRUM_PREFIX)) for t in topics)


def test_docs_list_every_status_figure():
    text = (ROOT / 'docs' / 'live_view.md').read_text()
    table = text[text.index('**Run status**'):text.index('## It does not slow')]
    rows = [line.split('|')[1].strip().strip('`') for line in table.splitlines()
            if line.startswith('| `')]
    assert rows == list(STATUS_NAMES)


def test_lower_priority_renices_every_thread():
    script = (
        'import os, threading, time\n'
        'from pentapod_sim.live.hub import lower_priority\n'
        'stop = threading.Event()\n'
        'threading.Thread(target=stop.wait).start()\n'
        'tids = [int(t) for t in os.listdir("/proc/self/task")]\n'
        'before = [os.getpriority(os.PRIO_PROCESS, t) for t in tids]\n'
        'n = lower_priority(3)\n'
        'after = [os.getpriority(os.PRIO_PROCESS, t) for t in tids]\n'
        'stop.set()\n'
        'print(n, len(tids), *[a - b for a, b in zip(after, before)])\n')
    out = subprocess.run([sys.executable, '-c', script], capture_output=True, text=True,
                         cwd=ROOT, timeout=60, check=True).stdout.split()
    assert int(out[0]) == int(out[1]) >= 2
    assert set(out[2:]) == {'3'}
