"""
The one builder of the sampled closed loop against python-control's feedback.

python-control knows nothing of the lockstep convention, so the plant is handed to it as the
proper discrete system it is: ``x_{k+1} = A x_k + B u_k``, ``w_{k+1} = u_k`` and
``y_k = C x_k + D w_k`` (the feed-through acts with the input of the step before). The
controllers are discrete state spaces from the plant outputs to the plant inputs, summed, and
``control.feedback(..., sign=+1)`` closes ``u = K y + e``. Transfer matrices from ``e`` to
``y`` and to ``u`` are compared at points of the z-plane, and so are the spectral radii.
"""
import control
import numpy as np
import pytest

from fixtures.demo_model import demo_model
from pentapod_damper.laws import Dynamics, strut_axial_damper, tcp_damper
from pentapod_sim.errors import ConfigError
from pentapod_sim.sim.closed_loop import closed_loop_system
from pentapod_sim.sim.controllers import DiscreteController, loop_system
from pentapod_sim.sim.stepping import DiscretePlant

DT = 1.0 / 2000.0
#: z on the unit circle (sampled FRF) and off it (transient behaviour)
Z = [np.exp(1j * 2 * np.pi * f * DT) for f in (3.0, 47.0, 311.0, 960.0)] + [1.3, 0.4 - 0.7j]


def _plant(n: int, n_in: int, n_out: int, feedthrough_rows: list[int], seed: int):
    """Random stable discrete plant (names u0.., y0..) with D only on ``feedthrough_rows``."""
    rng = np.random.default_rng(seed)
    q, _ = np.linalg.qr(rng.standard_normal((n, n)))
    a = q @ np.diag(rng.uniform(-0.9, 0.9, n)) @ q.T
    b, c = rng.standard_normal((n, n_in)), rng.standard_normal((n_out, n))
    d = np.zeros((n_out, n_in))
    d[feedthrough_rows] = 0.3 * rng.standard_normal((len(feedthrough_rows), n_in))
    return a, b, c, d, [f'u{i}' for i in range(n_in)], [f'y{i}' for i in range(n_out)]


def _selector(names, ports) -> np.ndarray:
    """(len(ports), len(names)) matrix picking ``ports`` out of ``names``."""
    return np.eye(len(names))[[list(names).index(p) for p in ports]]


def _reference(a, b, c, d, inputs, outputs, controllers):
    """python-control's closed loops e -> y and e -> u of the lockstep plant and controllers."""
    n, m = a.shape[0], b.shape[1]
    plant = control.ss(np.block([[a, np.zeros((n, m))], [np.zeros((m, n + m))]]),
                       np.vstack([b, np.eye(m)]), np.hstack([c, d]), 0.0, DT)
    law = control.ss([], [], [], np.zeros((m, len(outputs))), DT)
    for k in controllers:
        s_in, s_out = _selector(inputs, k.actuator_ports).T, _selector(outputs, k.sensor_ports)
        if k.n_states:
            law = law + control.ss(k.a, k.b @ s_out, s_in @ k.c, s_in @ k.d @ s_out, DT)
        else:
            law = law + control.ss([], [], [], s_in @ k.d @ s_out, DT)
    to_y = control.feedback(plant, law, sign=1)
    to_u = control.feedback(control.ss([], [], [], np.eye(m), DT), law * plant, sign=1)
    return to_y, to_u


def _ours(loop, d, z):
    """Transfer matrices e -> y, e -> u of a LoopSystem at z (the D u_{k-1} term if left out)."""
    resolvent = np.linalg.solve(z * np.eye(loop.a.shape[0]) - loop.a, loop.b)
    u = loop.c_u @ resolvent + np.eye(loop.b.shape[1])
    y = loop.c_y @ resolvent
    if not loop.augmented:
        y = y + d @ u / z
    return y, u


def _assert_same_loop(loop, plant, controllers):
    a, b, c, d, inputs, outputs = plant
    to_y, to_u = _reference(a, b, c, d, inputs, outputs, controllers)
    for z in Z:
        y, u = _ours(loop, d, z)
        np.testing.assert_allclose(y, to_y(z), rtol=1e-9, atol=1e-12 * np.abs(y).max())
        np.testing.assert_allclose(u, to_u(z), rtol=1e-9, atol=1e-12 * np.abs(u).max())
    ours = np.abs(np.linalg.eigvals(loop.a)).max()
    assert ours == pytest.approx(np.abs(to_y.poles()).max(), rel=1e-9)


