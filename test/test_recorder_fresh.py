"""
A source that outlives runs is matched by the recorder before the plant may start.

The judge's ``--node`` mode records a controller the user started earlier: its force topic is
a *fresh* topic (recorded volatile, so none of its earlier runs' answers come back as history),
so an answer published before the recorder's reader matched its writer is lost for good. In CI
(2026-12-03) a loaded machine matched that writer late and 900 of 6000 answers were missing.
The recorder now subscribes to the fresh topics first and to the plant's topics only once
their writers are matched; the plant, waiting for the recorder on its own topics, cannot start
before. Here the controller appears seconds after the plant and the recorder, and the
recorder looks for new topics only at its start (``discovery_period`` of an hour): without
the hold-back it would never subscribe to the controller's topic, and every answer would be
missing.
"""
import time

import pytest

from fixtures.demo_model import demo_model
from fixtures.processes import NodeProcesses
from pentapod_sim.analysis.bag.reader import open_bag
from pentapod_sim.interface import force_topic, TCP_STATE

pytestmark = [pytest.mark.ros]

RATE = 2000.0
STEPS = 400
TOPIC = force_topic('lab')


def test_the_plant_waits_until_the_recorder_matched_a_fresh_topics_writer(tmp_path):
    model_file = demo_model(4).save(tmp_path / 'model.npz')
    procs = NodeProcesses(tmp_path)
    try:
        procs.start('recorder', 'pentapod_sim.nodes.recorder_node',
                    f"output_dir:='{tmp_path}'", 'bag_name:=run', 'discovery_period:=3600.0',
                    f'topics:=[/clock,{TCP_STATE},{TOPIC}]', f'fresh_topics:=[{TOPIC}]')
        procs.start('plant', 'pentapod_sim.nodes.plant_node', f'model_file:={model_file}',
                    f'steps:={STEPS}', f'sample_rate:={RATE}', "loop_check:='off'",
                    'sources:=[lab]',
                    'wait_for_subscribers:=[recorder]', 'startup_timeout:=60.0')
        procs.wait_for('recorder', 'recording to')
        time.sleep(2.0)       # plant and recorder both up: no controller yet
        assert f'subscribed {TCP_STATE}' not in procs.log('recorder'), procs.log('recorder')
        procs.start('lab', 'pentapod_damper.nodes.damper_node', "tcp_directions:=['x']",
                    'tcp_gain:=400.0', f'sample_rate:={RATE}')
        assert procs.wait('plant', 60) == 0, procs.log('plant')
        code = procs.wait('recorder', 30)
    finally:
        procs.close()
    log = procs.log('recorder')
    assert code == 0, log
    assert (log.index(f'subscribed {TOPIC}') < log.index(f'matched the writer(s) of {TOPIC}')
            < log.index(f'subscribed {TCP_STATE}')), log
    assert 'none missing' in log, log
    bag = open_bag(tmp_path / 'run')
    assert bag.topic(TOPIC).count == bag.topic(TCP_STATE).count == STEPS
