"""
The plant polls for its sources' answers (lockstep, separate processes) only while it pays.

Polling (:mod:`pentapod_sim.nodes.answer_poll`) takes the answers straight from the force
subscriptions; it must change nothing in a trace, keep the plant's timers running (the run
status) although the executor no longer waits, and stop as soon as another node that works
each step joins (its CPU is then needed). The nodes of one process count once.
"""
import threading
import time

import numpy as np
import pytest

from fixtures.demo_model import demo_model
from fixtures.processes import NodeProcesses
from pentapod_sim import interface
from pentapod_sim.nodes.answer_poll import polling_pays, usable_cpus
from pentapod_sim.sim.closed_loop import excitation_matrix, simulate
from pentapod_sim.sim.excitation import Excitation, ExcitationSpec
from pentapod_sim.sim.stepping import DiscretePlant

pytestmark = [pytest.mark.ros]

RATE = 5000.0
TCP = ['tcp_force_x', 'tcp_force_y', 'tcp_force_z']
EXCITER = ('kind:=random', 'amplitude:=50.0', 'direction:=[1.0, 0.5, 0.0]', 'duration:=1.0',
           'f_start:=5.0', 'f_end:=400.0', 'seed:=3', f'sample_rate:={RATE}')


def test_polling_pays_only_while_every_busy_node_has_a_cpu():
    assert polling_pays(1e-3, cpus=2, peers=1)
    assert not polling_pays(1e-3, cpus=2, peers=2)        # plant + damper + recorder
    assert not polling_pays(1e-3, cpus=2, peers=3)        # plant + 3 dampers
    assert polling_pays(1e-3, cpus=8, peers=3)
    assert not polling_pays(0.0, cpus=8, peers=1)         # answer_poll_time = 0: never
    assert not polling_pays(1e-3, cpus=1, peers=1)


class Listener:
    """An rclpy node in this process, spun in a thread, that keeps what it receives."""

    def __init__(self, env, *others):
        """``others``: node factories ``f(context)``, spun with the listener."""
        import rclpy
        from rclpy.node import Node

        from pentapod_sim.nodes.common import make_executor
        self.rclpy, self.ctx = rclpy, rclpy.Context()
        rclpy.init(context=self.ctx, domain_id=int(env['ROS_DOMAIN_ID']))
        self.node = Node('poll_test_listener', context=self.ctx)
        self.executor = make_executor(self.ctx)
        self.nodes = [self.node, *(make(self.ctx) for make in others)]
        for node in self.nodes:
            self.executor.add_node(node)
        self.received: dict[str, list] = {}
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._spin, daemon=True)
        self._thread.start()

    def subscribe(self, msg_type, topic: str, qos):
        """Keep (arrival time, message) of every message on ``topic``; the subscription."""
        got = self.received.setdefault(topic, [])
        return self.node.create_subscription(msg_type, topic,
                                             lambda m: got.append((time.monotonic(), m)), qos)

    def _spin(self):
        while not self._stop.is_set():
            self.executor.spin_once(timeout_sec=0.05)

    def close(self):
        """
        Stop spinning and destroy the nodes.

        A node left alive keeps its DDS participant, and its publishers stayed in the graph of
        every later test of the session (a second /exciter refused their runs).
        """
        self._stop.set()
        self._thread.join(timeout=5)
        self.executor.shutdown()
        for node in self.nodes:
            node.destroy_node()
        self.rclpy.shutdown(context=self.ctx)


def _plant(procs, model_file, steps, trace, *extra):
    return procs.start('plant', 'pentapod_sim.nodes.plant_node', f'model_file:={model_file}',
                       f'steps:={steps}', f'sample_rate:={RATE}', 'sources:=[exciter]',
                       f"output_file:='{trace}'", 'startup_timeout:=60.0', *extra)


def _wall(log: str) -> float:
    """Wall time of the run from the plant's summary line [s]."""
    line = next(ln for ln in log.splitlines() if 'steps in' in ln)
    return float(line.split('steps in ')[1].split(' s wall')[0])


