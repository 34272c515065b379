"""The study's damping-per-mode rows (study/damping.py) and the damping_groups option."""
from pathlib import Path

import control
import numpy as np
import pytest

from fixtures.demo_model import demo_model
from pentapod_damper.laws import Dynamics, lag_displacement_feedback, tcp_damper
from pentapod_damper.scenario_laws import viscous_equivalent
from pentapod_damper.study.__main__ import main
from pentapod_damper.study.damping import continuous_loop_frf, damping_rows, settling_time
from pentapod_sim.errors import ConfigError
from pentapod_sim.plant.build import modal_damping
from pentapod_sim.plant.config import default_path, load_reduction_config
from pentapod_sim.plant.model import PlantModel

AXES = 'xyz'
#: Modes: frequency [Hz] and TCP motion (x, y, z) per unit modal coordinate [m / (sqrt(kg) m)].
FREQ = np.array([20.0, 35.0, 50.0, 80.0, 300.0, 120.0])
SHAPE = np.array([[0.8, 0, 0], [0, 0.6, 0], [0, 0, 0.5], [0.3, 0, 0], [2.0, 0, 0],
                  [0, 0, 0.4]])


def tcp_plant(zeta) -> PlantModel:
    """Modes with TCP motion only: force inputs, displacement and velocity outputs."""
    m = FREQ.size
    outs = [f'tcp_displacement_{a}' for a in AXES] + [f'tcp_velocity_{a}' for a in AXES]
    c_disp = np.vstack([SHAPE.T, np.zeros((3, m))])
    c_vel = np.vstack([np.zeros((3, m)), SHAPE.T])
    return PlantModel(2 * np.pi * FREQ, zeta, SHAPE, c_disp, c_vel, np.zeros((6, 3)),
                      [f'tcp_force_{a}' for a in AXES], outs, ['N'] * 3, ['m'] * 3 + ['m/s'] * 3,
                      [''] * 3, [''] * 6)


def test_open_loop_rows_rank_modes_by_their_peak_compliance_in_the_band():
    zeta = np.array([0.001, 0.002, 0.001, 0.0005, 0.001, 0.003])
    rows = damping_rows(tcp_plant(zeta), [], 1 / 3000, band=(2.0, 200.0), count=3)
    w = 2 * np.pi * FREQ
    peak = SHAPE ** 2 / (2 * zeta * w ** 2 * np.sqrt(1 - zeta ** 2))[:, None]   # m/N
    for k, a in enumerate(AXES):
        mine = [r for r in rows if r.direction == a + a]
        inside = [i for i in np.argsort(-peak[:, k]) if peak[i, k] > 0 and FREQ[i] <= 200]
        assert [r.mode - 1 for r in mine] == inside[:3]      # the 300 Hz mode is left out
        for r in mine:
            i = r.mode - 1
            assert r.open_freq_hz == pytest.approx(FREQ[i], rel=1e-12)
            assert r.open_zeta == zeta[i]
            assert r.continuous_zeta == pytest.approx(zeta[i], rel=1e-9)
            assert r.sampled_zeta == pytest.approx(zeta[i], rel=1e-6)   # ZOH: exp(s dt)
            # the zero-order hold changes the peak by O((w dt)^2) (0.26 % at 120 Hz, 3 kHz)
            assert r.peak_um_per_N == pytest.approx(peak[i, k] * 1e6,
                                                       rel=(w[i] / 3000) ** 2 / 12)
            assert r.decay_time_s == pytest.approx(1 / (zeta[i] * w[i]), rel=1e-6)
    slowest = max(1 / (zeta[i] * w[i]) for i in {r.mode - 1 for r in rows})
    assert settling_time(rows) == pytest.approx(5 * slowest, rel=1e-6)


