"""
`analyze lobes`: lobes of recorded runs equal those of the exact FRF of the sampled model.

Two bags of a 2-mode TCP model stepped like the lockstep plant (zero-order hold, y_k then
u_k), excited by a periodic multisine along x and along y, are written as the recorder
writes them. The lobes the command computes from them must equal the zero-order lobes of the
sampled model's exact FRF ``C (zI - A_d)^-1 B_d`` on the same lines: synchronous averaging
of a settled noise-free periodic record is exact, so what is left is rounding.
"""
import csv
import math
import struct

import numpy as np
import pytest

from fixtures.cdr import encode_joint_state, encode_wrench_stamped
from pentapod_sim.cli.analyze import main
from pentapod_sim.interface import EXCITATION, excitation_spec_topic, TCP_STATE
from pentapod_sim.machining.lobes import milling_limit
from pentapod_sim.machining.materials import load_machining
from pentapod_sim.machining.tcp_frf import tcp_plant, TcpFrf, TcpMode
from pentapod_sim.recording import BagWriter
from pentapod_sim.sim.excitation import Excitation, ExcitationSpec
from pentapod_sim.sim.excitation_spec import spec_message
from pentapod_sim.sim.stepping import DiscretePlant

RATE = 1000.0
PLANT = tcp_plant([TcpMode(60.0, 0.03, 2e6, (1.0, 0.0)), TcpMode(75.0, 0.04, 3e6, (0.6, 0.8))])
SPEC = {'kind': 'multisine', 'amplitude': 20.0, 'period': 4.0, 'f_start': 2.0,
        'f_end': 200.0, 'settle_periods': 3}


def _string(text: str) -> bytes:
    data = text.encode('utf-8') + b'\0'
    return b'\x00\x01\x00\x00' + struct.pack('<I', len(data)) + data


def _record(path, direction, periods=6, with_spec=True):
    spec = ExcitationSpec(direction=direction, **SPEC)
    dt = 1.0 / RATE
    n = int(round(periods * SPEC['period'] * RATE))
    force = Excitation(spec, dt).series(n)                       # (n, 3) [N]
    plant = DiscretePlant(PLANT.discretize(dt))
    with BagWriter(path, run_info={'scenario': 'test'}) as writer:
        writer.add_topic(EXCITATION, 'geometry_msgs/msg/WrenchStamped')
        writer.add_topic(TCP_STATE, 'sensor_msgs/msg/JointState')
        if with_spec:
            topic = excitation_spec_topic('exciter')
            writer.add_topic(topic, 'std_msgs/msg/String')
            writer.write(topic, _string(spec_message(spec, RATE, 'exciter')), 0)
        for k in range(n):
            y = plant.outputs()[:2]
            t_ns = k * 1_000_000
            writer.write(EXCITATION, encode_wrench_stamped(t_ns, force[k]), t_ns)
            writer.write(TCP_STATE, encode_joint_state(t_ns, ['tcp_x', 'tcp_y'], y, [0, 0]),
                         t_ns)
            plant.advance(force[k, :2])
    return path


@pytest.fixture(scope='module')
def bags(tmp_path_factory):
    folder = tmp_path_factory.mktemp('lobes')
    return (_record(folder / 'run_x', [1.0, 0.0, 0.0]),
            _record(folder / 'run_y', [0.0, 1.0, 0.0]),
            _record(folder / 'run_xy', [0.6, 0.8, 0.0]))


def _sampled_frf(freq):
    """Exact FRF of the ZOH-sampled TCP block: C (z I - A_d)^-1 B_d, z = exp(j w dt)."""
    sys = PLANT.discretize(1.0 / RATE)
    a, b, c = sys.A, sys.B, sys.C[:2]
    z = np.exp(2j * math.pi * np.asarray(freq) / RATE)
    h = np.array([c @ np.linalg.solve(zk * np.eye(a.shape[0]) - a, b) for zk in z])
    return np.moveaxis(h, 0, -1)                                  # (2, 2, n_f)


def _summary(out, name):
    with open(next(out.glob(f'lobes_*{name}*_summary.csv')), newline='',
              encoding='utf-8') as handle:
        return list(csv.DictReader(handle))


def test_two_bags_give_the_lobes_of_the_sampled_model(bags, tmp_path, capsys):
    out = tmp_path / 'out'
    assert main(['--out', str(out), 'lobes', f'{bags[0]},{bags[1]}', '--operation',
                 'steel_half_down', '--speeds', '500', '6000']) == 0
    text = capsys.readouterr().out
    assert 'WARNING' not in text and 'minimum stable depth' in text
    row, = _summary(out, 'run_x')
    lines = Excitation(ExcitationSpec(direction=[1, 0, 0], **SPEC), 1 / RATE).lines_hz
    cut = load_machining().milling_cut('steel_half_down')
    exact = milling_limit(TcpFrf(lines, _sampled_frf(lines)), cut).minimum()
    assert float(row['min_depth_m']) == pytest.approx(exact.depth, rel=1e-6)
    assert float(row['min_depth_chatter_Hz']) == pytest.approx(exact.freq_hz, rel=1e-9)
    env = milling_limit(TcpFrf(lines, _sampled_frf(lines)), cut).envelope(
        np.linspace(500.0, 6000.0, 2000))
    assert float(row['best_pocket_m']) == pytest.approx(env.best_pocket()[1], rel=1e-6)
    for suffix in ('.png', '.csv'):
        assert list(out.glob(f'lobes_*{suffix}'))


def test_an_oblique_pair_gives_the_same_matrix(bags):
    from pentapod_sim.cli.analyze_lobes import scenario_frf
    straight = scenario_frf(f'{bags[0]},{bags[1]}')
    oblique = scenario_frf(f'{bags[0]},{bags[2]}')
    np.testing.assert_allclose(oblique.matrix, straight.matrix, rtol=1e-6,
                               atol=1e-9 * np.abs(straight.matrix).max())


def test_one_bag_is_the_direction_it_was_excited_in(bags, tmp_path, capsys):
    out = tmp_path / 'out'
    assert main(['--out', str(out), 'lobes', str(bags[0]), str(bags[1])]) == 0
    rows = {r['label']: r for r in _summary(out, 'run_x')}
    assert set(rows) == {'run_x', 'run_y'}
    lines = Excitation(ExcitationSpec(direction=[1, 0, 0], **SPEC), 1 / RATE).lines_hz
    cut = load_machining().milling_cut('aluminium_half_down')
    for name, axis in (('run_x', 0), ('run_y', 1)):
        d = np.eye(2)[axis]
        direct = TcpFrf.single_direction(lines, _sampled_frf(lines)[axis, axis], d)
        assert float(rows[name]['min_depth_m']) == pytest.approx(
            milling_limit(direct, cut).minimum().depth, rel=1e-6)


def test_user_mistakes_are_one_line(bags, tmp_path, capsys):
    out = ['--out', str(tmp_path)]
    no_spec = _record(tmp_path / 'no_spec', [1.0, 0.0, 0.0], periods=4, with_spec=False)
    for argv, message in (
            (['lobes', str(no_spec)], 'holds no excitation record'),
            (['lobes', f'{bags[0]},{bags[0]}'], 'the same direction'),
            (['lobes', str(bags[0]), '--operation', 'steel_half_dwn'], 'did you mean'),
            (['lobes', str(bags[0]), '--speeds', '5000', '100'], '0 < MIN < MAX')):
        assert main(out + argv) == 1, argv
        err = capsys.readouterr().err
        assert message in err and err.count('\n') == 1 and 'Traceback' not in err, err
