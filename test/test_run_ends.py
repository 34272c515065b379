"""
How a run ends when a recorder or the plant fails: the runner's exit code names it (issue 25).

Real processes through the scenario runner (test/test_stopping.py's helpers) on the session's
domain: a recorder killed or stopped (SIGSTOP, never continued), a plant stopped or killed.
"""
import os
from pathlib import Path
import signal
import time

import numpy as np
import pytest
import test_stopping
from test_stopping import scenario
import yaml

from pentapod_sim import exits
from pentapod_sim.scenario.files import dump_params

pytestmark = [pytest.mark.ros, pytest.mark.slow]

#: the runner fixture of test_stopping (a run per call, every process killed after the test)
runner_of = test_stopping.runner_of

STALL = 2.0            # plant_stall_timeout of the sources [s]


def child(run, needle: str) -> int:
    return next(p for p, cmd in run.children().items() if needle in cmd)


def with_stall_timeout(path: Path) -> Path:
    doc = yaml.safe_load(path.read_text())
    doc['/**']['ros__parameters']['plant_stall_timeout'] = STALL
    path.write_text(dump_params(doc))
    return path


@pytest.mark.parametrize('sig', [signal.SIGKILL, signal.SIGSTOP], ids=['SIGKILL', 'SIGSTOP'])
def test_a_failed_recorder_fails_the_run_naming_it(tmp_path, runner_of, sig):
    """The runner stops the run at once and exits 3 naming the recorder (it exited 0)."""
    run = runner_of(scenario(tmp_path))
    run.wait_for('lockstep run of')
    time.sleep(0.5)
    recorder = child(run, 'recorder_node')
    os.kill(recorder, sig)
    try:
        code = run.proc.wait(timeout=120)
    finally:
        if sig == signal.SIGSTOP:
            try:
                os.kill(recorder, signal.SIGKILL)
            except ProcessLookupError:
                pass
    out = run.text()
    assert code == exits.RECORDING_FAILED, out
    assert 'recording failed: recorder recorder killed by SIGKILL' in out, out
    if sig == signal.SIGSTOP:
        assert 'recorder recorder is stopped' in out, out
    assert 'stopping the plant: a recorder failed' in out, out
    trace = np.load(tmp_path / 'trace.npz')      # the plant stopped cleanly, trace written
    assert int(trace['steps_run']) > 0 and str(trace['end']).startswith('stopped'), out


@pytest.mark.parametrize('timing', ['lockstep', 'realtime'])
def test_a_stopped_plant_is_named_within_the_stall_timeout(tmp_path, runner_of, timing):
    """SIGSTOP of the plant: a source stops the run with exit code 4; the runner names it."""
    run = runner_of(with_stall_timeout(scenario(tmp_path, record=False, timing=timing)))
    run.wait_for(f'{timing} run of')
    time.sleep(0.5)
    plant = child(run, 'plant_node')
    t0 = time.monotonic()
    os.kill(plant, signal.SIGSTOP)
    try:
        code = run.proc.wait(timeout=60)
    finally:
        try:
            os.kill(plant, signal.SIGCONT)
        except ProcessLookupError:
            pass
    took = time.monotonic() - t0
    out = run.text()
    assert code == exits.PLANT_STALLED, out
    assert 'the plant stalled: no message from it for 2 s' in out, out
    assert 'the plant plant stalled (seen by' in out, out
    # noticed after STALL s (checked every 0.25 s), the plant then stopped (SIGINT, SIGCONT)
    assert STALL < took < STALL + 30.0, (took, out)
    assert 'Traceback' not in out, out
    assert 'did not stop within' not in out, out     # continued, it stopped and wrote its trace
    trace = np.load(tmp_path / 'trace.npz')
    assert str(trace['end']) == 'stopped by SIGINT', out


def test_a_killed_plant_gives_128_plus_the_signal(tmp_path, runner_of):
    run = runner_of(scenario(tmp_path, record=False))
    run.wait_for('lockstep run of')
    os.kill(child(run, 'plant_node'), signal.SIGKILL)
    code = run.proc.wait(timeout=60)
    out = run.text()
    assert code == 128 + signal.SIGKILL == 137, out
    assert 'node plant killed by SIGKILL' in out, out