def test_tcp_damper_rows_against_closed_forms():
    """TCP yy: the one y mode makes a single-mode loop (closed forms hold exactly)."""
    dt, g, z0 = 1 / 3000, 30.0, 0.001
    plant = tcp_plant(z0)
    rows = damping_rows(plant, [tcp_damper('xyz', g)], dt, count=1)
    w, phi = 2 * np.pi * 35.0, 0.6
    yy = next(r for r in rows if r.direction == 'yy')
    assert yy.mode == 2 and yy.continuous_mac == pytest.approx(1.0)
    assert yy.continuous_zeta == pytest.approx(z0 + g * phi ** 2 / (2 * w), rel=1e-9)
    sys = control.ss([[0, 1], [-w ** 2, -2 * z0 * w]], [[0], [phi]], [[0, phi]], [[0]])
    zd = control.poles(control.feedback(control.sample_system(sys, dt, 'zoh'), g))
    s = np.log(zd[zd.imag > 0][0]) / dt
    assert yy.sampled_zeta == pytest.approx(-s.real / abs(s), rel=1e-8)
    assert yy.sampled_freq_hz == pytest.approx(abs(s) / (2 * np.pi), rel=1e-10)


def test_low_pass_law_uses_its_continuous_filter():
    dt, g, z0, bw = 1 / 3000, 30.0, 0.001, 150.0
    law = tcp_damper('z', g, Dynamics(1, bw), dt)
    rows = damping_rows(tcp_plant(z0), [law], dt, directions='z', count=3)
    zz = next(r for r in rows if r.mode == 3)         # 50 Hz; z also moves at 120 Hz
    wf = 2 * np.pi * bw
    w = 2 * np.pi * FREQ[[2, 5]]
    phi = SHAPE[[2, 5], 2]
    # two z modes + first-order filter: det of the coupled loop, from python-control
    plant = control.ss(np.block([[np.zeros((2, 2)), np.eye(2)],
                                 [-np.diag(w ** 2), -np.diag(2 * z0 * w)]]),
                       np.r_[0, 0, phi][:, None], np.r_[0, 0, phi][None, :], [[0]])
    loop = control.feedback(plant, control.tf([g * wf], [1, wf]))
    ref = [p for p in control.poles(loop) if p.imag > 0]
    mine = 2 * np.pi * zz.continuous_freq_hz
    near = min(ref, key=lambda p: abs(abs(p) - mine))
    assert zz.continuous_zeta == pytest.approx(-near.real / abs(near), rel=1e-8)
    # the filter costs damping against the same law without it
    plain = damping_rows(tcp_plant(z0), [tcp_damper('z', g)], dt, directions='z', count=3)
    assert zz.continuous_zeta < next(r for r in plain if r.mode == 3).continuous_zeta


def test_cli_refuses_a_bad_band(capsys):
    assert main(['damping', '--band', '2']) == 1
    assert capsys.readouterr().err.startswith('study damping: ')


def _reduction_file(tmp_path: Path, groups: str) -> Path:
    path = tmp_path / 'reduction.yaml'
    path.write_text(default_path().read_text().replace('damping_groups: []', groups))
    return path


def test_damping_groups_from_the_file_set_the_modal_damping(tmp_path):
    cfg = load_reduction_config(_reduction_file(
        tmp_path, 'damping_groups:\n  - {f_min: 20.0, f_max: 45.0, ratio: 0.005}\n'
                  '  - {f_min: 45.0, f_max: 60.0, ratio: 0.003}'))
    zeta = modal_damping(FREQ, cfg.damping_ratio, cfg.damping_groups)
    np.testing.assert_array_equal(zeta, [0.005, 0.005, 0.003, 0.001, 0.001, 0.001])
    rows = damping_rows(tcp_plant(zeta), [], 1 / 3000, directions='y', count=1)
    assert rows[0].sampled_zeta == pytest.approx(0.005, rel=1e-6)


@pytest.mark.parametrize('group,message', [
    ('{f_min: 20.0, f_max: 45.0, ratio: -0.005}', 'ratio = -0.005'),
    ('{f_min: 50.0, f_max: 45.0, ratio: 0.005}', 'f_min = 50.0'),
    ('{f_min: 20.0, f_max: 45.0, ratoi: 0.005}', "did you mean 'ratio'"),
    ('{f_min: 20.0, f_max: 45.0, ratio: 0.005}\n  - {f_min: 40.0, f_max: 50.0, ratio: 0.002}',
     'overlap'),
])
def test_bad_damping_groups_are_refused_naming_the_value(tmp_path, group, message):
    with pytest.raises(ConfigError, match=message):
        load_reduction_config(_reduction_file(tmp_path, f'damping_groups:\n  - {group}'))


