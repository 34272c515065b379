"""Nodes in real processes (rclpy, DDS on localhost): lockstep, energy, PMA, failures, help."""
import os
import subprocess
import sys
import time

import numpy as np
from numpy.testing import assert_allclose
import pytest

from fixtures.demo_model import demo_model
from fixtures.processes import NodeProcesses
from pentapod_damper.laws import Dynamics, ProofMassActuator, strut_bending_damper, tcp_damper
from pentapod_sim.parameters import params_of
from pentapod_sim.registry import NODES
from pentapod_sim.sim.closed_loop import excitation_matrix, simulate
from pentapod_sim.sim.excitation import Excitation, ExcitationSpec
from pentapod_sim.sim.stepping import DiscretePlant

RATE = 5000.0
TCP = ['tcp_force_x', 'tcp_force_y', 'tcp_force_z']


@pytest.fixture
def ros_env():
    """The session's isolated environment (conftest.py reserves its ROS domain)."""
    env = dict(os.environ)
    assert env.get('ROS_DOMAIN_ID') and env.get('ROS_AUTOMATIC_DISCOVERY_RANGE')
    return env


@pytest.fixture
def procs(ros_env, tmp_path):
    p = NodeProcesses(tmp_path, ros_env)
    yield p
    p.close()


def plant_params(model_file, steps, sources, trace, *extra):
    return (f'model_file:={model_file}', f'steps:={steps}', f'sample_rate:={RATE}',
            'sources:=[' + ','.join(sources) + ']', f"output_file:='{trace}'",
            'startup_timeout:=60.0', *extra)


def test_lockstep_reproduces_offline_closed_loop(procs, tmp_path):
    """Plant + exciter + damper + PMA through ROS equal the in-process closed loop."""
    model = demo_model(10, seed=11)
    model_file = model.save(tmp_path / 'model.npz')
    steps, trace = 1500, tmp_path / 'trace.npz'
    procs.start('exciter', 'pentapod_sim.nodes.exciter_node', 'kind:=random',
                'amplitude:=50.0', 'direction:=[1.0, 0.5, 0.0]', 'duration:=0.3',
                'f_start:=5.0', 'f_end:=400.0', 'seed:=3', f'sample_rate:={RATE}')
    procs.start('damper', 'pentapod_damper.nodes.damper_node', "tcp_directions:=['x','y']",
                'tcp_gain:=3000.0', 'bending_struts:=[1]', 'bending_gain:=400.0')
    procs.start('pma', 'pentapod_damper.nodes.pma_node', "directions:=['x']",
                'proof_mass:=2.0', 'gain:=1000.0', 'highpass_hz:=5.0', f'sample_rate:={RATE}')
    procs.start('plant', 'pentapod_sim.nodes.plant_node',
                *plant_params(model_file, steps, ['exciter', 'damper', 'pma'], trace))
    assert procs.wait('plant') == 0, procs.log('plant')
    run = np.load(trace)

    plant = DiscretePlant(model.discretize(1 / RATE))
    exc = Excitation(ExcitationSpec('random', 50.0, [1.0, 0.5, 0.0], f_start=5.0, f_end=400.0,
                                    duration=0.3, seed=3), 1 / RATE)
    laws = [tcp_damper(['x', 'y'], 3000.0), strut_bending_damper([1], 400.0),
            ProofMassActuator(['x'], 2.0, 1000.0, 1 / RATE, highpass_hz=5.0)]
    ref = simulate(plant, laws, excitation_matrix(plant, TCP, exc.series(steps), steps))
    assert list(run['output_names']) == ref.output_names
    scale = np.abs(ref.y).max(axis=0)
    assert np.all(scale > 0)
    assert np.max(np.abs(run['y'] - ref.y) / scale) < 1e-12
    assert np.max(np.abs(run['u'] - ref.u)) <= 1e-12 * np.abs(ref.u).max()
    # answers to a step the plant re-published after resend_period (a loaded machine) arrive
    # twice: the plant drops the late copy as stale or duplicate, by design; nothing else
    assert [r for r in run['rejected'] if r.split('/')[1].split('=')[0]
            not in ('stale', 'duplicate')] == []


