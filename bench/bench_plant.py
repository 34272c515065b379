"""
Benchmarks of the plant core and the lockstep / real-time ROS runs.

* Offline, demo model of 100 modes (200 states, 21 inputs, 39 outputs), random TCP force:
  open loop and closed loop (TCP and strut dampers) with our stepping core and our lfilter
  fast path, against ``control.forced_response`` and ``scipy.signal.dlsim`` on the same
  discrete system.
* Lockstep through ROS (separate processes, DDS on localhost): plant + 1 and + 3 controller
  nodes, steps/s, against a bare rclpy ping-pong between two processes with the same message
  sizes and the default executor (rclpy.spin).
* A short composed run through the scenario runner, started fresh and forked warm (as the
  study starts its runs): wall time of the whole run.
* Real-time mode with one damper node at 1, 5 and 10 kHz: achieved rate, lateness p50/p99,
  overruns.
* Real time at machine rates: 1 kHz exchange with a multi-rate plant at 5 and 10 kHz
  (``substeps`` 5, 10), separate processes and composed: share of missed deadlines (target
  < 0.1 %), lateness p50/p99.

Full: 100k offline steps, 20k lockstep steps, 5 s real time (60 s at machine rates); quick:
20k, 3k, 1 s (5 s).
``python bench/bench_plant.py --offline [--quick]`` prints the offline rows only,
``--composed [--quick]`` the ping-pong and the lockstep composed rows only;
``python bench/run_all.py --only plant`` runs all and saves bench/results/plant.json.
"""
from __future__ import annotations

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
sys.path.insert(0, str(ROOT / 'test'))   # test fixtures: the random modal demo plant

import control  # noqa: E402
import scipy.signal  # noqa: E402

from fixtures.demo_model import demo_model  # noqa: E402
from pentapod_damper.laws import strut_bending_damper, tcp_damper  # noqa: E402
from pentapod_sim.cli import CommandParser  # noqa: E402
from pentapod_sim.nodes.answer_poll import usable_cpus  # noqa: E402
from pentapod_sim.scenario.domain import isolation  # noqa: E402
from pentapod_sim.sim.closed_loop import (  # noqa: E402
    closed_loop_system,
    excitation_matrix,
    simulate,
)
from pentapod_sim.sim.multirate import MultiRatePlant  # noqa: E402
from pentapod_sim.sim.stepping import DiscretePlant  # noqa: E402

RATE = 5000.0
TCP = ['tcp_force_x', 'tcp_force_y', 'tcp_force_z']

PINGPONG = r"""
import sys, time
import rclpy
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
role, n, work = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
qos = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
rclpy.init()
node = Node('bench_' + role)
if role == 'pong':
    pub = node.create_publisher(JointState, '/bench/back', qos)
    def echo(msg):
        out = JointState(name=['tcp_force_x', 'tcp_force_y', 'tcp_force_z'],
                         effort=[1.0, 2.0, 3.0])
        out.header.stamp = msg.header.stamp
        pub.publish(out)
    node.create_subscription(JointState, '/bench/out', echo, qos)
    try:
        rclpy.spin(node)
    except BaseException:
        pass
else:
    got = []
    pub = node.create_publisher(JointState, '/bench/out', qos)
    node.create_subscription(JointState, '/bench/back', lambda m: got.append(1), qos)
    names = ['strut%d_%s' % (i, k) for i in range(1, 6) for k in ('b2', 'b3', 'ax')]
    while pub.get_subscription_count() == 0 or node.count_publishers('/bench/back') == 0:
        rclpy.spin_once(node, timeout_sec=0.05)
    time.sleep(1.0)
    import numpy as np
    A = np.linalg.qr(np.random.default_rng(0).standard_normal((200, 200)))[0]
    x = np.ones(200)
    def round_trip():
        global x
        for _ in range(work):      # numeric work between round trips, as a plant step has
            x = A @ x
        before = len(got)
        msg = JointState(name=names, position=[0.0] * 15, velocity=[0.0] * 15)
        pub.publish(msg)
        t = time.monotonic()
        while len(got) == before:
            rclpy.spin_once(node, timeout_sec=0.2)
            if time.monotonic() - t > 0.2:
                pub.publish(msg)
                t = time.monotonic()
    for _ in range(100):
        round_trip()
    t0 = time.perf_counter()
    for _ in range(n):
        round_trip()
    print(n / (time.perf_counter() - t0))
rclpy.try_shutdown()
"""


