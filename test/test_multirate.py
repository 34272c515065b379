"""Multi-rate plant core: N exact ZOH substeps per exchange, full-rate outputs, offline loop."""
import control
import numpy as np
import pytest

from fixtures.demo_model import demo_model
from pentapod_damper.laws import Dynamics, ProofMassActuator, tcp_damper
from pentapod_sim.errors import ConfigError
from pentapod_sim.interface import fullrate_layout, TCP_STATE_FULLRATE
from pentapod_sim.sim.closed_loop import closed_loop_system, excitation_matrix, simulate
from pentapod_sim.sim.multirate import full_rate_loop_outputs, MultiRatePlant
from pentapod_sim.sim.stepping import DiscretePlant

TCP = ['tcp_force_x', 'tcp_force_y', 'tcp_force_z']
RATE, N = 1000.0, 10            # 1 kHz exchange, 10 kHz plant


def _rel(a, b):
    return np.max(np.abs(np.asarray(a) - b)) / np.max(np.abs(b))


@pytest.mark.parametrize('feedthrough', [0.0, 1e-9])
def test_exchange_update_equals_single_rate_plant_at_the_exchange_rate(feedthrough):
    """A_f^N and sum A_f^j B_f of the fine ZOH are the ZOH over N dt_f (independent expm)."""
    model = demo_model(9, seed=6, feedthrough=feedthrough)
    multi = MultiRatePlant.from_model(model, RATE, N)
    single = DiscretePlant(model.discretize(1 / RATE))
    assert multi.modal and multi.dt == pytest.approx(1 / RATE, rel=1e-15)
    assert multi.fine_dt == pytest.approx(1 / (RATE * N), rel=1e-15)
    assert _rel(multi.a, single.a) < 1e-12 and _rel(multi.b, single.b) < 1e-12
    rng = np.random.default_rng(1)
    x0 = 1e-6 * rng.standard_normal(18)
    inputs = 30 * rng.standard_normal((400, len(model.input_names)))
    xs = {}
    for name, plant in (('multi', multi), ('single', single)):
        plant.reset(x0)
        ys = []
        for u in inputs:
            ys.append(plant.outputs().copy())
            plant.advance(u)
        xs[name] = np.array(ys)
    assert _rel(xs['multi'], xs['single']) < 1e-12


@pytest.mark.parametrize('feedthrough', [0.0, 1e-9])
def test_full_rate_outputs_equal_fine_stepping_with_u_held(feedthrough):
    """Row j of exchange k = the fine-rate plant stepped kN + j times with u_k held."""
    model = demo_model(7, seed=2, feedthrough=feedthrough)
    multi = MultiRatePlant.from_model(model, RATE, N)
    fine = DiscretePlant(model.discretize(1 / (RATE * N)))
    rng = np.random.default_rng(3)
    inputs = 20 * rng.standard_normal((120, len(model.input_names)))
    got, want = [], []
    for u in inputs:
        got.append(multi.fine_outputs(u, multi.outputs()))
        multi.advance(u)
        for _ in range(N):
            want.append(fine.outputs())
            fine.advance(u)
    got, want = np.concatenate(got), np.array(want)
    assert got.shape == (120 * N, len(model.output_names))
    scale = np.abs(want).max(axis=0)
    assert np.all(scale > 0)
    assert np.max(np.abs(got - want) / scale) < 1e-11
    assert _rel(multi.x, fine.x) < 1e-11


def test_one_substep_is_the_single_rate_plant_bit_for_bit():
    model = demo_model(5, seed=1, feedthrough=1e-9)
    one = MultiRatePlant.from_model(model, 5000.0, 1)
    single = DiscretePlant(model.discretize(1 / 5000.0))
    for name in 'abcd':
        assert np.array_equal(getattr(one, name), getattr(single, name)), name
    u = np.ones(len(model.input_names))
    assert np.array_equal(one.fine_outputs(u, one.outputs()), single.outputs()[None])


@pytest.mark.parametrize('bad', [0, -3, 2.5, True, 'ten', 10 ** 6])
def test_bad_substeps_name_the_value(bad):
    with pytest.raises(ConfigError, match='substeps') as err:
        MultiRatePlant.from_model(demo_model(3), RATE, bad)
    assert repr(bad) in str(err.value)


