"""
A recorder does not wait for steps that no publisher is left to send.

After a stop signal a source may end without answering the plant's last step; the recorder
then waited ``drain_timeout`` s (30 by default) for that answer, longer than a runner or a
launch gives it, and was killed with its bag unfinished. It must close its bag as soon as every
topic still short of the last step has lost its publishers, after taking what they sent.
"""
import os
import signal
import threading
import time
import warnings

import pytest
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rosgraph_msgs.msg import Clock
import yaml

from fixtures.demo_model import demo_model
from fixtures.processes import NodeProcesses
from pentapod_sim.analysis.bag.file_content import BagDamageWarning
from pentapod_sim.analysis.bag.reader import open_bag

pytestmark = [pytest.mark.ros]

DRAIN_TIMEOUT = 60.0
#: Plant steps the test lets pass while the recorder is stopped. Each step sends the recorder
#: at least six datagrams (/clock, three state topics, the exciter's force and excitation);
#: a datagram takes at least 256 B of a socket's receive buffer, so 3000 steps are 4.6 MB,
#: more than any buffer the kernel grants (net.core.rmem_max, 4 MB here). The recorder's socket
#: overflows and the exciter's last messages can only come by repair, which a writer that has
#: left cannot send. A stall of fixed wall time (0.5 s) did not always overflow it: on a loaded
#: machine the plant made too few steps, the recorder got every message and closed complete.
STALL_STEPS = 3000


class StepCounter:
    """Counts the plant's /clock messages in this process (its own context and thread)."""

    def __init__(self):
        self.ctx = rclpy.Context()
        rclpy.init(context=self.ctx, domain_id=int(os.environ['ROS_DOMAIN_ID']))
        self.node = rclpy.create_node('step_counter', context=self.ctx)
        self.count = 0
        self.running = True
        self.node.create_subscription(Clock, '/clock', self._on_clock, 1000)
        self.executor = SingleThreadedExecutor(context=self.ctx)
        self.executor.add_node(self.node)
        self.thread = threading.Thread(target=self._spin, daemon=True)
        self.thread.start()

    def _on_clock(self, msg):
        self.count += 1

    def _spin(self):
        while self.running:
            self.executor.spin_once(timeout_sec=0.05)

    def wait_for(self, count, timeout):
        end = time.monotonic() + timeout
        while self.count < count and time.monotonic() < end:
            time.sleep(0.01)
        return self.count

    def close(self):
        self.running = False
        self.thread.join(5.0)
        self.node.destroy_node()
        rclpy.shutdown(context=self.ctx)


def test_a_recorder_closes_once_the_missing_steps_have_no_publisher(tmp_path):
    model_file = demo_model(6, seed=4).save(tmp_path / 'model.npz')
    procs = NodeProcesses(tmp_path)
    counter = StepCounter()
    try:
        recorder = procs.start('recorder', 'pentapod_sim.nodes.recorder_node',
                               f"output_dir:='{tmp_path}'", 'bag_name:=run',
                               f'drain_timeout:={DRAIN_TIMEOUT}')
        exciter = procs.start('exciter', 'pentapod_sim.nodes.exciter_node', 'kind:=sine',
                              'amplitude:=20.0', 'frequency:=7.0', 'duration:=1000.0',
                              'sample_rate:=2000.0')
        procs.start('plant', 'pentapod_sim.nodes.plant_node', f'model_file:={model_file}',
                    'steps:=2000000', 'sample_rate:=2000.0', 'sources:=[exciter]',
                    'wait_for_subscribers:=[recorder]', 'startup_timeout:=60.0')
        procs.wait_for('plant', 'lockstep run of')
        time.sleep(1.0)
        recorder.send_signal(signal.SIGSTOP)   # the recorder lags: messages wait for it
        stalled = counter.count
        assert counter.wait_for(stalled + STALL_STEPS, 120.0) >= stalled + STALL_STEPS, \
            (counter.count, procs.log('plant'))
        exciter.send_signal(signal.SIGINT)     # leaves with its last messages undelivered
        assert procs.wait('exciter', 30) == 130, procs.log('exciter')
        recorder.send_signal(signal.SIGCONT)
        assert procs.wait('plant', 30) == 1, procs.log('plant')
        assert 'exciter' in procs.log('plant')
        stopped = time.monotonic()
        code = procs.wait('recorder', DRAIN_TIMEOUT + 30)
        waited = time.monotonic() - stopped
    finally:
        procs.close()
        counter.close()
    log = procs.log('recorder')
    # closed at once, and failed: steps are missing (issue 25: a failed recording fails)
    assert code == 3 and waited < 10.0, (waited, log)
    assert 'drain_timeout' not in log, log
    meta = yaml.safe_load((tmp_path / 'run' / 'metadata.yaml').read_text())
    counts = {e['topic_metadata']['name']: int(e['message_count'])
              for e in meta['rosbag2_bagfile_information']['topics_with_message_count']}
    # the plant's steps are all there (it waited for the recorder's acknowledgements); the
    # exciter's last ones went with it, and the report says how many
    steps = counts['/pentapod/tcp_state'] - 1      # y of the step it waited on went out too
    assert steps > 1000, counts
    failed = log.split('FAILED: ')[1].splitlines()[0]
    for topic in ('/pentapod/excitation', '/pentapod/forces/exciter'):
        assert steps - counts[topic] > 0, counts
        assert f'{topic} misses {steps - counts[topic]} of' in failed, log
    with warnings.catch_warnings():
        warnings.simplefilter('error', BagDamageWarning)     # closed: summary and footer
        bag = open_bag(tmp_path / 'run')
    assert bag.topic('/pentapod/tcp_state').count == steps + 1