def test_damper_node_with_filter_and_delay_reproduces_offline_loop(procs, tmp_path):
    """A damper node with a low-pass and a one-sample delay equals its offline law bit for bit."""
    model = demo_model(8, seed=5)
    model_file = model.save(tmp_path / 'model.npz')
    steps, trace = 800, tmp_path / 'trace.npz'
    procs.start('exciter', 'pentapod_sim.nodes.exciter_node', 'kind:=random',
                'amplitude:=50.0', 'direction:=[1.0, 0.0, 0.0]', 'duration:=0.2',
                'f_start:=5.0', 'f_end:=400.0', 'seed:=4', f'sample_rate:={RATE}')
    procs.start('damper', 'pentapod_damper.nodes.damper_node', "tcp_directions:=['x','y']",
                'tcp_gain:=3000.0', 'filter_order:=2', 'bandwidth_hz:=250.0',
                'filter_damping:=0.5', 'delay_steps:=1', f'sample_rate:={RATE}')
    procs.start('plant', 'pentapod_sim.nodes.plant_node',
                *plant_params(model_file, steps, ['exciter', 'damper'], trace))
    assert procs.wait('plant') == 0, procs.log('plant')
    run = np.load(trace)
    plant = DiscretePlant(model.discretize(1 / RATE))
    exc = Excitation(ExcitationSpec('random', 50.0, [1.0, 0.0, 0.0], f_start=5.0, f_end=400.0,
                                    duration=0.2, seed=4), 1 / RATE)
    law = tcp_damper(['x', 'y'], 3000.0, Dynamics(2, 250.0, 0.5, 1), 1 / RATE)
    ref = simulate(plant, [law], excitation_matrix(plant, TCP, exc.series(steps), steps))
    assert np.any(ref.input('tcp_force_y'))
    assert np.max(np.abs(run['u'] - ref.u)) <= 1e-12 * np.abs(ref.u).max()


def test_tcp_damper_energy(procs, tmp_path):
    """Dissipated energy = b int v^2 dt, and E_N = work of exciter + work of damper."""
    model = demo_model(6, f_max=120.0, zeta=0.0, inputs=TCP, seed=2)
    model_file = model.save(tmp_path / 'model.npz')
    steps, gain, trace = 2500, 5000.0, tmp_path / 'trace.npz'
    procs.start('exciter', 'pentapod_sim.nodes.exciter_node', 'kind:=sine',
                'amplitude:=40.0', 'frequency:=30.0', 'duration:=0.2', f'sample_rate:={RATE}')
    procs.start('damper', 'pentapod_damper.nodes.damper_node',
                "tcp_directions:=['x','y','z']", f'tcp_gain:={gain}')
    procs.start('plant', 'pentapod_sim.nodes.plant_node',
                *plant_params(model_file, steps, ['exciter', 'damper'], trace))
    assert procs.wait('plant') == 0, procs.log('plant')
    run = np.load(trace)
    y, u, dt, x_n = run['y'], run['u'], float(run['dt']), run['x_final']
    names = list(run['output_names'])
    disp_idx = [names.index(f'tcp_displacement_{a}') for a in 'xyz']
    vel_idx = [names.index(f'tcp_velocity_{a}') for a in 'xyz']
    c_disp = np.hstack([model.c_disp, model.c_vel])[disp_idx]
    disp = np.vstack([y[:, disp_idx], c_disp @ x_n])          # s_0 .. s_N
    steps_disp = np.diff(disp, axis=0)
    inputs = list(run['input_names'])
    t = np.arange(steps) * dt
    f_exc = np.where(t < 0.2, 40.0 * np.sin(2 * np.pi * 30.0 * t), 0.0)
    u_exc = np.zeros_like(u)
    u_exc[:, inputs.index('tcp_force_x')] = f_exc
    u_damp = u - u_exc
    v = y[:, vel_idx]
    assert_allclose(u_damp[:, :3], -gain * v, rtol=1e-12, atol=1e-12 * np.abs(u_damp).max())
    dissipated = -np.einsum('kj,kj->', u_damp, steps_disp)
    assert dissipated == pytest.approx(gain * np.trapezoid((v ** 2).sum(axis=1), dx=dt),
                                       rel=5e-3)
    m = model.n_modes
    energy = 0.5 * (x_n[m:] @ x_n[m:] + model.omega ** 2 @ x_n[:m] ** 2)
    w_exc = np.einsum('kj,kj->', u_exc, steps_disp)
    assert energy == pytest.approx(w_exc - dissipated, rel=1e-9)
    assert dissipated > 0.5 * w_exc   # the damper took most of the input energy