def test_non_modal_fine_plant_uses_the_dense_path():
    """A weakly coupled A_f (not modal): same closed forms through the dense products."""
    model = demo_model(4, seed=9)
    sys = model.discretize(1 / (RATE * N))
    a = sys.A.copy()
    a[1, 4 + 2] += 1e-5
    fine_sys = control.ss(a, sys.B, sys.C, sys.D, sys.dt, inputs=sys.input_labels,
                          outputs=sys.output_labels)
    multi = MultiRatePlant(fine_sys, N)
    assert not multi.modal
    assert _rel(multi.a, np.linalg.matrix_power(a, N)) < 1e-13
    b_sum = sum(np.linalg.matrix_power(a, j) for j in range(N)) @ sys.B
    assert _rel(multi.b, b_sum) < 1e-13


def _laws(dt):
    return [tcp_damper(['x', 'y'], 3000.0, Dynamics(2, 250.0, 0.5, 1), dt),
            ProofMassActuator(['x'], 2.0, 1000.0, dt)]


def test_offline_loop_and_sampled_loop_model_the_same_timing():
    """
    simulate() and loop_system() of the multi-rate plant agree, at both rates.

    The LoopSystem stepped as a matrix recursion gives the exchange outputs and (with
    full_rate_loop_outputs) the full-rate outputs of simulate(); and that loop equals the
    single-rate loop at the exchange rate, so the analytic FRFs need no other timing.
    """
    model = demo_model(8, seed=5)
    dt, n = 1 / RATE, 300
    multi = MultiRatePlant.from_model(model, RATE, N)
    rng = np.random.default_rng(4)
    exc = excitation_matrix(multi, TCP, 50 * rng.standard_normal((n, 3)), n)
    run = simulate(multi, _laws(dt), exc, full_rate=True)
    assert run.y_full.shape == (n * N, len(model.output_names))
    assert np.array_equal(run.y_full[::N], run.y)

    loop = closed_loop_system(MultiRatePlant.from_model(model, RATE, N), _laws(dt))
    c_fine, d_fine = full_rate_loop_outputs(multi, loop)
    z = np.zeros(loop.a.shape[0])
    ys, fine = [], []
    for e in exc:
        ys.append(loop.c_y @ z)
        fine.append((c_fine @ z + d_fine @ e).reshape(N - 1, -1))
        z = loop.a @ z + loop.b @ e
    scale = np.abs(run.y).max(axis=0)
    assert np.max(np.abs(np.array(ys) - run.y) / scale) < 1e-10
    full = run.y_full.reshape(n, N, -1)[:, 1:]
    assert np.max(np.abs(np.array(fine) - full) / scale) < 1e-10

    single = closed_loop_system(DiscretePlant(model.discretize(dt)), _laws(dt))
    assert loop.augmented == single.augmented
    assert _rel(loop.a, single.a) < 1e-12 and _rel(loop.b, single.b) < 1e-12
    assert np.array_equal(loop.c_y, single.c_y) and np.array_equal(loop.c_u, single.c_u)


def test_full_rate_of_a_single_rate_plant_is_its_outputs():
    model = demo_model(3, seed=2)
    plant = DiscretePlant(model.discretize(1e-3))
    exc = np.ones((20, len(model.input_names)))
    run = simulate(plant, [], exc, full_rate=True)
    assert np.array_equal(run.y_full, run.y)
    assert simulate(plant, [], exc).y_full is None


def test_fullrate_layout_picks_the_tcp_columns_of_every_substep():
    model = demo_model(3, seed=1)
    names = model.output_names
    layout = fullrate_layout(names, 4)
    assert layout.topic == TCP_STATE_FULLRATE
    assert layout.joints[:4] == ['tcp_x@0', 'tcp_y@0', 'tcp_z@0', 'tcp_x@1']
    rows = np.arange(4 * len(names), dtype=float).reshape(4, len(names))
    pos, vel, eff = layout.values(rows.reshape(-1))
    assert eff.size == 0                # the TCP joints have no effort
    for i, joint in enumerate(layout.joints):
        axis, j = joint[4], int(joint.split('@')[1])
        assert pos[i] == rows[j, names.index(f'tcp_displacement_{axis}')]
        assert vel[i] == rows[j, names.index(f'tcp_velocity_{axis}')]
    no_tcp = [n for n in names if not n.startswith('tcp_')]
    assert fullrate_layout(no_tcp, 4) is None


def test_fine_outputs_refuse_an_array_they_cannot_write_in_place():
    plant = MultiRatePlant.from_model(demo_model(3, seed=1), RATE, 4)
    u = np.zeros(len(plant.input_names))
    wide = np.zeros((4, 2 * len(plant.output_names)))
    with pytest.raises(ValueError, match='C-contiguous'):
        plant.fine_outputs(u, plant.outputs(), wide[:, ::2])
