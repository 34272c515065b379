"""
Lobes of the machine with a scenario's laws, and the cutting node's parameters and model.

The sampled loop's TCP FRF is checked against python-control's zero-order-hold discretisation
and feedback (an independent construction); the averaged regenerative loop (the cutting
node's linear model) against the zero-order lobes of that FRF: its spectral radius crosses 1
within 3 % of the predicted depth; the laws of a scenario come from the node parameter classes
and equal pentapod_damper's own reading of the file.
"""
import math

import control
import numpy as np
import pytest

from pentapod_damper.laws import Dynamics, tcp_damper
from pentapod_damper.scenario_laws import scenario_laws
from pentapod_sim.errors import ConfigError
from pentapod_sim.machining.cutting_model import (
    averaged_stiffness,
    MAX_MODEL_DELAY_STEPS,
    regenerative_controller,
)
from pentapod_sim.machining.cutting_spec import parse_spec_message, spec_message
from pentapod_sim.machining.loop_lobes import check_runs, lobe_bottoms, loop_lobes
from pentapod_sim.machining.materials import load_machining
from pentapod_sim.machining.milling_cut import directional_factors
from pentapod_sim.machining.sampled_floquet import check_speed
from pentapod_sim.machining.sampled_tcp import sampled_tcp_frf
from pentapod_sim.machining.tcp_frf import tcp_plant, TcpMode
from pentapod_sim.nodes.parameter_tables import CuttingParams
from pentapod_sim.scenario.files import read_scenario, scenario_names
from pentapod_sim.scenario.laws import scenario_loop_laws
from pentapod_sim.sim.controllers import controller_of
from pentapod_sim.sim.stability import plant_radius

PLANT = tcp_plant([TcpMode(150.0, 0.04, 4e6, (1.0, 0.3)), TcpMode(170.0, 0.05, 5e6, (-0.3, 1.0))])
DT = 1e-4
OPERATION = 'aluminium_half_down'


def test_sampled_tcp_frf_is_python_controls_discrete_loop():
    """Held force to sampled displacement, closed with a filtered damper: control.feedback."""
    law = tcp_damper(['x', 'y'], 400.0, Dynamics(1, 300.0), DT)
    got = sampled_tcp_frf(PLANT, [law], DT, 5.0, 1000.0)
    a, b, c, d = PLANT.state_matrices()
    plant_d = control.c2d(control.ss(a, b, c, d), DT, 'zoh')
    ctrl = controller_of(law)
    pick = np.zeros((2, len(PLANT.output_names)))          # the damper reads the velocities
    for i, port in enumerate(ctrl.sensor_ports):
        pick[i, PLANT.output_names.index(port)] = 1.0
    k = control.ss(ctrl.a, ctrl.b @ pick, ctrl.c, ctrl.d @ pick, DT)
    loop = control.feedback(plant_d, k, sign=+1)           # u = e + K y
    freq = got.frf.freq[::97]
    ref = loop(np.exp(2j * np.pi * freq * DT))[:2]          # displacement rows, (2, 2, F)
    np.testing.assert_allclose(got.frf.matrix[:, :, ::97], ref, rtol=1e-7,
                               atol=1e-9 * np.abs(ref).max())
    assert got.spectral_radius < 1 and got.frf.freq[0] >= 5.0


class _Pushing:
    """Velocity feedback with the wrong sign: negative damping."""

    sensor_ports = ['tcp_velocity_x', 'tcp_velocity_y']
    actuator_ports = ['tcp_force_x', 'tcp_force_y']

    def linear_gain(self):
        return 2000.0 * np.eye(2)


def test_an_unstable_loop_has_no_lobes():
    law = _Pushing()
    with pytest.raises(ConfigError, match='unstable'):
        sampled_tcp_frf(PLANT, [law], DT, 5.0, 1000.0)


@pytest.mark.parametrize('gain', [0.0, 400.0])
def test_the_cutting_nodes_linear_model_is_stable_exactly_below_the_lobes(gain):
    """The averaged regenerative loop crosses the unit circle within 3 % of the lobe depth."""
    laws = [tcp_damper(['x', 'y'], gain)] if gain else []
    table = load_machining()
    lobes = loop_lobes(PLANT, laws, DT, table, [OPERATION], np.linspace(1000, 24000, 300),
                       'x').operations[OPERATION]
    controllers = [controller_of(law) for law in laws]
    for speed, depth, freq in lobe_bottoms(lobes, 4, DT)[:3]:
        radius = {}
        for factor in (0.97, 1.03):
            model = regenerative_controller(table.conditions(OPERATION, speed, factor * depth),
                                            DT)
            radius[factor], at = plant_radius(PLANT, [*controllers, model], DT)
        assert radius[0.97] < 1.0 < radius[1.03], (speed, radius)
        assert at == pytest.approx(freq, rel=0.02)          # the unstable pole is the chatter


def test_the_linear_model_is_the_mean_force_of_the_regenerative_chip():
    cond = load_machining().conditions(OPERATION, 2000.0, 1e-3)
    cut = cond.cut
    k = averaged_stiffness(cond)
    np.testing.assert_allclose(k, 1e-3 * 4 * cut.tangential_coefficient / (4 * math.pi)
                               * directional_factors(cut))           # feed along x: R = I
    model = regenerative_controller(cond, DT)
    whole = int(cond.tooth_period / DT)
    assert model.n_states == 2 * (whole + 1) and np.array_equal(model.d, k)
    # constant displacement: no regenerative chip, no force (d + c summed over the delay)
    assert np.allclose(model.d + model.c.reshape(2, -1, 2).sum(axis=1), 0.0, atol=1e-6)
    slow = load_machining().conditions(OPERATION, 10.0, 1e-3)
    with pytest.raises(ConfigError, match=f'up to {MAX_MODEL_DELAY_STEPS} steps'):
        regenerative_controller(slow, DT)