def test_a_polled_run_equals_a_blocking_one_and_the_offline_loop_bit_for_bit(tmp_path):
    """Plant + exciter: polled (the default) and blocking runs give the offline loop's bits."""
    from diagnostic_msgs.msg import DiagnosticStatus

    from pentapod_sim.nodes.common import qos
    model = demo_model(8, seed=5)
    model_file = model.save(tmp_path / 'model.npz')
    steps, period = 8000, 0.1
    polls = polling_pays(1e-3, usable_cpus(), 1)
    traces = {}
    for mode, extra in (('default', ()), ('blocking', ('answer_poll_time:=0.0',))):
        folder = tmp_path / mode
        folder.mkdir()
        procs = NodeProcesses(folder)
        listener = Listener(procs.env)
        status = listener.subscribe(DiagnosticStatus, interface.RUN_STATUS, qos('status'))
        try:
            traces[mode] = folder / 'trace.npz'
            _plant(procs, model_file, steps, traces[mode], f'status_period:={period}', *extra)
            end = time.monotonic() + 60     # the run starts with the exciter: listen first
            while status.get_publisher_count() == 0:
                assert time.monotonic() < end, procs.log('plant')
                time.sleep(0.05)
            procs.start('exciter', 'pentapod_sim.nodes.exciter_node', *EXCITER)
            assert procs.wait('plant') == 0, procs.log('plant')
            time.sleep(0.5)                 # the last status messages
        finally:
            procs.close()
            listener.close()
        log = procs.log('plant')
        expected = ('answers: blocking (answer_poll_time = 0)' if mode == 'blocking' else
                    'answers: polled' if polls else 'answers: blocking')
        assert expected in log, log
        # the run status keeps coming every period while the plant polls: its timer still runs
        # (the first one is sent at the start, the last one says finished)
        times = [t for t, m in listener.received[interface.RUN_STATUS]
                 if {kv.key: kv.value for kv in m.values}['state'] in
                 (interface.RUN_RUNNING, interface.RUN_FINISHED)]
        assert len(times) >= _wall(log) / period, (len(times), log)
        assert np.diff(times).max() < 3 * period, (np.diff(times), log)

    runs = {mode: np.load(path) for mode, path in traces.items()}
    plant = DiscretePlant(model.discretize(1 / RATE))
    exc = Excitation(ExcitationSpec('random', 50.0, [1.0, 0.5, 0.0], f_start=5.0, f_end=400.0,
                                    duration=1.0, seed=3), 1 / RATE)
    ref = simulate(plant, [], excitation_matrix(plant, TCP, exc.series(steps), steps))
    assert np.any(ref.y)
    for mode, run in runs.items():
        assert np.array_equal(run['u'], ref.u), mode
        assert np.array_equal(run['y'], ref.y), mode


def test_a_node_subscribing_mid_run_turns_polling_off(tmp_path):
    """A subscriber of a per-step topic joins: the plant blocks from then on, and says so."""
    from sensor_msgs.msg import JointState

    from pentapod_sim.nodes.common import STATE_SUB_QOS
    model_file = demo_model(8, seed=5).save(tmp_path / 'model.npz')
    procs = NodeProcesses(tmp_path)
    listener = None
    try:
        procs.start('exciter', 'pentapod_sim.nodes.exciter_node', *EXCITER)
        _plant(procs, model_file, 10 ** 7, tmp_path / 'trace.npz')
        end = time.monotonic() + 60
        while 'run of' not in procs.log('plant'):
            assert time.monotonic() < end and procs.procs['plant'].poll() is None, \
                procs.log('plant')
            time.sleep(0.1)
        if not polling_pays(1e-3, usable_cpus(), 1):
            assert 'answers: blocking' in procs.log('plant')   # one CPU: never polls
            return
        while 'answers: polled (1 other process(es)' not in procs.log('plant'):
            assert time.monotonic() < end, procs.log('plant')
            time.sleep(0.1)
        listener = Listener(procs.env)
        listener.subscribe(JointState, interface.TCP_STATE, STATE_SUB_QOS)
        end = time.monotonic() + 30
        while 'on, answers: blocking (2 other process(es)' not in procs.log('plant'):
            assert time.monotonic() < end, procs.log('plant')
            time.sleep(0.1)
        while not listener.received[interface.TCP_STATE]:   # and it does get the states
            assert time.monotonic() < end, procs.log('plant')
            time.sleep(0.1)
        assert procs.procs['plant'].poll() is None
    finally:
        procs.close()
        if listener is not None:
            listener.close()


def test_the_nodes_of_one_process_count_once(tmp_path):
    """The exciter and a subscriber of the states in one process: one busy peer, still polled."""
    from sensor_msgs.msg import JointState

    from pentapod_sim.nodes.common import STATE_SUB_QOS
    from pentapod_sim.nodes.exciter_node import ExciterNode
    model_file = demo_model(8, seed=5).save(tmp_path / 'model.npz')
    procs = NodeProcesses(tmp_path)
    args = ['--ros-args'] + [a for p in EXCITER for a in ('-p', p)]
    listener = Listener(procs.env, lambda ctx: ExciterNode(context=ctx, cli_args=args))
    try:
        listener.subscribe(JointState, interface.TCP_STATE, STATE_SUB_QOS)
        _plant(procs, model_file, 10 ** 7, tmp_path / 'trace.npz')
        end = time.monotonic() + 60
        while not listener.received.get(interface.TCP_STATE):
            assert time.monotonic() < end and procs.procs['plant'].poll() is None, \
                procs.log('plant')
            time.sleep(0.1)
        time.sleep(1.0)                      # several looks at the graph (every 0.25 s)
        log = procs.log('plant')
    finally:
        procs.close()
        listener.close()
    # the exciter's node and the listener's: two nodes, one process
    expected = ('answers: polled (1 other process(es)' if polling_pays(1e-3, usable_cpus(), 1)
                else 'answers: blocking (1 other process(es)')
    assert expected in log and 'answers: blocking (2' not in log, log