def _drive_pma(env, n_steps, v_amp, omega):
    """Act as the plant for a PMA node: send v_k = V cos(omega t_k), collect its answers."""
    import rclpy
    from rclpy.node import Node
    from sensor_msgs.msg import JointState

    from pentapod_sim.nodes.common import (
        FORCE_QOS,
        make_executor,
        spin_until,
        stamp_msg,
        stamp_to_ns,
        STATE_QOS,
    )
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=int(env['ROS_DOMAIN_ID']))
    try:
        node = Node('pma_driver', context=ctx)
        pub = node.create_publisher(JointState, '/pentapod/pma_mount_state', STATE_QOS)
        forces, states = {}, {}
        node.create_subscription(JointState, '/pentapod/forces/pma',
                                 lambda m: forces.setdefault(stamp_to_ns(m.header.stamp),
                                                             m.effort[0]), FORCE_QOS)
        node.create_subscription(JointState, '/pentapod/pma/state',
                                 lambda m: states.setdefault(stamp_to_ns(m.header.stamp),
                                                             (m.position[0], m.effort[0])),
                                 STATE_QOS)
        executor = make_executor(ctx)
        executor.add_node(node)
        assert spin_until(executor, lambda: pub.get_subscription_count() > 0, 60.0)
        dt = 1 / RATE
        for k in range(n_steps):
            ns = round(k * dt * 1e9)
            msg = JointState(name=['pma_mount_x'], position=[float('nan')],
                             velocity=[v_amp * np.cos(omega * k * dt)])
            msg.header.stamp = stamp_msg(ns)
            pub.publish(msg)
            if not spin_until(executor, lambda: ns in forces and ns in states, 2.0):
                pub.publish(msg)     # the first messages may precede discovery
                assert spin_until(executor, lambda: ns in forces and ns in states, 10.0)
        return [forces[round(k * dt * 1e9)] for k in range(n_steps)], \
            [states[round(k * dt * 1e9)] for k in range(n_steps)]
    finally:
        executor.shutdown()
        rclpy.shutdown(context=ctx)


def test_pma_node_follows_its_law(procs, ros_env):
    """Force = -m g v each step; stroke matches the law's own discrete integration."""
    mass, gain, v_amp, omega, n = 5.0, 4000.0, 2e-3, 2 * np.pi * 40.0, 400
    procs.start('pma', 'pentapod_damper.nodes.pma_node', "directions:=['x']",
                f'proof_mass:={mass}', f'gain:={gain}', f'sample_rate:={RATE}')
    forces, states = _drive_pma(ros_env, n, v_amp, omega)
    dt = 1 / RATE
    v = np.array([v_amp * np.cos(omega * k * dt) for k in range(n)])   # as sent
    assert_allclose(forces, -mass * gain * v, rtol=1e-15, atol=1e-300)
    assert_allclose([s[1] for s in states], forces, rtol=0, atol=0)
    # stroke after step k: dt sum_j (w_j - v_j) + dt^2/2 g sum_j v_j with w_j = g dt sum_{i<j} v_i
    w = np.concatenate([[0.0], gain * dt * np.cumsum(v)[:-1]])
    stroke = np.cumsum(dt * (w - v) + 0.5 * dt ** 2 * gain * v)
    assert_allclose([s[0] for s in states], stroke, rtol=1e-9, atol=1e-18)


def test_killed_damper_stops_lockstep_run(procs, tmp_path):
    """SIGKILL of a source: the plant exits nonzero naming it."""
    model_file = demo_model(4).save(tmp_path / 'model.npz')
    damper = procs.start('damper_k', 'pentapod_damper.nodes.damper_node',
                         "tcp_directions:=['x']", 'tcp_gain:=100.0')
    plant = procs.start('plant', 'pentapod_sim.nodes.plant_node',
                        *plant_params(model_file, 10 ** 8, ['damper_k'], ''),
                        'source_timeout:=1.0')
    end = time.monotonic() + 60
    while ('lockstep run' not in procs.log('plant') and time.monotonic() < end
           and plant.poll() is None):
        time.sleep(0.1)
    time.sleep(0.5)
    damper.kill()
    assert plant.wait(timeout=30) != 0
    log = procs.log('plant')
    assert 'damper_k silent' in log and 'source_timeout' in log, log


