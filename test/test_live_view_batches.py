"""
The plant's display batches and the live view on them.

ROS-free part: a plant core and force mixer drive :class:`DisplayBatches` with a publisher
that keeps the bytes; the batches, decoded both with rclpy's deserialiser and with the live
view's :class:`BatchStream`, must give back every step's values and stamp bit for bit (3 kHz:
stamps are no multiple of a whole-ns step), also across a partial batch at the end and a source
that changes its ports.

ROS part: a lockstep run (plant in this process, exciter and live view in their own) where
only the live view and a batch reader subscribe. The plant must publish none of its state
topics on DDS (before the display batches, the live view's subscriptions made it publish
every one every step), the batches must hold every step of the trace bit for bit, and the
values the view serves on /pentapod/tcp_state and the exciter's force channel must be the
trace's values at their stamps.
"""
import array
import os
from pathlib import Path
import re
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from fixtures.demo_model import demo_model, load_cell_model
from fixtures.foxglove_client import decoder, FoxgloveClient
from pentapod_sim import interface
from pentapod_sim.interface import stamp_ns, state_layouts
from pentapod_sim.live.streams import BatchStream
from pentapod_sim.sim.multirate import MultiRatePlant
from pentapod_sim.sim.stepping import ForceMixer, ForceSource
from pentapod_sim.topic_layout import split_batch_name


class KeptPublisher:
    """A publisher that keeps what it is given and always has a subscriber."""

    def __init__(self, topic: str):
        self.topic_name, self.sent = topic, []

    def publish(self, data: bytes) -> None:
        assert isinstance(data, bytes)
        self.sent.append(data)

    def get_subscription_count(self) -> int:
        return 1


class FakeNode:
    def __init__(self):
        self.pubs = {}

    def create_publisher(self, msg_type, topic, profile):
        self.pubs[topic] = KeptPublisher(topic)
        return self.pubs[topic]


def joint_values(msg) -> dict:
    """{(joint, sample): (position, velocity, effort)} of a deserialised batch."""
    out = {}
    fields = [list(getattr(msg, f)) for f in ('position', 'velocity', 'effort')]
    for i, name in enumerate(msg.name):
        joint, sample = split_batch_name(name)
        out[(joint, sample)] = tuple(f[i] if f else None for f in fields)
    return out


