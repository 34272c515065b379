"""
Pole-residue FRFs of sampled loops: against dense solves, also with delay lines' Jordan chains.

A delay of n samples and the input memory give the loop nilpotent (non-diagonalisable) zero
blocks; the Schur split must still give the FRF a dense solve of ``(zI - A) x = b`` gives.
"""
import numpy as np
import pytest

from fixtures.demo_model import demo_model
from pentapod_damper.laws import Dynamics, strut_bending_damper, tcp_damper
from pentapod_damper.study.analytic import discrete_frf
from pentapod_sim.sim.controllers import controller_of
from pentapod_sim.sim.loop_frf import band_grid, PairFrf, SampledLoop

DT = 1 / 2000


@pytest.mark.parametrize('delay', [0, 1, 3])
def test_frf_equals_dense_solve_with_delay_chains(delay):
    plant = demo_model(10, feedthrough=2e-9, seed=2)
    laws = [tcp_damper('xy', 3e3, Dynamics(1, 200.0, delay_steps=delay), DT),
            strut_bending_damper([1, 2], 40.0, Dynamics(delay_steps=delay), DT)]
    loop = SampledLoop(plant, [controller_of(law) for law in laws], DT)
    freq = np.linspace(5.0, 400.0, 60)
    dense = discrete_frf(plant, laws, DT, freq, 'tcp_force_x')
    np.testing.assert_allclose(loop.output('tcp_displacement_x', 'tcp_force_x')(freq),
                               dense.outputs['tcp_displacement_x'], rtol=1e-6)
    np.testing.assert_allclose(loop.effort('tcp_force_y', 'tcp_force_x')(freq),
                               dense.efforts['tcp_force_y'], rtol=1e-8, atol=1e-12)
    assert loop.spectral_radius == pytest.approx(dense.spectral_radius, rel=1e-9)
    # the static gain: the FRF's limit at z = 1
    h0 = loop.output('tcp_displacement_x', 'tcp_force_x')(np.array([1e-7]))[0]
    assert loop.static('tcp_displacement_x', 'tcp_force_x') == pytest.approx(h0.real,
                                                                             rel=1e-6)


def test_rms_and_peak_of_one_mode_against_closed_forms():
    """|H|^2 of r / (z - l) integrated over the whole circle: |r|^2 / (1 - |l|^2)."""
    lam = np.array([0.999 * np.exp(2j * np.pi * 60.0 * DT)])
    frf = PairFrf(DT, np.concatenate([lam, lam.conj()]), np.array([1e-3, 1e-3]),
                  np.zeros(2), 0.0, 0.0)
    nyquist = 0.5 / DT
    # over 0..Nyquist the two conjugate terms give the whole circle's mean
    ms = frf.rms(1e-6, nyquist - 1e-6) ** 2
    z = np.exp(2j * np.pi * np.linspace(0, nyquist, 2_000_001) * DT)
    dense = np.mean(np.abs(frf(np.angle(z) / (2 * np.pi * DT))) ** 2)
    assert ms == pytest.approx(dense, rel=5e-4)
    peak = frf.peak(10.0, 200.0)
    assert peak.freq_hz == pytest.approx(60.0, abs=0.05)
    grid = band_grid(frf.poles, 10.0, 200.0, 1.0)
    assert np.abs(frf(grid)).max() <= peak.value * (1 + 1e-12)