def test_table_in_statespace_md_is_what_the_code_computes():
    from pentapod_damper.study.damping import markdown_table, rows
    from pentapod_damper.study.pipeline import CHECK_CACHE
    text = (Path(__file__).parents[1] / 'docs' / 'statespace.md').read_text()
    begin, end = '<!-- loop-poles:begin -->\n', '\n<!-- loop-poles:end -->'
    stated = text[text.index(begin) + len(begin):text.index(end)]
    assert stated == markdown_table(rows(['P1', 'P2'], ['strut_damping_12', 'tcp_damping'],
                                         CHECK_CACHE, directions='x'))


def test_rows_name_each_mode_by_its_fe_number_and_cause():
    """At P1 the reduction leaves a low FE mode out, so the plant's numbers are not the FE's."""
    from pentapod_sim.fe.machine_data import load_machine, load_positions
    from pentapod_sim.modes.causes import analyse_causes
    from pentapod_sim.modes.frame_reduction import build_model
    from pentapod_sim.modes.solver import solve_modes
    from pentapod_sim.plant.build import plant_from_fe, reduce_plant
    cfg = load_reduction_config()
    fe = build_model(load_machine(), load_positions()['P1'])
    modes = solve_modes(fe.K, fe.M, f_max=cfg.modes_f_max)
    plant_all, keep = plant_from_fe(fe, cfg, modes=modes, progress=lambda msg: None)
    plant = reduce_plant(plant_all, keep)
    causes = analyse_causes(fe, modes, neuber=False).cause
    named = [plant.fe_mode(i) for i in range(1, plant.n_modes + 1)]
    numbers = [n for n, _ in named]
    assert numbers != list(range(1, plant.n_modes + 1))
    for i, (n, cause) in enumerate(named):
        # the same mode: the FE model's frequency and the cause analysis' verdict
        assert plant.frequencies_hz[i] == pytest.approx(modes.frequencies[n - 1], rel=1e-12)
        assert cause == causes[n - 1]
    rows = damping_rows(plant, [], 1 / 3000, directions='x')
    assert rows and all((r.fe_mode, r.cause) == named[r.mode - 1] for r in rows)
    # a plant made from modal data has no FE model behind it: its own numbers, no cause
    assert tcp_plant(0.001).fe_mode(3) == (3, '')


def test_continuous_reference_of_a_law_with_its_own_dynamics():
    """
    Lag displacement feedback (no viscous equivalent): its continuous loop FRF as python-control's.

    The study's continuous reference of such a law is the loop of its own continuous model;
    with a feed-through in the plant (the static correction) the direct term counts too.
    """
    plant = demo_model(n_modes=5, f_min=25.0, f_max=180.0, zeta=0.002, input_scale=0.01,
                       seed=3, feedthrough=2e-9)
    law = lag_displacement_feedback('bending', [1, 2], 2e7, 60.0, 1 / 2000)
    assert viscous_equivalent([law]) is None
    frf = continuous_loop_frf(plant, [law], 'tcp_displacement_x', 'tcp_force_x')
    sys_p = plant.to_statespace()
    k = law.continuous_model()
    outs, ins = list(plant.output_names), list(plant.input_names)
    pick = np.zeros((len(k.sensor_ports), len(outs)))
    pick[np.arange(len(k.sensor_ports)), [outs.index(p) for p in k.sensor_ports]] = 1
    put = np.zeros((len(ins), len(k.actuator_ports)))
    put[[ins.index(p) for p in k.actuator_ports], np.arange(len(k.actuator_ports))] = 1
    loop = control.feedback(sys_p, control.ss(k.a, k.b @ pick, put @ k.c, put @ k.d @ pick),
                            sign=1)
    o, j = outs.index('tcp_displacement_x'), ins.index('tcp_force_x')
    freq = np.array([5.0, 22.0, 40.0, 66.0, 150.0, 400.0])
    expected = np.array([loop(2j * np.pi * f)[o, j] for f in freq])
    np.testing.assert_allclose(frf(freq), expected, rtol=1e-8)
    open_loop = np.array([sys_p(2j * np.pi * f)[o, j] for f in freq])
    assert np.max(np.abs(frf(freq) / open_loop - 1)) > 0.05        # the law acts