def test_bad_messages_rejected_and_counted(procs, ros_env, tmp_path):
    """A source that sends NaN / wrong length / unknown port messages besides good ones."""
    import rclpy
    from rclpy.node import Node
    from rosgraph_msgs.msg import Clock
    from sensor_msgs.msg import JointState

    from pentapod_sim.nodes.common import (
        FORCE_QOS,
        make_executor,
        spin_until,
        stamp_to_ns,
        STATE_QOS,
    )
    model_file = demo_model(4, inputs=TCP).save(tmp_path / 'model.npz')
    steps, trace = 300, tmp_path / 'trace.npz'
    plant = procs.start('plant', 'pentapod_sim.nodes.plant_node',
                        *plant_params(model_file, steps, ['tester'], trace))
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=int(ros_env['ROS_DOMAIN_ID']))
    # the source drives tcp_force_y (its first accepted answer); an empty answer is refused
    bad = [(['tcp_force_y'], [float('nan')]), (['tcp_force_x', 'tcp_force_y'], [1.0]),
           (['tcp_force_q'], [1.0]), ([], [])]
    try:
        node = Node('tester', context=ctx)
        pub = node.create_publisher(JointState, '/pentapod/forces/tester', FORCE_QOS)

        def answer(clock):
            k = round(stamp_to_ns(clock.clock) * RATE / 1e9)
            if k % 10 == 0:        # first the bad ones, then the good answer
                for names, efforts in bad:
                    msg = JointState(name=names, effort=efforts)
                    msg.header.stamp = clock.clock
                    pub.publish(msg)
            msg = JointState(name=['tcp_force_y'], effort=[float(k)])
            msg.header.stamp = clock.clock
            pub.publish(msg)
        node.create_subscription(Clock, '/clock', answer, STATE_QOS)
        executor = make_executor(ctx)
        executor.add_node(node)
        assert spin_until(executor, lambda: plant.poll() is not None, 90.0, poll=0.01)
    finally:
        executor.shutdown()
        rclpy.shutdown(context=ctx)
    assert plant.returncode == 0, procs.log('plant')
    run = np.load(trace)
    counts = dict(item.split('=') for item in run['rejected'])
    sent = steps // 10
    # a re-published step may be answered twice; every bad message is counted at least once
    for kind in ('nonfinite', 'length', 'unknown_port', 'ports'):
        assert sent <= int(counts[f'tester/{kind}']) <= 2 * sent, counts
    assert_allclose(run['u'][:, 1], np.arange(steps))     # every good answer applied
    assert "rejected message from source 'tester'" in procs.log('plant')


def test_realtime_holds_newest_exciter_force(procs, tmp_path):
    """Real time: every applied force is a genuine exciter sample of the same or an older step."""
    model_file = demo_model(4, inputs=TCP).save(tmp_path / 'model.npz')
    steps, rate, trace = 500, 1000.0, tmp_path / 'trace.npz'
    procs.start('exciter', 'pentapod_sim.nodes.exciter_node', 'kind:=sine', 'amplitude:=5.0',
                'frequency:=7.0', f'sample_rate:={rate}')
    procs.start('plant', 'pentapod_sim.nodes.plant_node', f'model_file:={model_file}',
                f'steps:={steps}', f'sample_rate:={rate}', 'timing:=realtime',
                'sources:=[exciter]', f"output_file:='{trace}'", 'startup_timeout:=60.0')
    assert procs.wait('plant') == 0, procs.log('plant')
    run = np.load(trace)
    sent = 5.0 * np.sin(2 * np.pi * 7.0 * np.arange(steps) / rate)
    applied = run['u'][:, 0]
    for k, f in enumerate(applied):
        lags = np.flatnonzero(np.isclose(sent[:k + 1], f, rtol=0, atol=1e-12))
        assert lags.size, f'step {k}: force {f} was never sent up to this step'
    assert run['achieved_rate'] > 0 and run['lateness_p99'] >= run['lateness_p50']
    assert 'realtime final' in procs.log('plant')