def _row(name, value, unit, baseline, baseline_value, higher_better=True, note=''):
    ratio = (value / baseline_value if higher_better else baseline_value / value) \
        if baseline_value and value else float('nan')
    return {'name': name, 'value': value, 'unit': unit, 'baseline': baseline,
            'baseline_value': baseline_value, 'ratio': ratio, 'note': note}


def _timed(func) -> float:
    t0 = time.perf_counter()
    func()
    return time.perf_counter() - t0


def _best_times(funcs: dict, repeats: int) -> dict:
    """
    Shortest CPU time of each function over ``repeats`` interleaved rounds [s].

    Process CPU time, not wall time: on the shared 2-core machine a single-threaded run (BLAS
    is pinned to one thread) is descheduled for most of its wall time, unevenly between rounds.
    """
    best = dict.fromkeys(funcs, float('inf'))
    for _ in range(repeats):
        for name, func in funcs.items():
            t0 = time.process_time()
            func()
            best[name] = min(best[name], time.process_time() - t0)
    return best


def offline_rows(n_steps: int, repeats: int = 3) -> list[dict]:
    """
    Open and closed loop: our core vs control.forced_response and scipy.signal.dlsim.

    The libraries run the closed loop as one discrete system (A + B K C, dense); our core steps
    the modal plant and calls the laws every step, as the ROS run does. Each figure is the best
    of ``repeats`` interleaved rounds (the machine is shared).
    """
    model = demo_model(100, seed=1)
    plant = DiscretePlant(model.discretize(1 / RATE))
    rng = np.random.default_rng(0)
    exc = excitation_matrix(plant, TCP, 100 * rng.standard_normal((n_steps, 3)), n_steps)
    laws = [tcp_damper(['x', 'y', 'z'], 20000.0), strut_bending_damper([1, 2, 3, 4, 5], 2e3)]
    rows = []
    for label, use_laws in (('open loop', []), ('closed loop', laws)):
        a, b, c_y, _, _ = closed_loop_system(plant, use_laws)
        sys_d = control.ss(a, b, c_y, plant.d if use_laws == [] else np.zeros_like(plant.d),
                           1 / RATE)

        def ours(use_laws=use_laws):
            plant.reset()
            simulate(plant, use_laws, exc)

        best = _best_times({
            'forced_response': lambda: control.forced_response(sys_d, U=exc.T),
            'dlsim': lambda: scipy.signal.dlsim((a, b, c_y, np.zeros_like(plant.d), 1 / RATE),
                                                exc),
            'ours': ours}, repeats)
        update = 'modal 2x2-block' if plant.modal else 'dense'
        note = (f'{n_steps} steps, 200 states, 21 in, 39 out; best CPU time of {repeats} '
                f'interleaved rounds; {update} state update')
        rows += [
            _row(f'offline {label}, stepping core', n_steps / best['ours'], 'steps/s',
                 'control.forced_response', n_steps / best['forced_response'], note=note),
            _row(f'offline {label}, stepping core', n_steps / best['ours'], 'steps/s',
                 'scipy.signal.dlsim', n_steps / best['dlsim'], note=note)]
    return rows


