"""
Benchmarks of recording and bag analysis.

* messages/s written by :class:`pentapod_sim.recording.BagWriter` vs the bare ``mcap`` Writer
  (same CDR payloads, same chunk size, no compression);
* time to load a bag of N samples (excitation force + TCP displacement, 1 kHz) and compute its
  FRF with our reader vs reading the same topics with rosbags ``AnyReader`` + deserialize
  (same FRF code afterwards); each run in a fresh process;
* the same load with our fast reader vs its fallback, the public ``mcap.reader`` API feeding the
  same CDR decoders (``open_bag(..., reader='mcap.reader')``);
* peak RSS of those two processes;
* the recorder node's memory over a long run: a publisher process sends N steps (/clock and
  /pentapod/tcp_state, as fast as the recorder keeps up) and announces the end of the run;
  the recorder's RSS is sampled while it records and must stay flat (``--recorder`` runs only
  this row).

Full run: N = 1e6 samples (2e6 messages); quick: N = 1e5.
"""
import os
from pathlib import Path
import shutil
import subprocess
import sys
import tempfile
import time

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / 'test'))   # test fixtures: CDR encoders of the bench's messages

from mcap.writer import CompressionType, Writer  # noqa: E402

from fixtures.cdr import encode_joint_state, encode_wrench_stamped  # noqa: E402
from pentapod_sim.recording import BagWriter, message_definition  # noqa: E402
from pentapod_sim.scenario.domain import isolation  # noqa: E402

STATE, EXCITATION = '/pentapod/tcp_state', '/pentapod/excitation'

OURS = r"""
import sys, time
import numpy as np
from pentapod_sim.analysis.bag.reader import open_bag
from pentapod_sim.analysis.frf.estimation import frf_from_series
t0 = time.perf_counter()
bag = open_bag(sys.argv[1], ['/pentapod/excitation', '/pentapod/tcp_state'])
res = frf_from_series(bag.series('/pentapod/excitation.force.x'),
                      bag.series('/pentapod/tcp_state.position.tcp_x'), 'random', 8192)
print(time.perf_counter() - t0, abs(res.H[100]),
      [l.split()[1] for l in open('/proc/self/status') if l.startswith('VmHWM:')][0])
"""

PUBLIC = OURS.replace("'/pentapod/tcp_state'])", "'/pentapod/tcp_state'], reader='mcap.reader')")

ROSBAGS = r"""
import sys, time
from pathlib import Path
import numpy as np
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_typestore
from pentapod_sim.analysis.frf.estimation import estimate_frf
t0 = time.perf_counter()
force, disp = [], []
with AnyReader([Path(sys.argv[1])], default_typestore=get_typestore(Stores.ROS2_JAZZY)) as r:
    for conn, _, raw in r.messages():
        msg = r.deserialize(raw, conn.msgtype)
        if conn.topic == '/pentapod/excitation':
            force.append(msg.wrench.force.x)
        else:
            disp.append(msg.position[0])
res = estimate_frf(np.array(force), np.array(disp), 1000.0, 'random', 8192)
print(time.perf_counter() - t0, abs(res.H[100]),
      [l.split()[1] for l in open('/proc/self/status') if l.startswith('VmHWM:')][0])
"""


#: Publishes argv[1] steps as fast as the subscribers acknowledge, then the end of the run.
FAST_PUBLISHER = r"""
import sys
import rclpy
from rclpy.duration import Duration
from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from pentapod_sim import interface
from pentapod_sim.nodes.common import qos
n = int(sys.argv[1])
rclpy.init()
node = rclpy.create_node('fast_publisher')
clock = node.create_publisher(Clock, interface.CLOCK, qos('state'))
state = node.create_publisher(JointState, interface.TCP_STATE, qos('state'))
status = node.create_publisher(DiagnosticStatus, interface.RUN_STATUS, qos('status'))
while clock.get_subscription_count() == 0 or state.get_subscription_count() == 0:
    rclpy.spin_once(node, timeout_sec=0.05)
rclpy.spin_once(node, timeout_sec=1.0)
c, js = Clock(), JointState(name=['tcp_x', 'tcp_y', 'tcp_z'])
for k in range(n):
    sec, nsec = divmod(k * 1_000_000, 10 ** 9)
    c.clock.sec = js.header.stamp.sec = sec
    c.clock.nanosec = js.header.stamp.nanosec = nsec
    js.position = [1e-6 * k, 0.0, 0.0]
    js.velocity = [float(k), 0.0, 0.0]
    clock.publish(c)
    state.publish(js)
    if k % 10000 == 9999:     # stay within the history depth of the recorder's writers
        clock.wait_for_all_acked(Duration(seconds=60))
values = {'state': 'finished', 'steps': n, 'dt': 0.001, 'last_stamp_ns': (n - 1) * 1_000_000,
          'step_topics': f'{interface.CLOCK},{interface.TCP_STATE}'}
status.publish(DiagnosticStatus(message='finished', values=[
    KeyValue(key=k, value=str(v)) for k, v in values.items()]))
for pub in (clock, state, status):
    pub.wait_for_all_acked(Duration(seconds=120))
"""


