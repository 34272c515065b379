"""Calibration target of the default machine: strut 1/2 bending dominates the low-frequency TCP.

Paper target (docs/model.md, "Strut bending and the TCP response"): damping the bending of
struts 1 and 2 alone gives most (>= 70 %) of the improvement of damping all five struts. Checked
at P1 for TCP x and y on the RMS of |H| over 0.5-200 Hz; each run is an independent closed-loop
FRF, the threshold comes from the paper, not from a run of this code.
"""
import numpy as np
import pytest

from pentapod_sim.plant.build import build_plant
from pentapod_sim.plant.frf import damper_feedback, statespace_frf

GAIN = 2.0e4            # N m s/rad, the paper's b
BEND_IN = [f'strut{i}_bending_moment_{k}' for i in range(1, 6) for k in (2, 3)]
BEND_OUT = [f'strut{i}_bending_rate_{k}' for i in range(1, 6) for k in (2, 3)]
TCP = 'xy'


@pytest.fixture(scope='module')
def rms_by_dampers():
    plant = build_plant('P1', progress=lambda msg: None)
    sub = plant.select([f'tcp_force_{a}' for a in TCP] + BEND_IN,
                       [f'tcp_displacement_{a}' for a in TCP] + BEND_OUT)
    freq = np.arange(0.5, 200.0, 0.01)          # Hz; half-power width at 27 Hz is 0.054 Hz
    out = {}
    for name, struts in (('none', ()), ('all', (1, 2, 3, 4, 5)), ('12', (1, 2))):
        dampers = {n: GAIN for n in BEND_IN if int(n[5]) in struts}
        h = statespace_frf(damper_feedback(sub, dampers), freq)
        out[name] = np.array([np.sqrt(np.mean(np.abs(h[j, j]) ** 2)) for j in range(len(TCP))])
    return out


def test_bending_damping_lowers_the_tcp_response(rms_by_dampers):
    assert np.all(rms_by_dampers['all'] < 0.7 * rms_by_dampers['none'])


def test_struts_1_and_2_give_most_of_the_bending_damping_effect(rms_by_dampers):
    r = rms_by_dampers
    share = (r['none'] - r['12']) / (r['none'] - r['all'])
    assert np.all(share >= 0.7), f'struts 1/2 share of the all-struts improvement x/y: {share}'