def multirate_rows(n_exchanges: int, rate: float = 1000.0, substeps: int = 10,
                   repeats: int = 3) -> list[dict]:
    """
    Multi-rate closed loop (1 kHz exchange, 10 kHz plant) against the fine plant.

    Our core (:class:`MultiRatePlant` in :func:`simulate`) vs the fine-rate plant stepped N
    times per exchange with u held, full-rate outputs kept by both; same 100-mode model.
    """
    model = demo_model(100, seed=1)
    multi = MultiRatePlant.from_model(model, rate, substeps)
    fine = DiscretePlant(model.discretize(1 / (rate * substeps)))
    rng = np.random.default_rng(0)
    exc = excitation_matrix(multi, TCP, 100 * rng.standard_normal((n_exchanges, 3)),
                            n_exchanges)
    # gains of the 5 kHz rows lose stability at a 1 kHz exchange (spectral radius 5.3)
    laws = [tcp_damper(['x', 'y', 'z'], 5000.0), strut_bending_damper([1, 2, 3, 4, 5], 500.0)]
    bound = [([fine.output_index[p] for p in law.sensor_ports],
              [fine.input_index[p] for p in law.actuator_ports], law.step) for law in laws]

    def fine_steps():
        fine.reset()
        y_full = np.empty((n_exchanges, substeps, len(fine.output_names)))
        for k in range(n_exchanges):
            u = exc[k].copy()
            for sensors, actuators, step in bound:
                u[actuators] += step(fine.outputs()[sensors])
            for j in range(substeps):
                fine.outputs(y_full[k, j])
                fine.advance(u)

    def ours(full_rate=True):
        multi.reset()
        simulate(multi, laws, exc, full_rate=full_rate)

    best = _best_times({'fine': fine_steps, 'ours': ours,
                        'exchange only': lambda: ours(False)}, repeats)
    note = (f'{n_exchanges} exchanges at {rate:g} Hz, plant at {rate * substeps:g} Hz, 200 '
            f'states, TCP + strut dampers; best CPU time of {repeats} interleaved rounds')
    base = f'fine plant stepped {substeps}x per exchange'
    return [_row(f'offline multi-rate loop, {substeps} substeps, full-rate outputs',
                 n_exchanges / best['ours'], 'exchanges/s', base,
                 n_exchanges / best['fine'], note=note),
            _row(f'offline multi-rate loop, {substeps} substeps, exchange outputs only',
                 n_exchanges / best['exchange only'], 'exchanges/s', base,
                 n_exchanges / best['fine'], note=note)]


FIFO_PRIORITY = 10   # SCHED_FIFO priority of the real-time runs at machine rates (chrt)


#: Fast DDS transports of the separate-process real-time runs (``FASTDDS_BUILTIN_TRANSPORTS``):
#: the set-up with the fewest missed deadlines here, though not reliably below 0.1 %
#: (docs/nodes.md, "Real time in separate processes").
REALTIME_TRANSPORTS = 'UDPv4'


def pinned(prefix: list[str], cpu: int) -> list[str]:
    """``taskset -c cpu`` before ``prefix`` if that CPU and taskset exist, else ``prefix``."""
    if shutil.which('taskset') is None or cpu >= (os.cpu_count() or 1):
        return prefix
    return ['taskset', '-c', str(cpu)] + prefix


def fifo_prefix() -> list[str]:
    """``chrt -f FIFO_PRIORITY`` if this user may run processes so, else nothing."""
    try:
        ok = subprocess.run(['chrt', '-f', str(FIFO_PRIORITY), 'true'],
                            capture_output=True).returncode == 0
    except OSError:
        ok = False
    return ['chrt', '-f', str(FIFO_PRIORITY)] if ok else []


class Session:
    """Node processes on a private ROS domain (optionally under a command prefix); all killed."""

    def __init__(self, folder: Path, prefix: list[str] | None = None, **env: str):
        self.folder = folder
        self.prefix = prefix or []
        # a free domain reserved for the session, LOCALHOST discovery (unless already set)
        changes, self.lease = isolation(os.environ)
        self.env = dict(os.environ, **changes, **env)
        self.procs = []

    def start(self, args: list[str], log: str, prefix: list[str] | None = None
              ) -> subprocess.Popen:
        prefix = self.prefix if prefix is None else prefix
        proc = subprocess.Popen(prefix + [sys.executable] + args, env=self.env, text=True,
                                stdout=subprocess.PIPE if log == 'pipe' else
                                open(self.folder / log, 'w'), stderr=subprocess.STDOUT)
        self.procs.append(proc)
        return proc

    def node(self, module: str, name: str, *params: str, cpu: int | None = None
             ) -> subprocess.Popen:
        """Start a node (pinned to ``cpu`` if given, see :func:`pinned`)."""
        args = ['-m', module, '--ros-args', '-r', f'__node:={name}']
        for p in params:
            args += ['-p', p]
        prefix = self.prefix if cpu is None else pinned(self.prefix, cpu)
        return self.start(args, f'{name}.log', prefix)

    def close(self):
        for proc in self.procs:
            if proc.poll() is None:
                proc.terminate()
        for proc in self.procs:
            try:
                proc.wait(timeout=5)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
        if self.lease is not None:
            self.lease.release()


