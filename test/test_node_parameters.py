"""
Nodes declare what their parameter classes say, refuse unknown overrides, build the offline laws.

Nodes are created in this process (rclpy, own context on the session's ROS domain); their
descriptors are read back through the ``describe_parameters`` service, as ``ros2 param
describe`` reads them.
"""
import math
import os
from pathlib import Path

import numpy as np
import pytest
from rcl_interfaces.msg import ParameterType
from rcl_interfaces.srv import DescribeParameters, GetParameters
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter, parameter_value_to_python

from fixtures.demo_model import demo_model
from pentapod_damper.node_parameters import DamperParams, PmaParams
from pentapod_damper.nodes.damper_node import DamperNode
from pentapod_damper.nodes.example_controller import ExampleController
from pentapod_damper.nodes.pma_node import PmaNode
from pentapod_damper.scenario_laws import scenario_laws
from pentapod_sim.errors import ConfigError
from pentapod_sim.nodes.exciter_node import ExciterNode
from pentapod_sim.nodes.plant_node import PlantNode
from pentapod_sim.nodes.recorder_node import RecorderNode
from pentapod_sim.parameters import ROS_NODE_PARAMETERS
from pentapod_sim.paths import scenario_dir
from pentapod_sim.scenario.files import read_scenario

TYPES = {'bool': ParameterType.PARAMETER_BOOL, 'integer': ParameterType.PARAMETER_INTEGER,
         'double': ParameterType.PARAMETER_DOUBLE, 'string': ParameterType.PARAMETER_STRING,
         'double[]': ParameterType.PARAMETER_DOUBLE_ARRAY,
         'integer[]': ParameterType.PARAMETER_INTEGER_ARRAY,
         'string[]': ParameterType.PARAMETER_STRING_ARRAY}


@pytest.fixture
def ctx():
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=int(os.environ.get('ROS_DOMAIN_ID', '0')))
    yield context
    rclpy.shutdown(context=context)


def _ask(ctx, node, service: str, srv_type, request):
    """Call one of the node's parameter services from another node; return the response."""
    client_node = Node('asker', context=ctx)
    executor = SingleThreadedExecutor(context=ctx)
    try:
        executor.add_node(node)
        executor.add_node(client_node)
        client = client_node.create_client(srv_type,
                                           f'{node.get_fully_qualified_name()}/{service}')
        assert client.wait_for_service(timeout_sec=30.0)
        future = client.call_async(request)
        executor.spin_until_future_complete(future, timeout_sec=30.0)
        assert future.done()
        return future.result()
    finally:
        executor.shutdown()
        client_node.destroy_node()


def _nodes(tmp_path):
    model_file = demo_model(3).save(tmp_path / 'model.npz')
    return [
        (PlantNode, ['-p', f'model_file:={model_file}', '-p', 'sources:=[exciter]',
                     '-p', 'source_ports.exciter:=[tcp_force_x]'],
         {'model_file': str(model_file), 'sources': ('exciter',),
          'source_ports.exciter': ('tcp_force_x',)}),
        (ExciterNode, [], {'source_name': 'exciter'}),
        (RecorderNode, ['-p', f'output_dir:={tmp_path / "bags"}'],
         {'output_dir': str(tmp_path / 'bags')}),
        (DamperNode, ['-p', "tcp_directions:=['x']", '-p', 'tcp_gain:=5'],
         {'tcp_directions': ('x',), 'source_name': 'damper', 'tcp_gain': 5.0}),
        (PmaNode, [], {'source_name': 'pma'}),
        (ExampleController, [], {}),
    ]


def _python(value):
    """A parameter value read from a node, lists as tuples (as the parameter classes hold them)."""
    value = parameter_value_to_python(value)
    return tuple(value) if isinstance(value, list) else value


@pytest.mark.parametrize('index', range(6), ids=['plant', 'exciter', 'recorder', 'damper',
                                                 'pma', 'example_controller'])
def test_declared_descriptors_and_values_match_the_parameter_class(ctx, tmp_path, index):
    """What ``ros2 param describe`` and ``ros2 param get`` show is the class's declaration."""
    cls, args, expected = _nodes(tmp_path)[index]
    node = cls(context=ctx, cli_args=['--ros-args', *args])
    try:
        declared = set(node.list_parameters([], 0).names) - set(ROS_NODE_PARAMETERS)
        specs = {p.field: p for p in cls.Params.ros_params()}
        instances = {f'source_ports.{s}' for s in expected.get('sources', [])}
        assert declared == {p.name for p in specs.values() if p.keys is None} | instances
        names = sorted(declared)
        described = _ask(ctx, node, 'describe_parameters', DescribeParameters,
                         DescribeParameters.Request(names=names)).descriptors
        values = _ask(ctx, node, 'get_parameters', GetParameters,
                      GetParameters.Request(names=names)).values
        for name, desc, value in zip(names, described, values):
            param = specs[name.split('.')[0]]
            assert desc.name == name
            assert desc.type == TYPES[param.type], name
            assert desc.description == param.full_description(), name
            if param.unit:
                assert desc.description.endswith(f'[{param.unit}]')
            assert desc.read_only == param.read_only, name
            assert desc.additional_constraints == param.range, name
            ranges = {'double': list(desc.floating_point_range),
                      'integer': list(desc.integer_range)}.get(param.type, [])
            if param.bounds is not None and not param.is_array:
                assert [(r.from_value, r.to_value) for r in ranges] == [param.bounds]
            else:
                assert not desc.floating_point_range and not desc.integer_range
            want = param.ros_value(expected.get(name, param.default))
            assert _python(value) == (tuple(want) if param.is_array else want), name
            typed = getattr(node.params, param.field)
            assert (typed[name.split('.')[1]] if param.keys else typed) == \
                expected.get(name, param.default), name
    finally:
        if isinstance(node, RecorderNode):
            node.close()
        node.destroy_node()