def test_batches_carry_every_step_bit_for_bit():
    from rclpy.serialization import deserialize_message
    from sensor_msgs.msg import JointState

    from pentapod_sim.nodes.display_batch import DisplayBatches
    rate, steps = 3000.0, 50
    core = MultiRatePlant.from_model(load_cell_model(4, seed=3), rate)     # strut efforts too
    mixer = ForceMixer(core.input_names, [ForceSource('a'), ForceSource('b')])
    node = FakeNode()
    batches = DisplayBatches(node, core, mixer, period=0.004)        # 12 steps per batch
    assert batches.size == 12
    batches.refresh()
    rng = np.random.default_rng(1)
    states, forces = {}, {'a': {}, 'b': {}}
    for k in range(steps):
        y = core.outputs()
        for lay in state_layouts(core.output_names):
            states.setdefault(lay.topic, {})[stamp_ns(k, core.dt)] = (lay.joints,
                                                                     *lay.values(y))
        # the mixer takes only the source's ports (in any order): the order changes
        ports_b = ['tcp_force_z', 'tcp_force_x'] if k < 30 else ['tcp_force_x', 'tcp_force_z']
        for source, ports in (('a', ['tcp_force_y', 'tcp_force_x']), ('b', ports_b)):
            efforts = array.array('d', rng.normal(size=len(ports)) * 10.0 ** rng.integers(-9, 3))
            assert mixer.submit(source, list(ports), efforts, k, k) is None
            forces[source][stamp_ns(k, core.dt)] = (ports, list(efforts))
        batches.record(k, y)
        core.advance(mixer.total())
    batches.flush()
    assert batches.count == 0 and batches.published == len(
        [m for p in node.pubs.values() for m in p.sent])
    for topic, per_step in states.items():
        sent = node.pubs[interface.display_batch_topic(topic)].sent
        assert len(sent) == 5               # steps 0-11, 12-23, 24-29 (cut), 30-41, 42-49
        seen = {}
        for data in sent:
            msg = deserialize_message(data, JointState)
            assert msg.header.frame_id == repr(core.dt)
            assert bool(msg.effort) == (topic == interface.STRUT_STATES)
            first = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
            k0 = interface.step_of(first, core.dt)
            for (joint, j), values in joint_values(msg).items():
                seen.setdefault(stamp_ns(k0 + j, core.dt), {})[joint] = values
        assert sorted(seen) == sorted(per_step)
        for stamp, (joints, *fields) in per_step.items():
            for f, values in enumerate(fields):       # position, velocity, effort
                got = [seen[stamp][j][f] for j in joints]
                if values.size:
                    assert np.array_equal(np.array(got), values, equal_nan=True), (topic, f)
                else:
                    assert got == [None] * len(joints), (topic, f)
        # the live view's decoder gives the same stamps and rows
        stream = BatchStream(topic, interface.JOINT_STATE, 10**7, 100)
        stamps, rows = stream.decode(sent)
        assert stamps.tolist() == sorted(per_step) and stream.samples == 8
        expected = np.array([np.concatenate(per_step[t][1:]) for t in stamps.tolist()])
        assert np.array_equal(rows, expected, equal_nan=True)
        assert stream.shape.names == per_step[stamps[0]][0] and stream.shape.frame_id == ''
    for source, per_step in forces.items():
        sent = node.pubs[interface.display_batch_topic(interface.force_topic(source))].sent
        seen = {}
        for data in sent:
            msg = deserialize_message(data, JointState)
            assert not msg.position and not msg.velocity
            k0 = interface.step_of(msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec,
                                   core.dt)
            ports = list(dict.fromkeys(split_batch_name(n)[0] for n in msg.name))
            for (joint, j), (_, _, effort) in joint_values(msg).items():
                step = seen.setdefault(stamp_ns(k0 + j, core.dt), ([], []))
                step[0].append(joint)
                step[1].append(effort)
            assert ports in (['tcp_force_y', 'tcp_force_x'], ['tcp_force_z', 'tcp_force_x'],
                             ['tcp_force_x', 'tcp_force_z'])
        assert seen == {t: (list(p), e) for t, (p, e) in per_step.items()}
    # b's port order changed at step 30: the batch of steps 24-35 was cut at 30, for every topic
    b_sent = node.pubs[interface.display_batch_topic(interface.force_topic('b'))].sent
    sizes = [len(deserialize_message(d, JointState).name) for d in b_sent]
    assert sizes == [12 * 2, 12 * 2, 6 * 2, 12 * 2, 8 * 2]


def test_batch_stream_counts_the_steps_of_lost_batches():
    stream = BatchStream(interface.TCP_STATE, interface.JOINT_STATE, 10**7, 3)
    stream.samples = 20
    stream.offer(b'1', 1)
    stream.offer(b'2', 4)                    # batches 2 and 3 never arrived
    assert stream.dropped == 40
    stream.offer(b'3', 5)
    stream.offer(b'4', 6)                    # backlog of 3 full: one more batch lost
    assert stream.dropped == 60 and len(stream.queue) == 3


# --- a lockstep run with only the live view attached ------------------------------------------

RATE, STEPS = 5000.0, 3000


def _start(folder: Path, name: str, module: str, *params: str) -> subprocess.Popen:
    cmd = [sys.executable, '-m', module, '--ros-args', '-r', f'__node:={name}']
    for p in params:
        cmd += ['-p', p]
    return subprocess.Popen(cmd, stdout=open(folder / f'{name}.log', 'w'),
                            stderr=subprocess.STDOUT, env=dict(os.environ))


def _port(log: Path, proc, timeout: float = 60.0) -> int:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        found = re.search(r'server on ws://127\.0\.0\.1:(\d+)', log.read_text())
        if found:
            return int(found.group(1))
        assert proc.poll() is None, log.read_text()
        time.sleep(0.1)
    raise TimeoutError(log.read_text())


def _stamp(msg) -> int:
    return msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec


def _last_step(msg, dt: float) -> int:
    """Step of the last sample of a batch."""
    return interface.step_of(_stamp(msg), dt) + max(j for _, j in joint_values(msg))