def _vm_hwm(pid: int) -> float:
    """Peak resident set size of a running process [bytes] (VmHWM of /proc/<pid>/status)."""
    try:
        for line in Path(f'/proc/{pid}/status').read_text().splitlines():
            if line.startswith('VmHWM:'):
                return float(line.split()[1]) * 1024.0
    except OSError:
        pass
    return 0.0


def wait_rss(proc: subprocess.Popen, timeout: float) -> tuple[int, float]:
    """
    Wait for a child, sampling its peak RSS until it ends; return (exit code, bytes).

    VmHWM is the process's own high-water mark (ru_maxrss of a child would include the
    parent's memory at fork time on Linux).
    """
    end, peak = time.monotonic() + timeout, 0.0
    while proc.poll() is None:
        peak = max(peak, _vm_hwm(proc.pid))
        if time.monotonic() > end:
            raise subprocess.TimeoutExpired(proc.args, timeout)
        time.sleep(0.02)
    return proc.returncode, peak


def _trace_figures(trace: Path, rss: float) -> dict:
    """The numeric scalars of a plant trace file (timing figures), and the peak RSS."""
    with np.load(trace) as data:
        return dict({k: float(data[k]) for k in data.files
                     if data[k].shape == () and data[k].dtype.kind in 'fiub'}, rss=rss)


def plant_run(folder: Path, model_file: Path, n_controllers: int, steps: int,
              timing: str = 'lockstep', rate: float = RATE, substeps: int = 1,
              prefix: list[str] | None = None, pin: bool = False, **env: str) -> dict:
    """
    Run the plant node with n damper nodes; return the figures of its trace file.

    ``pin``: the plant on CPU 0, the dampers on CPU 1 (:func:`pinned`); ``env``: extra
    environment of the nodes.
    """
    session = Session(folder, prefix, **env)
    trace = folder / f'trace_{timing}_{n_controllers}_{int(rate)}_{substeps}.npz'
    try:
        names = [f'damper{i}' for i in range(n_controllers)]
        for i, name in enumerate(names):
            session.node('pentapod_damper.nodes.damper_node', name, f'bending_struts:=[{i + 1}]',
                         'bending_gain:=100.0', cpu=1 if pin else None)
        plant = session.node('pentapod_sim.nodes.plant_node', 'plant',
                             f'model_file:={model_file}', f'steps:={steps}',
                             f'sample_rate:={rate}', f'timing:={timing}',
                             f'substeps:={substeps}', 'sources:=[' + ','.join(names) + ']',
                             f"output_file:='{trace}'", 'startup_timeout:=60.0',
                             cpu=0 if pin else None)
        code, rss = wait_rss(plant, 300)
        if code != 0:
            raise RuntimeError((folder / 'plant.log').read_text())
    finally:
        session.close()
    return _trace_figures(trace, rss)


def composed_run(folder: Path, model_file: Path, n_controllers: int, steps: int,
                 recorder: bool = False, timing: str = 'lockstep', rate: float = RATE,
                 substeps: int = 1, prefix: list[str] | None = None) -> dict:
    """Plant + n damper nodes (+ a recorder) in one process on one executor; trace figures."""
    from pentapod_sim.scenario.files import dump_params
    trace = folder / (f'trace_composed_{n_controllers}_{int(recorder)}_{timing}_{int(rate)}_'
                      f'{substeps}.npz')
    names = [f'damper{i}' for i in range(n_controllers)]
    doc = {name: {'ros__parameters': {'bending_struts': [i + 1], 'bending_gain': 100.0}}
           for i, name in enumerate(names)}
    doc['plant'] = {'ros__parameters': {
        'model_file': str(model_file), 'steps': steps, 'sample_rate': rate, 'sources': names,
        'output_file': str(trace), 'startup_timeout': 60.0, 'timing': timing,
        'substeps': substeps}}
    if recorder:
        doc['recorder'] = {'ros__parameters': {'output_dir': str(folder / 'bags'),
                                               'bag_name': f'composed_{n_controllers}'}}
        doc['plant']['ros__parameters']['wait_for_subscribers'] = ['recorder']
    path = folder / f'{trace.stem}.yaml'
    path.write_text(dump_params(doc))
    session = Session(folder, prefix)
    try:
        proc = session.start(['-m', 'pentapod_sim.nodes.composed', str(path)], 'composed.log')
        code, rss = wait_rss(proc, 300)
        if code != 0:
            raise RuntimeError((folder / 'composed.log').read_text())
    finally:
        session.close()
    return _trace_figures(trace, rss)