def _facts(law):
    """What defines a law, for comparing a node's law with the offline one."""
    facts = {'type': type(law).__name__, 'actuators': law.actuator_ports,
             'sensors': law.sensor_ports}
    for attr in ('gains', 'mass', 'gain', 'dt', 'highpass_hz', 'stroke_limit', 'force_limit',
                 'sos'):
        value = getattr(law, attr, None)
        facts[attr] = None if value is None else np.asarray(value).tolist()
    return facts


def _law_sections():
    """(scenario file, node section) of every damper and PMA node of the shipped scenarios."""
    cases = []
    for path in sorted(scenario_dir().glob('*.yaml')):
        for node in read_scenario(path).nodes:
            if node.executable in ('damper', 'pma'):
                cases.append((path, node.name))
    return cases


MINIMAL = """
/**:
  ros__parameters:
    sample_rate: 2000.0
plant:
  ros__parameters:
    sources: [damper_defaults, pma_defaults]
damper_defaults:
  ros__parameters:
    tcp_directions: ['y']
    bending_struts: [3, 1]
pma_defaults:
  ros__parameters:
    highpass_hz: 3.0
"""


def test_shipped_scenarios_have_damper_and_pma_nodes():
    """Both kinds are covered by the comparison below."""
    assert {name.startswith('pma') for _, name in _law_sections()} == {True, False}


@pytest.mark.parametrize(('path', 'name'), _law_sections() + [(None, 'damper_defaults'),
                                                              (None, 'pma_defaults')],
                         ids=lambda v: Path(v).stem if isinstance(v, Path) else str(v))
def test_offline_laws_equal_the_nodes_laws(ctx, tmp_path, path, name):
    """A scenario's laws built offline equal what its node builds from the same file."""
    if path is None:
        path = tmp_path / 'minimal.yaml'
        path.write_text(MINIMAL)
    sections = read_scenario(path).sections
    is_pma = name.startswith('pma')
    dt = (PmaParams if is_pma else DamperParams).build(sections[name], name).dt
    offline = scenario_laws({name: sections[name]}, dt)
    cls = PmaNode if is_pma else DamperNode
    node = cls(context=ctx, cli_args=['--ros-args', '-r', f'__node:={name}',
                                      '--params-file', str(path)])
    try:
        online = [node.law] if is_pma else list(node.laws.values())
        assert offline and [_facts(law) for law in online] == [_facts(law) for law in offline]
        assert node.source_name == name
    finally:
        node.destroy_node()
    if name == 'pma_defaults':     # defaults and the shared sample rate reached both sides
        assert math.isclose(node.law.dt, 1 / 2000.0) and node.law.mass == PmaParams.proof_mass
    if name == 'damper_defaults':
        assert list(node.laws) == ['bending_gain', 'tcp_gain']
        assert set(node.laws['tcp_gain'].gains) == {DamperParams.tcp_gain}


def test_damper_gains_change_while_running_and_read_only_ones_do_not(ctx):
    node = DamperNode(context=ctx, cli_args=['--ros-args', '-p', "tcp_directions:=['x']"])
    try:
        assert node.set_parameters([Parameter('tcp_gain', value=123.0)])[0].successful
        assert list(node.laws['tcp_gain'].gains) == [123.0] and node.params.tcp_gain == 123.0
        assert not node.set_parameters([Parameter('tcp_gain', value=-1.0)])[0].successful
        assert not node.set_parameters([Parameter('tcp_directions', value=['y'])])[0].successful
        assert list(node.laws['tcp_gain'].gains) == [123.0] and node.params.tcp_gain == 123.0
        assert node.params.tcp_directions == ('x',)
    finally:
        node.destroy_node()


