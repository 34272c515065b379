"""
A real-time plant that stalls catches up without its sources missing a deadline.

The machine may take the plant's CPU for a few milliseconds (docs/nodes.md, "Real time");
the plant then starts its next steps late and catches up. Each of those steps must still give
its sources time to answer (:data:`pentapod_sim.sim.realtime.ANSWER_WINDOW`): the run
then equals the lockstep run bit for bit, and no miss is blamed on a source that answered as
fast as it could.
"""
import os
import signal
import time

import numpy as np
import pytest

from fixtures.demo_model import demo_model
from fixtures.processes import NodeProcesses
from pentapod_sim.sim.closed_loop import excitation_matrix, simulate
from pentapod_sim.sim.excitation import Excitation, ExcitationSpec
from pentapod_sim.sim.stepping import DiscretePlant

pytestmark = [pytest.mark.ros]

RATE = 50.0
STEPS = 300
STALL = 0.3          # [s]: 15 periods
TCP = ['tcp_force_x', 'tcp_force_y', 'tcp_force_z']


def test_a_stalled_realtime_plant_catches_up_with_every_answer(tmp_path):
    model = demo_model(8, seed=5)
    model_file = model.save(tmp_path / 'model.npz')
    trace = tmp_path / 'trace.npz'
    procs = NodeProcesses(tmp_path)
    try:
        plant = procs.start('plant', 'pentapod_sim.nodes.plant_node', f'model_file:={model_file}',
                            f'steps:={STEPS}', f'sample_rate:={RATE}', 'timing:=realtime',
                            'sources:=[exciter]', f"output_file:='{trace}'",
                            'startup_timeout:=60.0', 'report_period:=1.0')
        procs.start('exciter', 'pentapod_sim.nodes.exciter_node', 'kind:=random',
                    'amplitude:=50.0', 'direction:=[1.0, 0.5, 0.0]', 'f_start:=1.0',
                    'f_end:=20.0', 'seed:=3', f'duration:={STEPS / RATE}',
                    f'sample_rate:={RATE}')
        end = time.monotonic() + 60
        while 'realtime run of' not in procs.log('plant'):
            assert plant.poll() is None and time.monotonic() < end, procs.log('plant')
            time.sleep(0.05)
        time.sleep(1.5)                        # about step 75 of 300
        os.kill(plant.pid, signal.SIGSTOP)     # the stall: the plant gets no CPU
        time.sleep(STALL)
        os.kill(plant.pid, signal.SIGCONT)
        assert procs.wait('plant') == 0, procs.log('plant')
    finally:
        procs.close()
    run = np.load(trace)
    late = run['lateness_per_step']
    assert late.max() > 0.8 * STALL, late.max()              # the stall happened mid-run
    behind = np.flatnonzero(late > 1 / RATE)
    assert behind.size >= 5 and 10 < behind[0] < STEPS - 50, behind
    assert int(run['missed_steps']) == 0, (np.flatnonzero(run['missed_per_step']),
                                           procs.log('plant'))
    plant_core = DiscretePlant(model.discretize(1 / RATE))
    exc = Excitation(ExcitationSpec('random', 50.0, [1.0, 0.5, 0.0], f_start=1.0, f_end=20.0,
                                    duration=STEPS / RATE, seed=3), 1 / RATE)
    ref = simulate(plant_core, [], excitation_matrix(plant_core, TCP, exc.series(STEPS), STEPS))
    assert np.any(ref.u)
    assert np.array_equal(run['u'], ref.u)
    assert np.array_equal(run['y'], ref.y)
