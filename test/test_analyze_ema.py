"""
`analyze modes BAG`: a recorded run of the sampled 2-DOF chain with its excitation record.

The bag is written as the lockstep recorder writes it (header stamps t_k = k dt on the force
and the response, the exciter's spec as a std_msgs/String); the excitation is rebuilt from the
spec, the estimator chosen from its kind, and the modes compared with the chain's poles.
"""
import csv
import struct

from modal_systems import TwoDof
import numpy as np
import pytest
import scipy.signal

from fixtures.cdr import encode_joint_state, encode_wrench_stamped
from pentapod_sim.analysis.frf.from_run import frfs_from_bag
from pentapod_sim.cli.analyze import main
from pentapod_sim.interface import EXCITATION, excitation_spec_topic, TCP_STATE
from pentapod_sim.recording import BagWriter
from pentapod_sim.sim.excitation import Excitation, ExcitationSpec
from pentapod_sim.sim.excitation_spec import spec_message

RATE = 1000.0  # Hz
ZETA = (0.005, 0.02)


def encode_string(text: str) -> bytes:
    data = text.encode('utf-8') + b'\0'
    return b'\x00\x01\x00\x00' + struct.pack('<I', len(data)) + data


def record(path, spec, n_steps, with_spec=True, noise=1e-3, seed=0):
    """Simulate the ZOH-sampled chain under ``spec`` and write a bag like a lockstep run."""
    system = TwoDof(zeta=ZETA)
    dt = 1.0 / RATE
    a, b, c, d, _ = scipy.signal.cont2discrete((system.a, system.b, system.c_out,
                                                np.zeros((2, 1))), dt, method='zoh')
    force = Excitation(spec, dt).series(n_steps)
    _, y, _ = scipy.signal.dlsim((a, b, c, d, dt), force[:, 0])
    y = y + noise * np.std(y, axis=0) * np.random.default_rng(seed).standard_normal(y.shape)
    with BagWriter(path, run_info={'scenario': 'test'}) as writer:
        writer.add_topic(EXCITATION, 'geometry_msgs/msg/WrenchStamped')
        writer.add_topic(TCP_STATE, 'sensor_msgs/msg/JointState')
        if with_spec:
            topic = excitation_spec_topic('exciter')
            writer.add_topic(topic, 'std_msgs/msg/String')
            writer.write(topic, encode_string(spec_message(spec, RATE, 'exciter')), 0)
        for k in range(n_steps):
            t_ns = k * 1_000_000
            writer.write(EXCITATION, encode_wrench_stamped(t_ns, force[k]), t_ns)
            writer.write(TCP_STATE, encode_joint_state(t_ns, ['tcp_x', 'tcp_y'], y[k],
                                                       [0.0, 0.0]), t_ns)
    return system


@pytest.fixture(scope='module')
def multisine_bag(tmp_path_factory):
    path = tmp_path_factory.mktemp('bags') / 'multisine'
    spec = ExcitationSpec('multisine', 20.0, [1, 0, 0], period=4.0, f_start=2.0, f_end=100.0,
                          settle_periods=3, start_delay=0.5)
    system = record(path, spec, int(RATE * (0.5 + 4.0 * 8)))
    return path, system


def test_analyze_modes_identifies_the_recorded_chain(multisine_bag, tmp_path, capsys):
    path, system = multisine_bag
    out = tmp_path / 'out'
    assert main(['--out', str(out), 'modes', str(path)]) == 0
    text = capsys.readouterr().out
    assert 'multisine excitation, synchronous average of 5 periods' in text
    assert 'WARNING' not in text  # 3 settling periods: 9 time constants of the 0.5 % mode
    with open(out / 'multisine_modes.csv', newline='', encoding='utf-8') as handle:
        rows = list(csv.DictReader(handle))
    freq = np.array([float(r['freq_Hz']) for r in rows])
    zeta = np.array([float(r['damping_ratio']) for r in rows])
    np.testing.assert_allclose(freq, system.freq_hz, rtol=1e-3)
    np.testing.assert_allclose(zeta, system.damping, rtol=0.05)
    # modal constants [1/kg] of the driving point, mass-normalised shapes
    rA = np.array([float(r[f'{TCP_STATE}.position.tcp_x rA_re [1/kg]']) for r in rows])
    np.testing.assert_allclose(rA, system.modal_constants[0], rtol=0.05)
    assert sorted(p.name for p in out.iterdir()) == [
        'multisine_frf.csv', 'multisine_modes.csv', 'multisine_stability.png',
        'multisine_synthesis.png']