def test_drive_iff_gain_changes_while_running_and_rebuilds_the_cascade(ctx):
    """HAC-LAC's IFF gain set like the other gains: the cascade is FeedDrives with the new g."""
    from pentapod_sim.plant.drives import load_drives
    from pentapod_sim.sim.drives import FeedDrives
    from pentapod_sim.sim.law_models import Dynamics
    rate = 5000.0
    node = DamperNode(context=ctx, cli_args=[
        '--ros-args', '-p', 'drive_struts:=[1, 3]', '-p', 'drive_iff_gain:=150.0',
        '-p', 'drive_iff_omega:=2.3', '-p', 'filter_order:=2', '-p', 'bandwidth_hz:=500.0',
        '-p', 'delay_steps:=1', '-p', f'sample_rate:={rate}'])

    def want(g):
        return FeedDrives(load_drives(), (1, 3), g, 2.3, Dynamics(2, 500.0, delay_steps=1)
                          ).discrete(1 / rate)
    try:
        law = node.laws['drive_iff_gain']
        law.step(np.ones(len(law.sensor_ports)))        # a state that must carry on
        state = law._state.copy()
        before = node.model_text()
        assert node.set_parameters([Parameter('drive_iff_gain', value=300.0)])[0].successful
        assert node.params.drive_iff_gain == 300.0
        mine, ref = node.linear_model(), want(300.0)
        assert mine.sensor_ports == ref.sensor_ports
        for m in 'abcd':
            assert np.array_equal(getattr(mine, m), getattr(ref, m)), m
        assert not np.array_equal(ref.c, want(150.0).c) or not np.array_equal(ref.b, want(150.0).b)
        assert np.array_equal(law._state, state)
        assert node.model_text() != before             # what is published for the check
        # to 0 would drop the load cells the node subscribed: refused, nothing changed
        result = node.set_parameters([Parameter('drive_iff_gain', value=0.0)])[0]
        assert not result.successful and 'load cells' in result.reason
        assert not node.set_parameters([Parameter('drive_iff_gain', value=-1.0)])[0].successful
        assert node.params.drive_iff_gain == 300.0
        assert np.array_equal(node.linear_model().d, ref.d)
    finally:
        node.destroy_node()
    alone = DamperNode(context=ctx, cli_args=['--ros-args', '-p', 'drive_struts:=[2]'])
    try:
        result = alone.set_parameters([Parameter('drive_iff_gain', value=10.0)])[0]
        assert not result.successful and 'load cells' in result.reason
        assert alone.params.drive_iff_gain == 0.0
    finally:
        alone.destroy_node()


def _params_file(tmp_path, shared: str, own: str) -> str:
    path = tmp_path / 'p.yaml'
    path.write_text(f'/**:\n  ros__parameters:\n    {shared}\n'
                    f'damper:\n  ros__parameters:\n    tcp_directions: [x]\n    {own}\n')
    return str(path)


def test_another_kinds_parameters_are_ignored_misspelt_ones_refused(ctx, tmp_path):
    """The rule of a shared section: a name some node kind declares is left to that kind."""
    for shared, own in (('proof_mass: 2.0', 'tcp_gain: 10.0'),     # proof_mass: the PMA's
                        ('proof_mass: 2.0', 'proof_mass: 2.0')):   # (the runner refuses this)
        path = _params_file(tmp_path, shared, own)
        node = DamperNode(context=ctx, cli_args=['--ros-args', '--params-file', path])
        try:
            assert not node.has_parameter('proof_mass')
            assert node.params.tcp_gain == (10.0 if 'tcp_gain' in own else DamperParams.tcp_gain)
        finally:
            node.destroy_node()
    path = _params_file(tmp_path, 'tcp_gian: 1.0', 'tcp_gain: 1.0')
    with pytest.raises(ConfigError) as err:
        DamperNode(context=ctx, cli_args=['--ros-args', '--params-file', path])
    assert str(err.value) == "node 'damper': unknown parameter 'tcp_gian'; did you mean " \
                             "'tcp_gain'?"


@pytest.mark.parametrize(('kwargs', 'message'), [
    ({'cli_args': ['--ros-args', '-p', "tcp_directions:=['x']"],
      'parameter_overrides': [Parameter('axial_gian', value=1.0)]},
     "unknown parameter 'axial_gian'; did you mean 'axial_gain'?"),
    ({'cli_args': ['--ros-args', '-p', 'tcp_directions:=[x]', '-p', 'tcp_gain:=-5.0']},
     'parameter tcp_gain = -5.0 N s/m: must lie in [0, 1e+09]'),
    ({'cli_args': ['--ros-args', '-p', 'tcp_directions:=[x]', '-p', 'filter_hold:=y']},
     'parameter filter_hold = True: expected a text (YAML reads a bare y, n, yes, no, on, off '
     'as true or false: quote it)'),
    ({'cli_args': ['--ros-args', '-p', 'tcp_directions:=[]']},
     'a parameter override cannot be declared'),
])
def test_damper_refuses_unknown_or_bad_overrides(ctx, kwargs, message):
    with pytest.raises(ConfigError) as err:
        DamperNode(context=ctx, **kwargs)
    assert str(err.value).startswith(f"node 'damper': {message}")


def test_plant_refuses_source_ports_of_no_source(ctx, tmp_path):
    model_file = demo_model(3).save(tmp_path / 'model.npz')
    with pytest.raises(ConfigError, match=r"'source_ports.damperr' names no source"):
        PlantNode(context=ctx, cli_args=[
            '--ros-args', '-p', f'model_file:={model_file}', '-p', 'sources:=[damper]',
            '-p', 'source_ports.damperr:=[tcp_force_x]'])
