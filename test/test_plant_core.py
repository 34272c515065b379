"""Plant stepping core, force mixer and offline closed loop against closed forms."""
import control
import numpy as np
from numpy.testing import assert_allclose
import pytest

from fixtures.demo_model import demo_model
from pentapod_damper.laws import strut_bending_damper, tcp_damper
from pentapod_sim.errors import ConfigError, PortError, RunError
from pentapod_sim.plant.model import PlantModel
from pentapod_sim.sim.closed_loop import excitation_matrix, simulate
from pentapod_sim.sim.modal_blocks import modal_blocks
from pentapod_sim.sim.stepping import DiscretePlant, ForceMixer, ForceSource

TCP = ['tcp_force_x', 'tcp_force_y', 'tcp_force_z']


def one_mode(omega: float, b: float, zeta: float = 0.0, d: float = 0.0) -> PlantModel:
    """Single mass-normalised mode driven by tcp_force_x, observed at the TCP."""
    return PlantModel([omega], [zeta], [[b]], [[b], [0.0]], [[0.0], [b]], [[d], [0.0]],
                      ['tcp_force_x'], ['tcp_displacement_x', 'tcp_velocity_x'],
                      ['N'], ['m', 'm/s'], ['f'], ['x', 'v'])


def test_rectangular_pulse_matches_closed_form():
    """A force held over step 0 only: exact undamped free vibration afterwards."""
    omega, b, force, dt = 2 * np.pi * 30.0, 0.1, 50.0, 1e-3
    plant = DiscretePlant(one_mode(omega, b).discretize(dt))
    y = []
    for k in range(200):
        y.append(plant.outputs())
        plant.advance(np.array([force if k == 0 else 0.0]))
    t = np.arange(200) * dt
    # q(t) for a unit-mass oscillator under modal force p = b F on [0, dt]
    p = b * force
    q = np.where(t >= dt, p / omega ** 2 * (np.cos(omega * (t - dt)) - np.cos(omega * t)),
                 p / omega ** 2 * (1 - np.cos(omega * t)))
    dq = np.where(t >= dt, p / omega * (np.sin(omega * t) - np.sin(omega * (t - dt))),
                  p / omega * np.sin(omega * t))
    y = np.array(y)
    assert y[0, 0] == 0.0 and y[0, 1] == 0.0        # y_0 does not see u_0
    assert_allclose(y[:, 0], b * q, rtol=1e-10, atol=1e-12 * np.abs(b * q).max())
    assert_allclose(y[:, 1], b * dq, rtol=1e-10, atol=1e-12 * np.abs(b * dq).max())


def test_feedthrough_uses_previous_input():
    """y_k = C x_k + D u_{k-1}."""
    plant = DiscretePlant(one_mode(100.0, 0.0, d=2e-6).discretize(1e-3))
    plant.advance(np.array([3.0]))
    assert plant.outputs()[0] == pytest.approx(6e-6, rel=1e-15)
    plant.advance(np.array([0.0]))
    assert plant.outputs()[0] == 0.0


def test_instability_raises_run_error():
    """Positive velocity feedback grows the state until the bound trips."""
    plant = DiscretePlant(one_mode(2 * np.pi * 20, 1.0).discretize(1e-3), max_state_norm=1.0)
    plant.advance(np.array([1.0]))
    with pytest.raises(RunError, match='max_state_norm'):
        for _ in range(100000):
            plant.advance(np.array([+200.0 * plant.outputs()[1]]))


@pytest.mark.parametrize('bound', [0.0, -1.0, float('nan'), float('inf'), 1e300])
def test_a_state_bound_whose_square_overflows_is_refused(bound):
    """The bound is compared squared: above 1e150 its square is inf (no traceback, a name)."""
    with pytest.raises(ConfigError, match='max_state_norm'):
        DiscretePlant(one_mode(2 * np.pi * 20, 1.0).discretize(1e-3), max_state_norm=bound)


def test_rejects_continuous_system():
    with pytest.raises(ConfigError, match='discrete'):
        DiscretePlant(one_mode(1.0, 1.0).to_statespace())