def test_check_runs_pick_a_lobe_bottom_and_size_the_runs():
    table = load_machining()
    lobes = loop_lobes(PLANT, [], DT, table, [OPERATION], np.linspace(1000, 24000, 300),
                       'x').operations[OPERATION]
    point = check_runs(PLANT, [], DT, table, lobes)
    bottoms = lobe_bottoms(lobes, 4, DT)
    assert [b[1] for b in bottoms] == sorted(b[1] for b in bottoms)
    # a bottom moved to a whole number of steps per tooth period (>= 50), the limit there
    assert point.speed in [check_speed(b[0], 4, DT) for b in bottoms[:8]]
    assert point.depth == pytest.approx(float(lobes.limit.envelope([point.speed]).depth[0]))
    steps = 60.0 / (4 * point.speed * DT)
    assert steps == pytest.approx(round(steps), abs=1e-6) and round(steps) >= 50
    below, above = point.runs
    assert (below.expected, above.expected) == ('stable', 'chatter')
    assert below.growth_rate < 0 < above.growth_rate
    assert above.params['axial_depth'] == pytest.approx(1.2 * point.depth)
    assert below.conditions(table) == table.conditions(OPERATION, point.speed, 0.8 * point.depth)
    assert below.settle == pytest.approx(0.25 * below.duration)


def test_cutting_parameters_are_the_operation_with_overrides():
    table = load_machining()
    plain = CuttingParams.build({'spindle_speed': 900.0, 'axial_depth': 5e-4}, 'test')
    assert plain.spec().conditions == table.conditions(OPERATION, 900.0, 5e-4)
    steel = CuttingParams.build({'operation': 'steel_half_down', 'teeth': 2, 'milling': 'up',
                                 'radial_immersion': 0.25, 'radial_ratio': 0.0,
                                 'edge_radial': 0.0, 'feed_per_tooth': 2e-4}, 'test')
    cond = steel.spec('mill').conditions
    k_tc, _, k_te, _ = table.materials['steel'].coefficients()
    assert (cond.cut.teeth, cond.cut.entry_angle, cond.cut.radial_ratio) == (2, 0.0, 0.0)
    assert cond.cut.exit_angle == pytest.approx(math.acos(0.5))
    assert (cond.cut.tangential_coefficient, cond.edge_tangential, cond.feed_per_tooth) == (
        k_tc, k_te, 2e-4)
    with pytest.raises(ConfigError, match="did you mean 'steel_half_down'"):
        CuttingParams.build({'operation': 'steel_half_dwn'}, 'test').spec()


def test_the_cutting_record_survives_its_message():
    spec = CuttingParams.build({'spindle_speed': 1234.5, 'axial_depth': 3.3e-4,
                                'teeth': 3}, 'test').spec('mill')
    assert parse_spec_message(spec_message(spec)) == spec
    text = spec_message(spec)
    with pytest.raises(ConfigError, match='lacks teeth$'):
        parse_spec_message(text.replace('"teeth": 3, ', ''))
    with pytest.raises(ConfigError, match='teeth = 3.5 is not an integer'):
        parse_spec_message(text.replace('"teeth": 3', '"teeth": 3.5'))
    with pytest.raises(ConfigError, match='axial_depth = -1.0 m must be > 0'):
        parse_spec_message(text.replace('"axial_depth": 0.00033', '"axial_depth": -1.0'))
    with pytest.raises(ConfigError, match='not a cutting record'):
        parse_spec_message('[1, 2]')


@pytest.mark.parametrize('name', scenario_names())
def test_a_scenarios_laws_are_those_pentapod_damper_reads(name):
    """The registry's way (parameter classes) and pentapod_damper's reading of the file agree."""
    ours = scenario_loop_laws(name, 2e-4)
    theirs = scenario_laws(read_scenario(name).sections, 2e-4)
    assert [type(law) for law in ours] == [type(law) for law in theirs]
    for a, b in zip(ours, theirs):
        ca, cb = controller_of(a), controller_of(b)
        assert ca.actuator_ports == cb.actuator_ports
        for m in 'abcd':
            assert np.array_equal(getattr(ca, m), getattr(cb, m))
    assert (name == 'baseline') == (not ours)


def test_a_node_that_does_not_say_its_laws_is_refused(tmp_path):
    path = tmp_path / 'mine.yaml'
    path.write_text("mine:\n  ros__parameters:\n    node_class: 'pentapod_damper.nodes."
                    "example_controller:ExampleController'\n    gain: 100.0\n"
                    'plant:\n  ros__parameters:\n    sources: [mine]\n')
    laws = scenario_loop_laws(path)             # a registry class: it says (a TCP damper in x)
    assert [law.actuator_ports for law in laws] == [['tcp_force_x']]
    path.write_text("mine:\n  ros__parameters:\n    node_class: 'collections:OrderedDict'\n"
                    'plant:\n  ros__parameters:\n    sources: [mine]\n')
    with pytest.raises(ConfigError, match="node 'mine' .* does not say which laws"):
        scenario_loop_laws(path)
