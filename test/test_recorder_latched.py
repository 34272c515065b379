"""
A recorder keeps the latched messages of a run, even of a topic it found only at the end.

An exciter's signal parameters and a controller's model are published once and kept by their
writers for late readers (transient local). A recorder looks for new topics every
``discovery_period``; a short run can end before it looked again, and a topic subscribed just
then gets its kept message a moment later. A recorder that closed its bag as soon as the steps
were in lost such messages (CI, 2026-11-28: a 600-step run's bag without the excitation).
Here the recorder looks only at its start and at the end of the run (``discovery_period`` of
an hour) and the latched topic appears in between, so the race happens every time.
"""
import os
import time

import pytest
import rclpy
from rclpy.node import Node
from std_msgs.msg import String

from fixtures.demo_model import demo_model
from fixtures.processes import NodeProcesses
from pentapod_sim.analysis.bag.excitation_record import excitation_of
from pentapod_sim.analysis.bag.reader import open_bag
from pentapod_sim.interface import excitation_spec_topic
from pentapod_sim.nodes.common import qos
from pentapod_sim.sim.excitation import ExcitationSpec
from pentapod_sim.sim.excitation_spec import spec_message

pytestmark = [pytest.mark.ros]

RATE = 2000.0
STEPS = 600
SPEC = ExcitationSpec('multisine', amplitude=3.0, period=0.1, f_start=10.0, f_end=400.0)


@pytest.mark.parametrize('selection', [(), ('/clock', excitation_spec_topic('probe'))],
                         ids=['every-topic', 'chosen-topics'])
def test_a_latched_topic_found_only_at_the_end_of_a_run_is_recorded(tmp_path, selection):
    """Also with chosen topics: the run status (latched, always subscribed) is not awaited."""
    model_file = demo_model(4).save(tmp_path / 'model.npz')
    topic = excitation_spec_topic('probe')
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=int(os.environ['ROS_DOMAIN_ID']))
    node = Node('probe', context=ctx)
    procs = NodeProcesses(tmp_path)
    try:
        procs.start('recorder', 'pentapod_sim.nodes.recorder_node',
                    f"output_dir:='{tmp_path}'", 'bag_name:=run', 'discovery_period:=3600.0',
                    'drain_timeout:=60.0', *([f'topics:=[{",".join(selection)}]'] if selection
                                             else []))
        procs.wait_for('recorder', 'recording to')      # its first look is over
        pub = node.create_publisher(String, topic, qos('spec'))
        procs.start('plant', 'pentapod_sim.nodes.plant_node', f'model_file:={model_file}',
                    f'steps:={STEPS}', f'sample_rate:={RATE}', "loop_check:='off'",
                    'wait_for_subscribers:=[recorder]', 'startup_timeout:=60.0')
        procs.wait_for('recorder', f'subscribed {topic}')
        # the kept message comes a moment after the subscription (a slow match, made slower:
        # the recorder had its steps in 0.4 s after the end; LATCHED_WAIT is 2 s)
        time.sleep(0.8)
        pub.publish(String(data=spec_message(SPEC, RATE, 'probe')))
        assert procs.wait('plant', 60) == 0, procs.log('plant')
        code = procs.wait('recorder', 30)        # drain_timeout would be 60 s
    finally:
        procs.close()
        node.destroy_node()
        rclpy.shutdown(context=ctx)
    log = procs.log('recorder')
    assert code == 0, log
    # found at the end of the run, not before (else the race did not happen)
    assert log.index(f'subscribed {topic}') > log.index(f'run finished after {STEPS} steps'), log
    assert 'none missing' in log and 'no message on' not in log, log
    assert excitation_of(tmp_path / 'run', 'probe') == (SPEC, 1 / RATE)
    bag = open_bag(tmp_path / 'run')
    assert bag.topic('/clock').count == STEPS
    assert not selection or set(bag.topics) == set(selection), bag.topics