class TestForceMixer:
    def make(self):
        return ForceMixer(TCP + ['pma_force_x'],
                          [ForceSource('exciter', tuple(TCP)), ForceSource('damper')])

    def test_sum_and_missing(self):
        mixer = self.make()
        assert mixer.missing(0) == ['exciter', 'damper']
        assert mixer.submit('exciter', TCP, [2.0, 0.0, 0.0], 0, 0) is None
        assert mixer.missing(0) == ['damper']
        assert mixer.submit('damper', ['tcp_force_x', 'pma_force_x'], [1.0, -4.0], 0, 0) is None
        assert_allclose(mixer.total(), [3.0, 0.0, 0.0, -4.0])

    @pytest.mark.parametrize(('source', 'names', 'efforts', 'step', 'kind'), [
        ('exciter', TCP, [np.nan, 0.0, 0.0], 0, 'nonfinite'),
        ('exciter', TCP, [0.0, np.inf, 0.0], 0, 'nonfinite'),
        ('exciter', TCP, [1.0], 0, 'length'),
        ('exciter', ['tcp_force_q'], [1.0], 0, 'unknown_port'),
        ('exciter', ['pma_force_x'], [1.0], 0, 'forbidden_port'),
        ('nobody', TCP, [1.0, 0.0, 0.0], 0, 'unknown_source'),
        ('exciter', TCP, [1.0, 0.0, 0.0], 1, 'future'),
        ('exciter', ['tcp_force_x', 'tcp_force_x'], [1.0, 1.0], 0, 'duplicate_port'),
        ('exciter', ['tcp_force_x'], [1.0], 0, 'ports'),       # a source answers all its ports
        ('exciter', [], [], 0, 'ports'),
    ])
    def test_rejects_and_counts(self, source, names, efforts, step, kind):
        mixer = self.make()
        assert mixer.submit('exciter', TCP, [0.0, 5.0, 0.0], 0, 0) is None
        mixer.latest_step['exciter'] = -1   # allow a second message for the same step
        reason = mixer.submit(source, names, efforts, step, 0)
        assert reason is not None and reason.startswith(kind)
        assert mixer.rejected[(source, kind)] == 1
        assert_allclose(mixer.total(), [0.0, 5.0, 0.0, 0.0])   # accepted force kept

    def test_stale_in_lockstep_newest_in_realtime(self):
        mixer = self.make()
        assert mixer.submit('damper', ['tcp_force_x'], [1.0], 2, 3).startswith('stale')
        assert mixer.submit('damper', ['tcp_force_x'], [1.0], 2, 3, exact=False) is None
        assert mixer.submit('damper', ['tcp_force_x'], [9.0], 1, 3, exact=False) is not None
        assert mixer.total()[0] == 1.0

    def test_bad_configuration(self):
        with pytest.raises(PortError, match='tcp_force_w'):
            ForceMixer(TCP, [ForceSource('a', ('tcp_force_w',))])
        with pytest.raises(ConfigError, match="'a'"):
            ForceMixer(TCP, [ForceSource('a'), ForceSource('a')])


def reference_loop(model, dt, gain_rows, exc):
    """Independent plain-numpy closed loop with one-step delay (u_k = K y_k + e_k)."""
    a, b, c, d = model.discrete_matrices(dt)
    x, u_prev, ys = np.zeros(a.shape[0]), np.zeros(b.shape[1]), []
    for e in exc:
        y = c @ x + d @ u_prev
        u = gain_rows @ y + e
        ys.append(y)
        x, u_prev = a @ x + b @ u, u
    return np.array(ys)


@pytest.mark.parametrize('feedthrough', [0.0, 1e-9])
def test_offline_closed_loop_matches_reference(feedthrough):
    """The stepping loop and an independent loop agree."""
    model = demo_model(12, feedthrough=feedthrough, seed=3)
    dt, n = 1 / 5000, 3000
    plant = DiscretePlant(model.discretize(dt))
    rng = np.random.default_rng(0)
    exc = excitation_matrix(plant, TCP, rng.standard_normal((n, 3)) * 50, n)
    laws = [tcp_damper(['x', 'y'], 3000.0), strut_bending_damper([1], 500.0)]
    slow = simulate(plant, laws, exc)
    gain = np.zeros((len(model.input_names), len(model.output_names)))
    for law in laws:
        for a_port, s_port, g in zip(law.actuator_ports, law.sensor_ports, law.gains):
            gain[model.input_names.index(a_port), model.output_names.index(s_port)] = -g
    ref = reference_loop(model, dt, gain, exc)
    scale = np.abs(ref).max(axis=0) + 1e-300
    assert np.max(np.abs(slow.y - ref) / scale) < 1e-12


def test_energy_balance_of_damped_loop():
    """Undamped modes, TCP damper: E_N = work of excitation - damper dissipation (exact)."""
    model = demo_model(8, f_max=100.0, zeta=0.0, inputs=TCP, seed=5)
    dt, n, gain = 1 / 5000, 4000, 4000.0
    plant = DiscretePlant(model.discretize(dt))
    exc = excitation_matrix(plant, TCP, np.outer(np.sin(np.arange(n) * 0.05) *
                                                 (np.arange(n) < 1000), [30.0, 10.0, 0.0]), n)
    run = simulate(plant, [tcp_damper(['x', 'y', 'z'], gain)], exc)
    disp = np.vstack([run.y[:, :3], (plant.c @ plant.x)[:3]])   # s_0..s_N
    work = np.einsum('kj,kj->k', run.u, np.diff(disp, axis=0))    # u_k . (s_{k+1} - s_k)
    m = model.n_modes
    energy = 0.5 * (plant.x[m:] @ plant.x[m:] + (model.omega ** 2) @ plant.x[:m] ** 2)
    assert energy == pytest.approx(work.sum(), rel=1e-9)
    damper_u = run.u - exc
    dissipated = -np.einsum('kj,kj->', damper_u, np.diff(disp, axis=0))
    v = run.y[:, 3:6]
    assert dissipated > 0
    assert dissipated == pytest.approx(gain * np.trapezoid((v ** 2).sum(axis=1), dx=dt),
                                       rel=2e-3)