#: Matrix-vector products (200 x 200) the ping of the second ping-pong baseline does per round
#: trip: about the numeric work of a plant step between two publishes. The DDS publish of the
#: bare ping costs about 30 us, with this work about 55 us (its code runs cache-cold), as the
#: plant's does (docs/nodes.md, "Where a lockstep step's time goes").
PING_WORK = 3


def pingpong(folder: Path, n: int, work: int = 0) -> tuple[float, float]:
    """
    Bare rclpy ping-pong (default executor) between two processes.

    ``work``: matrix-vector products of a 200 x 200 matrix the ping does per round trip.
    Returns round trips/s and the peak RSS of the pong process [bytes].
    """
    session = Session(folder)
    try:
        pong = session.start(['-c', PINGPONG, 'pong', str(n), '0'], 'pong.log')
        ping = session.start(['-c', PINGPONG, 'ping', str(n), str(work)], 'pipe')
        out, _ = ping.communicate(timeout=300)
        return float(out.strip().splitlines()[-1]), _vm_hwm(pong.pid)
    finally:
        session.close()


MISS_TARGET = 0.001    # share of exchanges with a missed deadline that real time may have


def multirate_realtime_rows(folder: Path, model_file: Path, seconds: float,
                            rate: float = 1000.0) -> list[dict]:
    """
    Real time at machine rates: 1 kHz exchange with a 5 and a 10 kHz plant, one damper node.

    Separate processes and composed (one process, one executor); per run the share of
    exchanges with a missed deadline (target < 0.1 %), the share of overruns and the lateness
    of the period starts p50 / p99 against the exchange period. A missed deadline is a
    source's answer not in by the period's end, or by half a period after the step began if
    the plant was late (:data:`pentapod_sim.sim.realtime.ANSWER_WINDOW`); it leaves
    out the plant's own lateness, which the overruns count (a period started more than one
    period late). The node processes run at SCHED_FIFO priority
    ``FIFO_PRIORITY`` where allowed (a real-time setup; on this shared 2-core machine the
    other jobs' load otherwise descheduled them for milliseconds). In separate processes the
    plant and the damper are pinned to one CPU each and Fast DDS uses UDP only
    (:data:`REALTIME_TRANSPORTS`).
    """
    prefix = fifo_prefix()
    policy = (f'SCHED_FIFO {FIFO_PRIORITY}' if prefix else
              'normal scheduling (SCHED_FIFO not allowed)')
    rows = []
    n = int(seconds * rate)
    period_us = 1e6 / rate
    for substeps in (5, 10):
        for where in ('separate processes', 'composed'):
            if where == 'composed':
                res = composed_run(folder, model_file, 1, n, timing='realtime', rate=rate,
                                   substeps=substeps, prefix=prefix)
            else:
                res = plant_run(folder, model_file, 1, n, 'realtime', rate, substeps, prefix,
                                pin=True, FASTDDS_BUILTIN_TRANSPORTS=REALTIME_TRANSPORTS)
            label = (f'realtime {rate / 1000:g} kHz exchange, {rate * substeps / 1000:g} kHz '
                     f'plant, {where}')
            setup = policy if where == 'composed' else (
                f'{policy}, plant and damper pinned to one CPU each, Fast DDS transport '
                f'{REALTIME_TRANSPORTS} only')
            note = (f'{n} exchanges ({seconds:g} s), plant + 1 damper, 200 states, full-rate '
                    f'outputs kept in the trace, processes at {setup}; achieved '
                    f'{res["achieved_rate"]:.1f} Hz, '
                    f'{int(res["missed_steps"])} missed deadlines, lateness max '
                    f'{res["lateness_max"] * 1e6:.0f} us, {int(res["overruns"])} overruns')
            rows += [
                _row(f'{label}: missed deadlines', res['missed_steps'] / n, 'share',
                     'target', MISS_TARGET, higher_better=False,
                     note=note + '; a miss: an answer later than the period end or, for a '
                     'late step, half a period after it began; the plant being late is counted '
                     'as overruns'),
                _row(f'{label}: overruns', res['overruns'] / n, 'share', 'target',
                     MISS_TARGET, higher_better=False,
                     note=note + '; an overrun: a period that started more than one period '
                     'late (the plant lost its CPU, it then catches up)'),
                _row(f'{label}: lateness p50', res['lateness_p50'] * 1e6, 'us',
                     'exchange period', period_us, higher_better=False, note=note),
                _row(f'{label}: lateness p99', res['lateness_p99'] * 1e6, 'us',
                     'exchange period', period_us, higher_better=False, note=note)]
    return rows