@pytest.fixture(scope='module')
def viewed_run(tmp_path_factory):
    """Plant (this process) + exciter + live view; counters, batches, served messages, trace."""
    import rclpy
    from rclpy.node import Node
    from sensor_msgs.msg import JointState

    from pentapod_sim.nodes import plant_node
    from pentapod_sim.nodes.common import make_executor, qos, spin_until
    folder = tmp_path_factory.mktemp('batches')
    model_file = demo_model(8, seed=4).save(folder / 'model.npz')
    trace = folder / 'trace.npz'
    procs = {'live_view': _start(folder, 'live_view', 'pentapod_sim.nodes.live_view_node',
                                 'port:=0', 'discovery_period:=0.1', 'idle_flush:=0.2')}
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=int(os.environ['ROS_DOMAIN_ID']))
    try:
        client = FoxgloveClient(f'ws://127.0.0.1:'
                                f'{_port(folder / "live_view.log", procs["live_view"])}').start()
        procs['exciter'] = _start(folder, 'exciter', 'pentapod_sim.nodes.exciter_node',
                                  'kind:=random', 'amplitude:=50.0', 'direction:=[1.0, 0.3, 0.5]',
                                  'f_start:=5.0', 'f_end:=800.0', 'duration:=0.5', 'seed:=3',
                                  f'sample_rate:={RATE}')
        client.wait_for_topics([interface.TCP_STATE, interface.force_topic('exciter')], 60.0)
        plant = plant_node.PlantNode(context=ctx, cli_args=[
            '--ros-args', '-p', f'model_file:={model_file}', '-p', f'steps:={STEPS}',
            '-p', f'sample_rate:={RATE}', '-p', 'sources:=[exciter]', '-p', "loop_check:='off'",
            '-p', f"output_file:='{trace}'", '-p', 'startup_timeout:=60.0',
            '-p', 'wait_for_subscribers:=[live_view, batch_reader]'])
        reader = Node('batch_reader', context=ctx)
        batches: dict[str, list] = {}
        topics = [interface.display_batch_topic(t) for t in
                  (*interface.STATE_TOPICS, interface.force_topic('exciter'))]
        for topic in topics:
            reader.create_subscription(JointState, topic,
                                       lambda m, t=topic: batches.setdefault(t, []).append(m),
                                       qos('display'))
        executor = make_executor(ctx)
        executor.add_node(plant)
        executor.add_node(reader)
        plant_node.run(plant, executor)
        layouts = interface.state_layouts(plant.core.output_names)
        assert spin_until(executor, lambda: len(batches) == len(layouts) + 1 and all(
            _last_step(m[-1], 1 / RATE) == STEPS - 1 for m in batches.values()), 30.0)
        counts = plant.outputs.dds_published()
        published = plant.outputs.display_batches()[1]
        time.sleep(1.0)                                         # the view's last windows
        client.stop()
        executor.shutdown()
        plant.destroy_node()
        reader.destroy_node()
    finally:
        rclpy.try_shutdown(context=ctx)
        for proc in procs.values():
            if proc.poll() is None:
                proc.send_signal(signal.SIGINT)
            try:
                proc.wait(timeout=20)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
    served = {}
    for topic in (interface.TCP_STATE, interface.force_topic('exciter')):
        decode = decoder(client.channels[client.topic_ids()[topic]])
        served[topic] = [(t, decode(p)) for t, p in client.of_topic(topic)]
    return {'counts': counts, 'published': published, 'batches': batches, 'served': served,
            'trace': dict(np.load(trace)), 'layouts': layouts,
            'log': (folder / 'live_view.log').read_text()}


def test_plant_publishes_no_state_topic_for_the_live_view(viewed_run):
    counts = viewed_run['counts']
    assert {t: c for t, c in counts.items() if t != interface.CLOCK} == dict.fromkeys(
        interface.STATE_TOPICS, 0), counts
    assert counts[interface.CLOCK] >= STEPS          # the exciter reads /clock
    # the state topics and the exciter's forces, 50 steps per batch
    assert viewed_run['published'] == (len(viewed_run['layouts']) + 1) * STEPS // 50
    assert f'serving {interface.TCP_STATE} [{interface.JOINT_STATE}] from ' \
        f'{interface.display_batch_topic(interface.TCP_STATE)}' in viewed_run['log']


