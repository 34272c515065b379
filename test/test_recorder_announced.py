"""
A recorder subscribes to the force topics the plant announces, before discovery finds them.

The forces of a source are not known by name (any source may publish on
``/pentapod/forces/<source>``), so a recorder used to subscribe to them only when its own
discovery found their writer; a recorder whose participant had not yet found a source's writer
when a short run ended kept none of its forces (a two-worker test session, 2026-12-03). The
plant names the force topics of its lockstep sources (plant parameter ``sources``) in its run
status, and the recorder subscribes to them when that comes. Here the recorder looks for
topics only at its start, before the exciter exists, and at the end of the run
(``discovery_period`` of an hour): it must have subscribed to the exciter's forces before the
end, and the bag must hold every step of them.
"""
import pytest

from fixtures.demo_model import demo_model
from fixtures.processes import NodeProcesses
from pentapod_sim import interface
from pentapod_sim.analysis.bag.reader import open_bag

pytestmark = [pytest.mark.ros]

RATE = 2000.0
STEPS = 1000
EXCITER = ('kind:=random', 'amplitude:=50.0', 'direction:=[1.0, 0.5, 0.0]', 'duration:=1.0',
           'f_start:=5.0', 'f_end:=400.0', 'seed:=3', f'sample_rate:={RATE}')


def test_the_announced_forces_are_subscribed_before_discovery_finds_them(tmp_path):
    model_file = demo_model(4).save(tmp_path / 'model.npz')
    forces = interface.FORCE_PREFIX + 'exciter'
    procs = NodeProcesses(tmp_path)
    try:
        procs.start('recorder', 'pentapod_sim.nodes.recorder_node',
                    f"output_dir:='{tmp_path}'", 'bag_name:=run', 'discovery_period:=3600.0',
                    'drain_timeout:=60.0')
        procs.wait_for('recorder', 'recording to')      # its first look is over
        procs.start('plant', 'pentapod_sim.nodes.plant_node', f'model_file:={model_file}',
                    f'steps:={STEPS}', f'sample_rate:={RATE}', "loop_check:='off'",
                    'sources:=[exciter]', 'wait_for_subscribers:=[recorder]',
                    'startup_timeout:=60.0')
        procs.start('exciter', 'pentapod_sim.nodes.exciter_node', *EXCITER)
        assert procs.wait('plant', 60) == 0, procs.log('plant')
        code = procs.wait('recorder', 30)
    finally:
        procs.close()
    log = procs.log('recorder')
    assert code == 0, log
    assert log.index(f'subscribed {forces}') < log.index(f'run finished after {STEPS} steps'), log
    assert 'none missing' in log, log
    bag = open_bag(tmp_path / 'run')
    assert bag.topic(forces).count == STEPS, bag.topics