def test_scenario_runner_end_to_end(ros_env, tmp_path):
    """`python -m pentapod_sim.scenario.runner file.yaml` starts, runs and stops every node."""
    model_file = demo_model(4).save(tmp_path / 'model.npz')
    scenario = tmp_path / 'mini.yaml'
    scenario.write_text(f"""
/**:
  ros__parameters:
    sample_rate: {RATE}
plant:
  ros__parameters:
    model_file: {model_file}
    steps: 400
    sources: [exciter, damper_tcp]
    output_file: ''      # the runner's --output-file must win over this
    startup_timeout: 60.0
exciter:
  ros__parameters:
    kind: impulse
    amplitude: 10.0
damper_tcp:
  ros__parameters:
    tcp_directions: ['x', 'y']
    tcp_gain: 100.0
""")
    trace = tmp_path / 'trace.npz'
    proc = subprocess.run([sys.executable, '-m', 'pentapod_sim.scenario.runner', str(scenario),
                           '--output-file', str(trace), '--timeout', '120'], env=ros_env,
                          capture_output=True, text=True, timeout=180)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    run = np.load(trace)
    assert run['u'][0, 0] == 10.0
    names = list(run['output_names'])
    v = run['y'][:, names.index('tcp_velocity_y')]
    assert_allclose(run['u'][1:, 1], -100.0 * v[1:], rtol=1e-12, atol=1e-15)


@pytest.mark.parametrize(('module', 'params', 'named'), [
    ('pentapod_sim.nodes.plant_node', ['timing:=fast'], "node 'plant': parameter timing"),
    ('pentapod_sim.nodes.plant_node', ['sample_rate:=-5.0'], 'parameter sample_rate = -5.0'),
    ('pentapod_damper.nodes.damper_node', ['bending_struts:=[7]'], 'strut number 7'),
    ('pentapod_damper.nodes.pma_node', ['proof_mass:=0.0'], "'pma': parameter proof_mass"),
    ('pentapod_sim.nodes.exciter_node', ['kind:=hammer'], "'hammer'"),
])
def test_bad_parameters_stop_node_with_named_error(ros_env, tmp_path, module, params, named):
    cmd = [sys.executable, '-m', module, '--ros-args']
    if module.endswith('plant_node'):
        cmd += ['-p', f"model_file:={demo_model(2).save(tmp_path / 'model.npz')}"]
    for p in params:
        cmd += ['-p', p]
    proc = subprocess.run(cmd, env=ros_env, capture_output=True, text=True, timeout=60)
    assert proc.returncode == 1
    assert named in proc.stderr, proc.stderr


def test_misspelt_override_stops_the_plant_naming_the_parameter(ros_env):
    """`-p postion:=P2` used to build P1 silently; now one error line, before any model."""
    proc = subprocess.run([sys.executable, '-m', 'pentapod_sim.nodes.plant_node', '--ros-args',
                           '-p', 'postion:=P2'], env=ros_env, capture_output=True, text=True,
                          timeout=60)
    assert proc.returncode == 1
    assert proc.stderr.strip().splitlines() == [
        "error: node 'plant': unknown parameter 'postion'; did you mean 'position'?"], \
        proc.stderr
    assert 'plant model' not in proc.stdout + proc.stderr


@pytest.mark.parametrize('kind', NODES, ids=lambda k: k.name)
def test_help_prints_the_table_and_starts_nothing(ros_env, tmp_path, kind):
    """`--help` exits 0 with the table; a started node would fail on these parameters."""
    bogus = {'plant': 'model_file:=/nonexistent/model.npz',
             'recorder': f'output_dir:={tmp_path / "bags"}'}.get(kind.name,
                                                                 'no_such_parameter:=1')
    proc = subprocess.run([sys.executable, '-m', kind.module, '--help', '--ros-args', '-p',
                           bogus], env=ros_env, capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.startswith(f'usage: ros2 run pentapod_testbed {kind.name} ')
    for param in params_of(kind.name).ros_params():
        assert f'  {param.name} ({param.type}; default' in proc.stdout
    assert proc.stderr == '' and '[INFO]' not in proc.stdout
    assert not (tmp_path / 'bags').exists()
