"""
A gain set while the run goes on (issue 25, item 5): logged, stamped, re-checked, recorded.

Real processes through the scenario runner (test/test_loop_check_node.py's scenario) on the
session's domain; the gain is set from this process as a user's ``ros2 param set`` does
(the damper's set_parameters service). The spectral radius the plant reports for the new loop
is checked against a loop closed with python-control, not the testbed's own construction.
"""
import re
import time

import pytest
from rcl_interfaces.srv import SetParameters
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from test_loop_check_node import finish, python_control_radius, RATE, scenario, TCP
from test_stopping import Runner

from fixtures.demo_model import demo_model
from pentapod_sim.analysis.bag.reader import open_bag
from pentapod_sim.nodes.common import spin_until

pytestmark = [pytest.mark.ros, pytest.mark.slow]

NEW_GAIN = 1.0e6
LONG = 2_000_000


def set_gain(name: str, value: float) -> bool:
    """Set ``tcp_gain`` of node ``name`` through its parameter service; True if accepted."""
    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    try:
        node = rclpy.create_node('gain_setter', context=ctx)
        client = node.create_client(SetParameters, f'/{name}/set_parameters')
        assert client.wait_for_service(timeout_sec=30.0)
        future = client.call_async(SetParameters.Request(
            parameters=[Parameter('tcp_gain', value=value).to_parameter_msg()]))
        executor = SingleThreadedExecutor(context=ctx)
        executor.add_node(node)
        assert spin_until(executor, future.done, 30.0)
        return bool(future.result().results[0].successful)
    finally:
        rclpy.shutdown(context=ctx)


@pytest.mark.parametrize('policy', ['refuse', 'warn'])
def test_a_gain_set_mid_run_is_logged_recorded_and_checked_again(tmp_path, policy):
    run = Runner(scenario(tmp_path, 2000.0, LONG if policy == 'refuse' else 12000, policy),
                 tmp_path)
    try:
        run.wait_for('lockstep run of')
        time.sleep(1.0)
        assert set_gain('damper', NEW_GAIN)
        code, out = finish(run, 180.0)
    finally:
        run.kill_all()
    changed = re.search(r'parameter tcp_gain changed during the run: 2000.0 -> 1000000.0, '
                        r'acting from step (\d+) \(t = ([0-9.e+-]+) s\)', out)
    assert changed, out
    step = int(changed.group(1))
    assert float(changed.group(2)) == pytest.approx(step / RATE)
    arrived = re.search(r'truncation check again: new model of damper \(arrived at step '
                        r'(\d+)\)', out)
    assert arrived and int(arrived.group(1)) >= step - 1, out
    expected = python_control_radius(demo_model(6, seed=4), *TCP, [NEW_GAIN] * 2, 1 / RATE)
    radius = float(re.search(r'of the new model of damper from step \d+: .*?spectral radius '
                             r'([0-9.eE+-]+)', out).group(1))
    assert radius == pytest.approx(expected, rel=1e-6) and expected > 1.5
    if policy == 'refuse':
        assert code == 1, out
        assert 'error: truncation check (loop_check = refuse) of the new model of damper' in out
    else:
        assert '!!! truncation check (loop_check = warn) of the new model of damper' in out
    bag = open_bag(tmp_path / 'bags' / 'run')
    change = bag.topic('/pentapod/parameter_changes/damper')
    assert change.count == 1
    # logged at the simulated time of the step it acts from
    assert int(change.log_time_ns[0]) == round(step * 1e9 / RATE)