def test_band_selects_modes_and_an_empty_band_is_a_clear_error(multisine_bag, tmp_path,
                                                                capsys):
    path, system = multisine_bag
    out = str(tmp_path / 'out')
    assert main(['--out', out, 'modes', str(path), '--band', '30', '90']) == 0
    text = capsys.readouterr().out
    assert 'band 30 .. 90 Hz' in text and '1 modes' in text
    row = next(line.split() for line in text.splitlines() if line.startswith('   1 '))
    assert abs(float(row[1]) / system.freq_hz[1] - 1) < 1e-3
    assert main(['--out', out, 'modes', str(path), '--band', '30', '45']) == 1
    err = capsys.readouterr().err
    assert 'no mode in 30 .. 45 Hz' in err and 'Traceback' not in err
    assert main(['--out', out, 'modes', str(path), '--outputs', f'{TCP_STATE}.nothing']) == 1
    assert 'nothing' in capsys.readouterr().err


def test_bag_without_excitation_record_is_a_clear_error(tmp_path, capsys):
    spec = ExcitationSpec('multisine', 20.0, period=1.0, f_start=2.0, f_end=100.0)
    record(tmp_path / 'bare', spec, 3000, with_spec=False)
    assert main(['--out', str(tmp_path / 'out'), 'modes', str(tmp_path / 'bare')]) == 1
    err = capsys.readouterr().err
    assert 'holds no excitation record' in err and 'Traceback' not in err


def test_an_unsettled_record_is_flagged(tmp_path, capsys):
    spec = ExcitationSpec('multisine', 20.0, period=1.0, f_start=2.0, f_end=100.0,
                          settle_periods=0)
    record(tmp_path / 'early', spec, 4000)  # 4 s from rest: 3 time constants of 0.5 %
    main(['--out', str(tmp_path / 'out'), 'modes', str(tmp_path / 'early')])
    assert 'WARNING: transient error / noise error is' in capsys.readouterr().out


def test_stepped_sine_bag_uses_the_line_fit(tmp_path):
    lines = [20.0, 24.3, 30.0, 49.5]  # settle 8 s: 6 time constants of the 0.5 % mode
    spec = ExcitationSpec('stepped_sine', 10.0, frequencies=lines, settle_time=8.0,
                          periods_per_line=40)
    dt = 1.0 / RATE
    n_steps = Excitation(spec, dt).stepped_windows()[-1][2] + 10
    system = record(tmp_path / 'stepped', spec, n_steps, noise=0.0)
    run = frfs_from_bag(tmp_path / 'stepped')
    assert run.estimator == 'stepped-sine line fit' and run.frf_form == 'receptance'
    a, b, c, d, _ = scipy.signal.cont2discrete((system.a, system.b, system.c_out,
                                                np.zeros((2, 1))), dt, method='zoh')
    z = np.exp(2j * np.pi * run.freq * dt)
    exact = np.array([(c @ np.linalg.solve(zk * np.eye(4) - a, b))[:, 0] for zk in z]).T
    # the 0.5 % mode's free vibration (excited at 24.3 Hz) has not quite died out 8 s into the
    # 30 Hz line, where the response is 30x smaller: 1 % there, 0.1 % elsewhere
    np.testing.assert_allclose(run.H[:, 0, :], exact, rtol=0.02)
    err = np.abs(run.H[:, 0, :] - exact)
    worst = np.unravel_index(np.argmax(err / np.abs(exact)), err.shape)
    assert run.transient[worst[0], 0, worst[1]] > 0.3 * err[worst]
    np.testing.assert_allclose(run.freq, Excitation(spec, dt).lines_hz)


def test_random_bag_uses_h1(tmp_path):
    spec = ExcitationSpec('random', 10.0, f_start=5.0, f_end=150.0, duration=40.0, seed=3)
    system = record(tmp_path / 'random', spec, 40000, noise=0.0)
    run = frfs_from_bag(tmp_path / 'random')
    assert run.estimator == 'H1' and run.band == (5.0, 150.0) and run.sigma is None
    # H1 of the 2 % mode's peak region (Welch, Hann): within 10 % of the continuous FRF
    near = np.abs(run.freq - system.freq_hz[1]) < 3.0
    exact = system.frf(run.freq[near])[:, 0, :]
    np.testing.assert_allclose(np.abs(run.H[:, 0, near]), np.abs(exact), rtol=0.1)