def _dynamic(sensors, actuators, n, seed, feedthrough=0.2) -> DiscreteController:
    rng = np.random.default_rng(seed)
    return DiscreteController(sensors, actuators, np.diag(rng.uniform(0.2, 0.8, n)),
                              rng.standard_normal((n, len(sensors))),
                              rng.standard_normal((len(actuators), n)),
                              feedthrough * rng.standard_normal((len(actuators), len(sensors))))


@pytest.mark.parametrize('feedthrough_rows', [[], [1, 3]], ids=['no-D', 'D-read'])
def test_static_gain_loop_is_control_feedback(feedthrough_rows):
    """A full static gain: augmented with u_{k-1} exactly when K D != 0."""
    plant = _plant(6, 3, 4, feedthrough_rows, seed=1)
    gain = 0.4 * np.random.default_rng(2).standard_normal((3, 4))
    static = DiscreteController.static(plant[5], plant[4], gain)
    loop = loop_system(*plant, [static])
    assert loop.augmented == bool(feedthrough_rows)
    _assert_same_loop(loop, plant, [static])


@pytest.mark.parametrize('feedthrough_rows,augmented', [([0], True), ([2], False), ([], False)],
                         ids=['D-read', 'D-unread', 'no-D'])
def test_controllers_with_states_on_shared_ports_are_control_feedback(feedthrough_rows,
                                                                      augmented):
    """A dynamic and two static controllers summed on a shared actuator port (u1)."""
    plant = _plant(5, 3, 4, feedthrough_rows, seed=3)
    controllers = [_dynamic(['y0', 'y1'], ['u0', 'u1'], 3, seed=4),
                   DiscreteController.static(['y3'], ['u1', 'u2'], [[0.5], [-0.7]]),
                   DiscreteController.static(['y1'], ['u1'], [[0.3]])]
    loop = loop_system(*plant, controllers)
    assert loop.augmented == augmented
    assert loop.a.shape[0] == 5 + 3 + (3 if augmented else 0)
    _assert_same_loop(loop, plant, controllers)


def test_controller_states_fed_through_the_plant_augment_the_loop():
    """No law answers at once (K D = 0), yet the states read y_k = C x_k + D u_{k-1}."""
    plant = _plant(4, 2, 3, [0], seed=5)
    controllers = [_dynamic(['y0', 'y2'], ['u0', 'u1'], 2, seed=6, feedthrough=0.0),
                   _dynamic(['y2'], ['u1'], 1, seed=7)]
    loop = loop_system(*plant, controllers)
    assert loop.augmented and loop.a.shape[0] == 4 + 3 + 2
    _assert_same_loop(loop, plant, controllers)


@pytest.fixture(scope='module')
def demo_plant() -> DiscretePlant:
    model = demo_model(n_modes=5, f_min=40.0, f_max=500.0, zeta=0.01, feedthrough=3e-8,
                       inputs=['tcp_force_x', 'tcp_force_y', 'strut1_axial_force'])
    return DiscretePlant(model.discretize(DT))


def _matrices(plant: DiscretePlant):
    return (plant.a, plant.b, plant.c, plant.d, list(plant.input_names),
            list(plant.output_names))


def test_closed_loop_system_of_laws_is_control_feedback(demo_plant):
    """The path of the study: laws with a low-pass and a memoryless one on the demo plant."""
    laws = [tcp_damper(['x', 'y'], 2500.0, Dynamics(2, 250.0, 0.4, 1), DT),
            strut_axial_damper([1], 4.0e4)]
    loop = closed_loop_system(demo_plant, laws)
    _assert_same_loop(loop, _matrices(demo_plant), [law.discrete_model() for law in laws])


def _static_loop(plant, gain):
    static = DiscreteController.static(plant.output_names, plant.input_names, gain)
    return loop_system(plant.a, plant.b, plant.c, plant.d, plant.input_names,
                       plant.output_names, [static])


def test_a_static_gain_with_feed_through_is_the_augmented_loop(demo_plant):
    """A gain reading displacements with feed-through: the augmented loop of python-control."""
    outputs = list(demo_plant.output_names)
    gain = np.zeros((len(demo_plant.input_names), len(outputs)))
    gain[0, outputs.index('tcp_displacement_x')] = -2.0e6
    gain[:, outputs.index('tcp_velocity_y')] = -800.0
    loop = _static_loop(demo_plant, gain)
    assert loop.augmented
    static = DiscreteController.static(outputs, demo_plant.input_names, gain)
    _assert_same_loop(loop, _matrices(demo_plant), [static])


def test_a_static_gain_of_the_wrong_shape_is_named(demo_plant):
    with pytest.raises(ConfigError, match=r'matrix d has shape \(2, 2\), expected \(3, '):
        _static_loop(demo_plant, np.eye(2))