def composed_rows(folder: Path, model_file: Path, steps: int, base: float) -> list[dict]:
    """Lockstep composed runs (plant + 1 controller; + 3 and a recorder) against ``base``."""
    rows = []
    for n_ctrl, rec in ((1, False), (3, True)):
        res = composed_run(folder, model_file, n_ctrl, steps, rec)
        extra = ' + recorder' if rec else ''
        rows.append(_row(f'lockstep composed, plant + {n_ctrl} controller{extra}',
                         steps / res['wall_time'], 'steps/s',
                         'rclpy ping-pong, 2 processes, default executor', base,
                         note=f'{steps} steps, 200 states; every node in one process on one '
                              'EventsExecutor (scenario --composed), plant and controllers '
                              'hand over in-process (no DDS)' + (
                                  '; the recorder takes every per-step message over DDS'
                                  if rec else '')))
    return rows


def warm_start_rows(folder: Path, model_file: Path, steps: int, rounds: int) -> list[dict]:
    """
    Wall time of a short composed run started fresh and forked warm (the study's runs).

    Plant + 1 damper + recorder, through the scenario runner as the study starts them
    (:func:`pentapod_sim.scenario.runner.run_scenario`), rounds interleaved, best of each.
    """
    from pentapod_sim.scenario.files import dump_params
    from pentapod_sim.scenario.runner import run_scenario
    from pentapod_sim.scenario.warm_start import WarmStarter
    warm = WarmStarter()
    doc = {'damper0': {'ros__parameters': {'bending_struts': [1], 'bending_gain': 100.0}},
           'plant': {'ros__parameters': {
               'model_file': str(model_file), 'steps': steps, 'sample_rate': RATE,
               'sources': ['damper0'], 'startup_timeout': 60.0,
               'wait_for_subscribers': ['recorder']}},
           'recorder': {'ros__parameters': {'output_dir': str(folder / 'warm_bags'),
                                            'bag_name': 'run'}}}
    path = folder / 'warm_start.yaml'
    path.write_text(dump_params(doc))
    best = {'fresh': np.inf, 'warm': np.inf}
    def run(starter) -> float:
        shutil.rmtree(folder / 'warm_bags', ignore_errors=True)
        t0 = time.perf_counter()
        code = run_scenario(path, {}, 120.0, log_dir=folder / 'warm_logs', composed=True,
                            warm=starter)
        if code != 0:
            raise RuntimeError((folder / 'warm_logs' / 'composition.log').read_text())
        return time.perf_counter() - t0
    run(warm)                           # the forkserver's own start: not timed
    for _ in range(rounds):
        for mode in best:
            best[mode] = min(best[mode], run(warm if mode == 'warm' else None))
    return [_row('study: composed run started warm', best['warm'], 's',
                 'the same run started fresh', best['fresh'], higher_better=False,
                 note=f'{steps} lockstep steps, plant + 1 damper + recorder, 200 states, '
                      'whole run through the scenario runner (start, run, bag closed, exit); '
                      'warm: forked from a forkserver that imported the node modules once '
                      f'(pentapod_sim/scenario/warm_start.py); best of {rounds} interleaved '
                      'rounds')]


def composed_only(quick: bool) -> list[dict]:
    """The ping-pong and the composed rows alone (``--composed``; saves nothing)."""
    steps = 3000 if quick else 20000
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        model_file = demo_model(100, seed=1).save(folder / 'model.npz')
        base, _ = pingpong(folder, steps)
        return composed_rows(folder, model_file, steps, base)


def best_of(rounds: int, runs: dict) -> dict:
    """Run each callable of ``runs`` once per round, interleaved; keep each one's best result."""
    best: dict = {}
    for _ in range(rounds):
        for key, run in runs.items():
            rate, extra = run()
            if key not in best or rate > best[key][0]:
                best[key] = (rate, extra)
    return best


