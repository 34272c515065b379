"""
A recorded topic forged by a second participant: the recorder's report fails the run (issue 25).

The spoofer (test/fixtures/spoofer.py, ``excitation``) publishes /pentapod/excitation, a
per-step topic that only the recorder reads, so no source or plant stops the run first: the
recorder alone must notice the foreign writer and the conflicting copies of steps (same stamp,
other content), keep them in the bag as evidence, and fail the run naming the topic and the
spoofer's participant. Started before the run (stamps counting from 0 at 200 Hz) and during it
(a copy of every real message with the same stamp).
"""
import time

from mcap.reader import make_reader
import numpy as np
import pytest
from rosbags.highlevel import AnyReader
import test_stopping
from test_stopping import RATE, scenario
from test_writers import FORGED_VELOCITY, spoofer

from pentapod_sim import exits
from pentapod_sim.interface import EXCITATION
from pentapod_sim.nodes.recorder_node import RECORDING_RECORD

pytestmark = [pytest.mark.ros, pytest.mark.slow]

runner_of = test_stopping.runner_of
STEPS = 16000          # long enough for a spoofer started after step 0 to be matched
FORGED = FORGED_VELOCITY   # N: the spoofer's excitation force (the exciter's is 20 N at most)


@pytest.mark.parametrize('when', ['before', 'during'])
def test_a_forged_recorded_topic_fails_the_run_naming_the_writer(tmp_path, runner_of, when):
    run_file = scenario(tmp_path, steps=STEPS)
    fake = spoofer(RATE, 'free', 'excitation') if when == 'before' else None
    try:
        if when == 'before':
            time.sleep(2.0)
        run = runner_of(run_file)
        if when == 'during':
            run.wait_for('lockstep run of')
            fake = spoofer(RATE, 'excitation')
        code = run.proc.wait(timeout=300)
    finally:
        if fake is not None:
            fake.kill()
            forged = fake.communicate()[0]
    out = run.text()
    assert 'forged' in forged, forged                  # the attack happened
    assert code == exits.RECORDING_FAILED, out
    assert ('recording failed: recorder recorder exited with code 3; its bag is closed, its '
            'report (above) says why it cannot be trusted') in out, out
    assert 'Traceback' not in out, out
    # the recorder names the topic and the spoofer's participant (by its process id)
    line = next(x for x in out.splitlines() if 'foreign writer: ' in x)
    assert f'{EXCITATION} has 2 writers' in line, line
    assert f'process id {fake.pid & 0xffff} ' in line, line
    assert line.count('participant 01.0f.') == 2, line
    failed = next(x for x in out.splitlines() if 'is incomplete or not trustworthy' in x)
    assert f'{EXCITATION} holds ' in failed and 'conflicting copies of steps' in failed, failed
    assert f'{EXCITATION}: {EXCITATION} has 2 writers' in failed, failed
    # the physics was not touched: only a recorder reads the excitation
    trace = np.load(tmp_path / 'trace.npz')
    assert int(trace['steps_run']) == STEPS and str(trace['end']) == 'finished', out
    # the bag is complete and holds the evidence: forged messages beside the real ones
    bag = tmp_path / 'bags' / 'run'
    forces, stamps = [], []
    with AnyReader([bag]) as reader:
        conns = [c for c in reader.connections if c.topic == EXCITATION]
        for conn, _, raw in reader.messages(connections=conns):
            msg = reader.deserialize(raw, conn.msgtype)
            forces.append(msg.wrench.force.x)
            stamps.append(msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec)
    forces = np.array(forces)
    assert np.count_nonzero(forces == FORGED) > 0, 'no forged message in the bag'
    real = np.array(stamps)[forces != FORGED]
    assert len(np.unique(real)) == STEPS, len(np.unique(real))
    # the forged copies share stamps with real steps: conflicting copies, counted in the report
    assert np.isin(np.array(stamps)[forces == FORGED], real).any()
    with open(next(bag.glob('*.mcap')), 'rb') as stream:
        records = {m.name: dict(m.metadata) for m in make_reader(stream).iter_metadata()}
    record = records[RECORDING_RECORD]
    assert EXCITATION in record['foreign'], record
    assert EXCITATION in record['conflicting'], record