def test_batches_of_the_run_are_the_trace_bit_for_bit(viewed_run):
    trace, batches = viewed_run['trace'], viewed_run['batches']
    dt, y, u = float(trace['dt']), trace['y'], trace['u']
    assert len(y) == STEPS
    stamps = [stamp_ns(k, dt) for k in range(STEPS)]
    for lay in viewed_run['layouts']:
        seen = {}
        for msg in batches[interface.display_batch_topic(lay.topic)]:
            k0 = interface.step_of(_stamp(msg), dt)
            for (joint, j), (pos, vel, _) in joint_values(msg).items():
                seen.setdefault(stamp_ns(k0 + j, dt), {})[joint] = (pos, vel)
        assert sorted(seen) == stamps, lay.topic
        for k, stamp in enumerate(stamps):
            pos, vel, _ = lay.values(y[k])
            got = np.array([seen[stamp][j] for j in lay.joints])
            assert np.array_equal(got, np.stack([pos, vel], axis=1), equal_nan=True), (lay, k)
    names = list(trace['input_names'])
    seen = {}
    for msg in batches[interface.display_batch_topic(interface.force_topic('exciter'))]:
        k0 = interface.step_of(_stamp(msg), dt)
        for (port, j), (_, _, effort) in joint_values(msg).items():
            seen.setdefault(k0 + j, {})[port] = effort
    assert sorted(seen) == list(range(STEPS))
    for k, efforts in seen.items():         # the only source: u_k is its force, bit for bit
        assert all(u[k, names.index(p)] == e for p, e in efforts.items()), k
        assert np.count_nonzero(u[k]) <= len(efforts)


def test_the_view_serves_the_trace_values_at_their_stamps(viewed_run):
    """Every served envelope value is a value of the trace in its 10 ms window."""
    trace = viewed_run['trace']
    dt, y, u = float(trace['dt']), trace['y'], trace['u']
    window_of = np.array([stamp_ns(k, dt) for k in range(len(y))]) // 10_000_000
    tcp = next(lay for lay in viewed_run['layouts'] if lay.topic == interface.TCP_STATE)
    names = list(trace['input_names'])
    shown = viewed_run['served'][interface.TCP_STATE]
    forces = viewed_run['served'][interface.force_topic('exciter')]
    assert len(shown) >= STEPS * dt * 100 and len(forces) >= STEPS * dt * 100
    for log_time, msg in shown:
        k = interface.step_of(_stamp(msg), dt)
        assert log_time == _stamp(msg) == stamp_ns(k, dt) and list(msg.name) == tcp.joints
        window = np.flatnonzero(window_of == window_of[k])
        recorded = np.array([np.concatenate(tcp.values(y[j])) for j in window])
        values = np.concatenate([list(msg.position), list(msg.velocity)])
        assert all(v in recorded[:, col] for col, v in enumerate(values)), k
    for log_time, msg in forces:
        k = interface.step_of(_stamp(msg), dt)
        assert log_time == _stamp(msg) == stamp_ns(k, dt)
        window = np.flatnonzero(window_of == window_of[k])
        assert all(e in u[window, names.index(p)] for p, e in zip(msg.name, msg.effort)), k


def test_without_a_client_the_view_subscribes_to_nothing(tmp_path):
    """No client: the plant publishes no display batch; a client watching makes it publish."""
    import rclpy

    from pentapod_sim.nodes import plant_node
    from pentapod_sim.nodes.common import make_executor, spin_until
    model_file = demo_model(4, seed=2).save(tmp_path / 'model.npz')
    view = _start(tmp_path, 'live_view', 'pentapod_sim.nodes.live_view_node', 'port:=0',
                  'discovery_period:=0.1')
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=int(os.environ['ROS_DOMAIN_ID']))
    try:
        port = _port(tmp_path / 'live_view.log', view)   # the view subscribed before this
        plant = plant_node.PlantNode(context=ctx, cli_args=[
            '--ros-args', '-p', f'model_file:={model_file}', '-p', 'steps:=2000',
            '-p', f'sample_rate:={RATE}', '-p', "loop_check:='off'"])
        executor = make_executor(ctx)
        executor.add_node(plant)
        batch_pubs = plant.outputs.display_batches()[0]

        def watched():
            return [pub.get_subscription_count() > 0 for pub in batch_pubs]
        assert not spin_until(executor, lambda: any(watched()), 2.0)
        plant_node.run(plant, executor)
        assert plant.outputs.display_batches()[1] == 0
        states = {t: n for t, n in plant.outputs.dds_published().items() if t != interface.CLOCK}
        assert states == dict.fromkeys(
            (lay.topic for lay in interface.state_layouts(plant.core.output_names)), 0)
        client = FoxgloveClient(f'ws://127.0.0.1:{port}').start()
        try:
            client.wait_for_topics([interface.TCP_STATE], 30.0)
            assert spin_until(executor, lambda: all(watched()), 30.0), watched()
        finally:
            client.stop()
        assert spin_until(executor, lambda: not any(watched()), 30.0), watched()  # it left
        executor.shutdown()
        plant.destroy_node()
    finally:
        rclpy.try_shutdown(context=ctx)
        view.send_signal(signal.SIGINT)
        assert view.wait(timeout=20) == 128 + signal.SIGINT