def ros_rows(quick: bool) -> list[dict]:
    """Lockstep steps/s and real-time figures."""
    steps = 3000 if quick else 20000
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        model_file = demo_model(100, seed=1).save(folder / 'model.npz')
        rounds = 1 if quick else 3

        def lockstep(n_ctrl):
            res = plant_run(folder, model_file, n_ctrl, steps)
            return steps / res['wall_time'], res
        best = best_of(rounds, {'base': lambda: pingpong(folder, steps),
                                'work': lambda: pingpong(folder, steps, PING_WORK),
                                1: lambda: lockstep(1), 3: lambda: lockstep(3)})
        (base, base_rss), work = best['base'], best['work'][0]
        for n_ctrl in (1, 3):
            rate, res = best[n_ctrl]
            if n_ctrl == 1:
                rows.append(_row('plant node peak RSS (lockstep run)', res['rss'] / 2 ** 20,
                                 'MiB', 'bare rclpy node (ping-pong pong)', base_rss / 2 ** 20,
                                 higher_better=False, note='VmHWM of the process; the '
                                 'plant imports numpy, scipy and python-control'))
            note = (f'{steps} steps, 200 states; each step: strut_states out (the only '
                    f'subscribed topic), {n_ctrl} answer(s) in, taken by polling in '
                    f'{res.get("answers_polled", 0) / steps:.0%} of the steps (the plant '
                    'polls while every node that works each step has a CPU, '
                    f'{usable_cpus()} here); best of {rounds} rounds, interleaved with the '
                    'baselines')
            rows.append(_row(f'lockstep plant + {n_ctrl} controller node(s)', rate, 'steps/s',
                             'rclpy ping-pong, 2 processes, default executor', base,
                             note=note))
            rows.append(_row(f'lockstep plant + {n_ctrl} controller node(s)', rate, 'steps/s',
                             f'rclpy ping-pong, 2 processes, default executor, {PING_WORK} '
                             'matrix-vector products (200 states) per round trip', work,
                             note=note + "; the plant step's numeric work in the ping"))
        rows += composed_rows(folder, model_file, steps, base)
        rows += warm_start_rows(folder, model_file, 2000, 2 if quick else 3)
        seconds = 1.0 if quick else 5.0
        for rate in (1000.0, 5000.0, 10000.0):
            res = plant_run(folder, model_file, 1, int(seconds * rate), 'realtime', rate,
                            pin=True, FASTDDS_BUILTIN_TRANSPORTS=REALTIME_TRANSPORTS)
            rows.append(_row(f'realtime {rate / 1000:g} kHz achieved rate',
                             res['achieved_rate'], 'Hz', 'target', rate,
                             note=f'lateness p50 {res["lateness_p50"] * 1e6:.0f} us, '
                                  f'p99 {res["lateness_p99"] * 1e6:.0f} us, max '
                                  f'{res["lateness_max"] * 1e6:.0f} us, '
                                  f'{int(res["overruns"])} overruns, '
                                  f'{int(res.get("missed_steps", 0))} missed deadlines of '
                                  f'{int(seconds * rate)} steps (plant + 1 damper, pinned to '
                                  f'one CPU each, Fast DDS {REALTIME_TRANSPORTS} only)'))
        rows += multirate_realtime_rows(folder, model_file, 5.0 if quick else 60.0)
    return rows


def run(quick: bool) -> list[dict]:
    """All plant benchmarks (quick: about a minute)."""
    return (offline_rows(20000 if quick else 100000)
            + multirate_rows(2000 if quick else 10000) + ros_rows(quick))


if __name__ == '__main__':
    parser = CommandParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--quick', action='store_true', help='short version (about a minute)')
    parser.add_argument('--offline', action='store_true',
                        help='only the offline rows (no ROS); prints them, saves nothing')
    parser.add_argument('--composed', action='store_true',
                        help='only the ping-pong and the lockstep composed rows; prints them, '
                        'saves nothing')
    args = parser.parse_args()
    steps = 20000 if args.quick else 100000
    if args.composed:
        rows = composed_only(args.quick)
    elif args.offline:
        rows = offline_rows(steps) + multirate_rows(steps // 10)
    else:
        rows = run(args.quick)
    for r in rows:
        print(f'{r["name"]}: {r["value"]:.4g} {r["unit"]} | {r["baseline"]}: '
              f'{r["baseline_value"]:.4g} | ratio {r["ratio"]:.3g} | {r["note"]}')