def _rss_mib(pid: int) -> float:
    """Resident set size of a running process [MiB] (VmRSS), 0 once it has ended."""
    try:
        for line in Path(f'/proc/{pid}/status').read_text().splitlines():
            if line.startswith('VmRSS:'):
                return float(line.split()[1]) / 1024.0
    except OSError:
        pass
    return 0.0


def recorder_memory(n: int, folder: Path) -> dict:
    """
    Record n steps with the recorder node; its RSS against the messages written so far.

    Returns a result row: RSS growth [MiB] from 10 % to 100 % of the run, against the RSS at
    10 %. The recorder stops by itself at the announced end (checks the count too).
    """
    changes, lease = isolation(os.environ)
    env = dict(os.environ, **changes, PYTHONPATH=str(ROOT))
    rec = subprocess.Popen([sys.executable, '-m', 'pentapod_sim.nodes.recorder_node',
                            '--ros-args', '-p', f'output_dir:={folder}', '-p', 'bag_name:=mem',
                            '-p', 'drain_timeout:=120.0'], env=env, cwd=ROOT,
                           stdout=open(folder / 'recorder.log', 'w'),  # noqa: SIM115
                           stderr=subprocess.STDOUT)
    pub = subprocess.Popen([sys.executable, '-c', FAST_PUBLISHER, str(n)], env=env, cwd=ROOT)
    samples = []            # (messages written, RSS [MiB])
    meta = folder / 'mem' / 'metadata.yaml'
    try:
        t0 = time.monotonic()
        while rec.poll() is None and time.monotonic() - t0 < 3600:
            rss = _rss_mib(rec.pid)
            try:
                count = int(next(line.split(':')[1] for line in meta.read_text().splitlines()
                                 if line.strip().startswith('message_count:')))
            except (OSError, StopIteration, ValueError):
                count = 0
            if rss:
                samples.append((count, rss))
            time.sleep(0.5)
        wall = time.monotonic() - t0
        if pub.wait(timeout=60) != 0 or rec.wait(timeout=60) != 0:
            raise RuntimeError((folder / 'recorder.log').read_text()[-2000:])
    finally:
        for proc in (pub, rec):
            if proc.poll() is None:
                proc.kill()
                proc.wait()
        if lease is not None:
            lease.release()
    log = (folder / 'recorder.log').read_text()
    if 'none missing' not in log:
        raise RuntimeError(f'recorder lost messages: {log[-2000:]}')
    total = 2 * n
    early = [rss for count, rss in samples if count >= total // 10]
    start, end = early[0], max(rss for count, rss in samples if count >= total // 10)
    return {'name': f'recorder node RSS growth over {n:.0e} steps', 'value': end - start,
            'unit': 'MiB', 'baseline': 'recorder RSS after 10 % of the steps',
            'baseline_value': start, 'ratio': end / start,
            'note': f'{total} messages (/clock + tcp_state) in {wall:.0f} s; growth per '
                    f'100k steps {(end - start) / (0.9 * n) * 1e5:.2f} MiB; every step '
                    'recorded (its log)'}


def _payloads(n: int) -> tuple:
    rng = np.random.default_rng(0)
    force = rng.normal(0.0, 10.0, n)
    # a lightly damped 40 Hz oscillator driven by the force, as a plausible response
    from scipy import signal
    b, a = signal.iirpeak(40.0, 30.0, fs=1000.0)
    disp = 1e-6 * signal.lfilter(b, a, force)
    states = [encode_joint_state(k * 1_000_000, ['tcp_x', 'tcp_y', 'tcp_z'],
                                 [disp[k], 0.0, 0.0], [0.0, 0.0, 0.0]) for k in range(n)]
    wrenches = [encode_wrench_stamped(k * 1_000_000, [force[k], 0.0, 0.0]) for k in range(n)]
    return states, wrenches


def _write_ours(path: Path, states: list, wrenches: list) -> float:
    t0 = time.perf_counter()
    with BagWriter(path, run_info={'bench': 'recording'}) as writer:
        writer.add_topic(STATE, 'sensor_msgs/msg/JointState')
        writer.add_topic(EXCITATION, 'geometry_msgs/msg/WrenchStamped')
        for k, (state, wrench) in enumerate(zip(states, wrenches)):
            writer.write(EXCITATION, wrench, k * 1_000_000)
            writer.write(STATE, state, k * 1_000_000)
    return time.perf_counter() - t0


def _write_bare(path: Path, states: list, wrenches: list) -> float:
    t0 = time.perf_counter()
    with open(path, 'wb') as stream:
        writer = Writer(stream, chunk_size=64 * 1024, compression=CompressionType.NONE)
        writer.start(profile='ros2')
        ids = []
        for topic, msg_type in ((STATE, 'sensor_msgs/msg/JointState'),
                                (EXCITATION, 'geometry_msgs/msg/WrenchStamped')):
            schema = writer.register_schema(msg_type, 'ros2msg',
                                            message_definition(msg_type).encode())
            ids.append(writer.register_channel(topic, 'cdr', schema))
        for k, (state, wrench) in enumerate(zip(states, wrenches)):
            writer.add_message(ids[1], k * 1_000_000, wrench, k * 1_000_000)
            writer.add_message(ids[0], k * 1_000_000, state, k * 1_000_000)
        writer.finish()
    return time.perf_counter() - t0


def _run_child(script: str, bag: Path) -> tuple:
    """Run a reader script in a fresh process; return (seconds inside, peak RSS [MB], |H|)."""
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    read_fd, write_fd = os.pipe()
    pid = os.fork()
    if pid == 0:  # child: run the script with stdout into the pipe
        os.dup2(write_fd, 1)
        os.close(read_fd)
        os.execve(sys.executable, [sys.executable, '-c', script, str(bag)], env)
    os.close(write_fd)
    with os.fdopen(read_fd) as pipe:
        out = pipe.read()
    _, status, _ = os.wait4(pid, 0)
    if status != 0:
        raise RuntimeError(f'reader process failed with status {status}')
    # the child's own VmHWM: ru_maxrss of a forked child would include this process's memory
    seconds, magnitude, hwm_kib = (float(v) for v in out.split())
    return seconds, hwm_kib / 1024.0, magnitude


def run(quick: bool) -> list:
    """Run the benchmarks; return result rows (see bench/run_all.py)."""
    n = 100_000 if quick else 1_000_000
    rows = []
    tmp = Path(tempfile.mkdtemp(prefix='bench_recording_'))
    try:
        states, wrenches = _payloads(n)
        ours_s, bare_s = np.inf, np.inf
        for attempt in range(2):  # best of two, alternating: the machine is shared
            shutil.rmtree(tmp / 'ours', ignore_errors=True)
            ours_s = min(ours_s, _write_ours(tmp / 'ours', states, wrenches))
            bare_s = min(bare_s, _write_bare(tmp / 'bare.mcap', states, wrenches))
        rate, bare_rate = 2 * n / ours_s, 2 * n / bare_s
        rows.append({'name': 'write rate (JointState + WrenchStamped)', 'value': rate,
                         'unit': 'msg/s', 'baseline': 'bare mcap Writer',
                         'baseline_value': bare_rate,
                         'ratio': rate / bare_rate,
                         'note': 'best of 2; ours adds metadata.yaml, flush+fsync every 0.5 s'})
        del states, wrenches
        ours = _run_child(OURS, tmp / 'ours')
        base = _run_child(ROSBAGS, tmp / 'ours')
        public = _run_child(PUBLIC, tmp / 'ours')
        if not np.isclose(ours[2], base[2], rtol=1e-9) or ours[2] != public[2]:
            raise RuntimeError(f'readers disagree: |H| {ours[2]} vs {base[2]}, {public[2]}')
        rows.append({'name': f'fast bag reader, load {n:.0e} samples + FRF', 'value': ours[0],
                     'unit': 's', 'baseline': 'mcap.reader + the same CDR decoder',
                     'baseline_value': public[0], 'ratio': public[0] / ours[0],
                     'note': 'chunk CRCs checked by both; open_bag(reader=...) on the same bag'})
        rows.append({'name': f'load {n:.0e} samples + FRF', 'value': ours[0], 'unit': 's',
                         'baseline': 'rosbags AnyReader + deserialize', 'baseline_value': base[0],
                         'ratio': base[0] / ours[0], 'note': f'{2 * n} messages, same FRF code'})
        rows.append({'name': f'peak RSS load {n:.0e} samples + FRF', 'value': ours[1],
                         'unit': 'MB', 'baseline': 'rosbags AnyReader + deserialize',
                         'baseline_value': base[1], 'ratio': base[1] / ours[1],
                         'note': 'whole reader process (its own VmHWM)'})
        rows.append(recorder_memory(n, tmp))
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return rows


if __name__ == '__main__':
    if '--recorder' in sys.argv:   # only the recorder's memory row
        with tempfile.TemporaryDirectory(prefix='bench_recorder_') as folder:
            results = [recorder_memory(100_000 if '--quick' in sys.argv else 1_000_000,
                                       Path(folder))]
    else:
        results = run(quick='--quick' in sys.argv)
    for row in results:
        print(f"{row['name']}: {row['value']:.4g} {row['unit']} vs {row['baseline']} "
              f"{row['baseline_value']:.4g} {row['unit']} -> ratio {row['ratio']:.2f}")
