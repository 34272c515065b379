"""
`tune` against closed forms: IFF on one mode (Preumont's optimum), the constraints' effect.

One mode of a mass held by a structure spring k_s and an active strut (spring k_a, force u,
load cell F): pure IFF ``u = -g/s F`` has the closed-loop poles of
``s^3 + g s^2 + w_p^2 s + g w_z^2`` whose best damping is ``(w_p - w_z) / (2 w_z)`` at
``g = w_p sqrt(w_p / w_z)``; with ``omega_i`` the link keeps ``k_a / (1 + g / omega_i)``
statically, so the static compliance ratio is closed-form too.
"""
import numpy as np
import pytest
from test_law_models import K_A, K_S, M, one_mode

from pentapod_sim.plant.drives import DriveParams
from pentapod_sim.sim.design_models import DesignModel
from pentapod_sim.sim.law_families import Family, Parameter, StrutStiffness
from pentapod_sim.sim.law_models import Dynamics, iff
from pentapod_sim.sim.tuning import Judge, trade_off, tune, TuneSettings

W_P, W_Z = np.sqrt((K_S + K_A) / M), np.sqrt(K_S / M)
DRIVES = DriveParams(300.0, 80.0, 0.01, 50.0, 1000.0, 1)


def _model() -> DesignModel:
    return DesignModel('one mode', one_mode(0.0005), None, {}, DRIVES,
                       StrutStiffness(np.ones((5, 2)), np.ones((5, 2)), {}))


def _family(with_omega: bool) -> Family:
    def build(values, struts, context):
        omega = values.get('omega_ratio', 0.0) * values['gain']
        return [iff(['strut1_force'], ['strut1_drive_force'], values['gain'], omega,
                    context['dynamics'])]
    params = (Parameter('gain', '1/s', 50.0, 5000.0),)
    if with_omega:
        params += (Parameter('omega_ratio', '-', 0.05, 5.0),)
    return Family('pure iff', 'locked', 'load cell', 'force actuator', params, build)


def test_tuned_iff_reaches_the_closed_form_optimum():
    settings = TuneSettings(sample_rate=2.0e5, objective='damping', static_ratio_limit=100.0,
                            effort_limit=1e9, struts=(1,), dynamics=Dynamics(),
                            extra_delay=0, gain_points=12, refine_iterations=60,
                            band=(1.0, 400.0))
    result = tune(Judge(_model(), _family(False), settings))
    assert result.best is not None and result.best.feasible
    assert result.best.values['gain'] == pytest.approx(W_P * np.sqrt(W_P / W_Z), rel=0.03)
    # the optimum's damping: Preumont's, plus a little of the open loop's 0.05 %
    assert result.best.min_zeta == pytest.approx((W_P - W_Z) / (2 * W_Z), rel=0.01)


def test_static_limit_binds_as_the_closed_form_says():
    limit = 1.5
    settings = TuneSettings(sample_rate=2.0e5, objective='peak', static_ratio_limit=limit,
                            effort_limit=1e9, struts=(1,), dynamics=Dynamics(),
                            extra_delay=1, gain_points=8, grid_points=6,
                            refine_iterations=0, band=(1.0, 400.0))
    judge = Judge(_model(), _family(True), settings)
    ev = judge.evaluate({'gain': 400.0, 'omega_ratio': 0.5})
    k_link = K_A / (1 + 1 / 0.5)
    assert ev.static_ratio == pytest.approx((K_S + K_A) / (K_S + k_link), rel=1e-6)
    result = tune(judge)
    for e in result.evaluations:
        ratio = (K_S + K_A) / (K_S + K_A / (1 + 1 / e.values['omega_ratio']))
        assert (e.static_ratio <= limit) == (ratio <= limit) or not np.isfinite(e.static_ratio)
        if e.feasible:
            assert ratio <= limit
    assert result.best is not None and result.best.static_ratio <= limit
    curve = trade_off(result)
    ratios, reductions = zip(*[(s, r) for s, r, _ in curve])
    assert list(ratios) == sorted(ratios) and list(reductions) == sorted(reductions)
    # more static compliance allowed buys more peak reduction than the constrained optimum
    assert reductions[-1] > result.peak_reduction