def _dense_steps(sys, x0, inputs):
    """Independent dense stepping x_{k+1} = A x_k + B u_k; returns the states x_1..x_N."""
    x, out = np.array(x0, dtype=float), []
    for u in inputs:
        x = sys.A @ x + sys.B @ u
        out.append(x)
    return np.array(out)


def test_modal_blocks_detects_the_layout():
    model = demo_model(7, seed=4)
    a = model.discrete_matrices(1e-3)[0]
    blocks = modal_blocks(a)
    phi = model.zoh_blocks(1e-3)[0]                     # (m, 2, 2) per mode
    assert_allclose(blocks, phi.transpose(1, 2, 0), rtol=0, atol=0)
    coupled = a.copy()
    coupled[0, 1] = 1e-300                              # one entry coupling two modes
    assert modal_blocks(coupled) is None
    assert modal_blocks(np.eye(3)) is None              # odd number of states
    assert DiscretePlant(model.discretize(1e-3)).modal


@pytest.mark.parametrize('coupled', [False, True])
def test_state_update_matches_dense_reference(coupled):
    """Modal (blockwise) and dense (any A_d) paths both step x_{k+1} = A_d x_k + B_d u_k."""
    model = demo_model(9, seed=6)
    sys = model.discretize(1 / 4000)
    if coupled:                                         # a weak coupling: not modal any more
        a = sys.A.copy()
        a[2, 9 + 4] += 1e-4
        sys = control.ss(a, sys.B, sys.C, sys.D, sys.dt, inputs=sys.input_labels,
                         outputs=sys.output_labels)
    plant = DiscretePlant(sys)
    assert plant.modal is not coupled
    rng = np.random.default_rng(1)
    x0 = 1e-6 * rng.standard_normal(18)
    inputs = 30 * rng.standard_normal((500, len(model.input_names)))
    plant.reset(x0)
    states = []
    for u in inputs:
        plant.advance(u)
        states.append(plant.x.copy())
    ref = _dense_steps(sys, x0, inputs)
    assert np.max(np.abs(np.array(states) - ref)) < 1e-12 * np.abs(ref).max()
    assert_allclose(plant.outputs(), sys.C @ ref[-1] + sys.D @ inputs[-1], rtol=1e-12)


def test_state_setter_checks_shape_and_copies():
    plant = DiscretePlant(demo_model(3).discretize(1e-3))
    x0 = np.arange(6.0)
    plant.reset(x0)
    x0[:] = 0.0                                         # the plant holds its own copy
    assert_allclose(plant.x, np.arange(6.0))
    with pytest.raises(ConfigError, match=r'\(6,\)'):
        plant.reset(np.zeros(5))


def test_offline_loop_is_bit_identical_to_the_node_loop():
    """
    simulate() gives the very bits of the plant node's loop.

    simulate() writes outputs into its trace and builds u in place; the node takes fresh
    outputs() and u summed by the ForceMixer from each source's message.
    """
    model = demo_model(12, seed=8)
    dt, n = 1 / 5000, 1500
    laws = [tcp_damper(['x', 'y'], 3000.0), strut_bending_damper([1, 4], 500.0)]
    plant = DiscretePlant(model.discretize(dt))
    rng = np.random.default_rng(2)
    exc = excitation_matrix(plant, TCP, 40 * rng.standard_normal((n, 3)), n)
    offline = simulate(plant, laws, exc)

    for law in laws:
        law.reset()
    node = DiscretePlant(model.discretize(dt))
    mixer = ForceMixer(node.input_names, [ForceSource('exciter', tuple(TCP))]
                       + [ForceSource(f'law{i}') for i in range(len(laws))])
    sensors = [[node.output_index[p] for p in law.sensor_ports] for law in laws]
    ys, us = [], []
    for k in range(n):
        y = node.outputs()
        mixer.submit('exciter', TCP, exc[k, :3], k, k)
        for i, law in enumerate(laws):
            mixer.submit(f'law{i}', law.actuator_ports, law.step(y[sensors[i]]), k, k)
        u = mixer.total()
        ys.append(y)
        us.append(u)
        node.advance(u)
    assert np.array_equal(offline.y, np.array(ys))
    assert np.array_equal(offline.u, np.array(us))
    assert np.array_equal(plant.x, node.x)


def test_simulate_rejects_an_excitation_of_the_wrong_width():
    plant = DiscretePlant(demo_model(3).discretize(1e-3))
    with pytest.raises(ConfigError, match=r'\(10, 3\)'):
        simulate(plant, [], np.zeros((10, 3)))
