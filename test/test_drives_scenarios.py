"""
Every offline path that closes a scenario's laws models its feed drives (plant ``drives``).

The sweep, the design table's fixed scenario rows, the study's dynamics table and the damping
table (``python -m pentapod_damper.study damping``) each read the scenario's drives
(:func:`pentapod_sim.scenario.laws.scenario_drives`): a drives scenario's loop through each path
is the loop built here directly on :class:`~pentapod_sim.plant.drives.DrivenPlant` (radius by
python-control's feedback, FRF of python-control's continuous closed loop), and not the
locked machine's. Small model: the 186-mode chain of ``fixtures.drives_plant``.
"""
import dataclasses
from pathlib import Path
import re

import control
import numpy as np
import pytest

from fixtures.drives_plant import drives_plant, OUTPUTS
from pentapod_damper.design import rows as design_rows
from pentapod_damper.scenario_laws import scenario_laws
from pentapod_damper.study import damping, dynamics
from pentapod_damper.study.analytic import SampledPairFrf
from pentapod_damper.study.config import load_study_config
from pentapod_damper.sweep import compute
from pentapod_damper.sweep.loops import loop_columns
from pentapod_damper.sweep.settings import make_settings
from pentapod_sim.errors import ConfigError
from pentapod_sim.plant.drives import DrivenPlant, DriveSet, load_drives, with_drives
from pentapod_sim.plant.frf_peaks import maximise_near_poles
from pentapod_sim.scenario.files import read_scenario
from pentapod_sim.sim.controllers import controller_of
from pentapod_sim.sim.design_models import collocated_statics, DesignModel
from pentapod_sim.sim.drives import FeedDrives
from pentapod_sim.sim.law_families import StrutStiffness
from pentapod_sim.sim.loop_frf import SampledLoop
from pentapod_sim.sim.tuning import Judge, TuneSettings

ALL = (1, 2, 3, 4, 5)


def _scenario(tmp_path: Path, damper: str = '') -> Path:
    """A drives scenario at 5 kHz: the drives' cascade, and ``damper`` lines besides."""
    text = f"""/**:
  ros__parameters:
    sample_rate: 5000.0
plant:
  ros__parameters:
    drives: drives.yaml
    sources: [damper_struts]
damper_struts:
  ros__parameters:
    drive_struts: [1, 2, 3, 4, 5]
{damper}"""
    path = tmp_path / 'drives_test.yaml'
    path.write_text(text)
    return path


def _control_radius(driven, ctrls, dt: float) -> float:
    """Largest |pole| of the sampled loop built by python-control (positive feedback)."""
    sys_p = driven.discretize(dt)
    outs, ins = list(driven.output_names), list(driven.input_names)
    blocks = []
    for ctrl in ctrls:
        pick = np.zeros((len(ctrl.sensor_ports), len(outs)))
        pick[np.arange(len(ctrl.sensor_ports)), [outs.index(p) for p in ctrl.sensor_ports]] = 1
        put = np.zeros((len(ins), len(ctrl.actuator_ports)))
        put[[ins.index(p) for p in ctrl.actuator_ports], np.arange(len(ctrl.actuator_ports))] = 1
        if ctrl.n_states:
            blocks.append(control.ss(ctrl.a, ctrl.b @ pick, put @ ctrl.c, put @ ctrl.d @ pick,
                                     dt))
        else:
            blocks.append(control.ss([], [], [], put @ ctrl.d @ pick, dt))
    k = blocks[0]
    for more in blocks[1:]:
        k = control.parallel(k, more)
    return float(np.abs(np.linalg.eigvals(control.feedback(sys_p, k, sign=1).A)).max())


def _written_out_frf(driven, cascade, freq: np.ndarray) -> np.ndarray:
    """
    TCP xx of the continuous loop of ``driven`` and ``cascade``, written out and solved.

    Sensors ``y_s = C_s x + D_s e`` (e the TCP force x; the motors do not feed through),
    ``u = C_k x_k + D_k y_s`` into the motors, ``x_k' = A_k x_k + B_k y_s``.
    """
    a, b, c, d = driven.state_matrices()
    outs, ins = list(driven.output_names), list(driven.input_names)
    s_idx = [outs.index(p) for p in cascade.sensor_ports]
    put = np.zeros((len(ins), len(cascade.actuator_ports)))
    put[[ins.index(p) for p in cascade.actuator_ports], np.arange(put.shape[1])] = 1
    assert not np.any(d[s_idx] @ put)
    i, o = ins.index('tcp_force_x'), outs.index('tcp_displacement_x')
    c_s, d_s = c[s_idx], d[s_idx, i]
    kd, kc = put @ cascade.d, put @ cascade.c
    a_cl = np.block([[a + b @ kd @ c_s, b @ kc], [cascade.b @ c_s, cascade.a]])
    b_cl = np.concatenate([b[:, i] + b @ kd @ d_s, cascade.b @ d_s])
    c_cl = np.concatenate([c[o] + d[o] @ kd @ c_s, d[o] @ kc])
    d_cl = d[o, i] + d[o] @ kd @ d_s
    eye = np.eye(a_cl.shape[0])
    return np.array([c_cl @ np.linalg.solve(2j * np.pi * f * eye - a_cl, b_cl) + d_cl
                     for f in freq])


def test_with_drives_is_the_one_choice():
    _, plant = drives_plant(n_modes=10)
    assert with_drives(plant, None) is plant
    driven = with_drives(plant, DriveSet(load_drives(), (2, 4)))
    assert isinstance(driven, DrivenPlant) and driven.struts == (2, 4)
    root = Path(__file__).parents[1]
    for pkg in ('pentapod_sim', 'pentapod_damper'):     # nobody spells it out again
        for path in (root / pkg).rglob('*.py'):
            if path.name == 'drives.py' and path.parent.name == 'plant':
                continue                                # with_drives itself
            assert not re.search(r'drives is None else [\w.]*\.on\(', path.read_text()), path


def test_damping_table_of_a_drives_scenario_has_the_rotors(monkeypatch, tmp_path):
    """``damping.rows`` (the command's path) = the loop poles on DrivenPlant, not locked."""
    _, plant = drives_plant(n_modes=60)
    monkeypatch.setattr(damping, 'load_or_build_model',
                        lambda position, cache_dir: (plant, 'fixture'))
    dt = load_study_config().dt
    table = damping.rows(['P1'], ['drives_struts'], tmp_path, directions='x', count=3)
    laws = scenario_laws(read_scenario('drives_struts').sections, dt)
    direct = damping.damping_rows(DrivenPlant(plant, load_drives()), laws, dt,
                                  directions='x', count=3, position='P1',
                                  scenario='drives_struts')
    assert table == direct and len(table) == 3
    # the servo-held rotors damp the modes (the locked machine keeps its 0.1 %)
    locked = {r.mode: r.sampled_zeta for r in damping.damping_rows(plant, [], dt,
                                                                   directions='x', count=3)}
    assert set(locked) == {r.mode for r in table}
    ratios = [r.sampled_zeta / locked[r.mode] for r in table]
    assert min(ratios) > 1.1 and max(ratios) > 2.0, ratios


def test_dynamics_table_of_a_drives_scenario_has_the_rotors(monkeypatch, tmp_path):
    """Radii on plant and check model and the peak reduction with the rotors and cascade."""
    _, full = drives_plant()
    _, plant = drives_plant(n_modes=60)
    monkeypatch.setattr(dynamics, 'load_or_build_model',
                        lambda position, cache_dir: (plant, 'fixture'))
    monkeypatch.setattr(dynamics, 'load_or_build_check_model',
                        lambda position, f_max, cache_dir: (full, 'fixture'))
    scn = _scenario(tmp_path, '    tcp_directions: [x]\n    tcp_gain: 2000.0\n'
                              '    filter_order: 1\n    bandwidth_hz: 300.0\n')
    table = dynamics.rows(['P1'], [str(scn)], tmp_path)
    cfg = load_study_config()
    dt, band = cfg.dt, (float(cfg.band[0]), float(cfg.f_max))
    laws = scenario_laws(read_scenario(scn).sections, dt)
    assert any(isinstance(getattr(law, 'law', None), FeedDrives) for law in laws)
    params = load_drives()
    shipped = next(r for r in table if r.variant == 'buildable')
    ctrls = [controller_of(law) for law in laws]
    assert shipped.plant_radius == pytest.approx(
        _control_radius(DrivenPlant(plant, params), ctrls, dt), abs=1e-9)
    assert shipped.check_radius == pytest.approx(
        _control_radius(DrivenPlant(full, params), ctrls, dt), abs=1e-9)
    frf = SampledPairFrf(DrivenPlant(plant, params), laws, dt, 'tcp_displacement_x',
                         'tcp_force_x')
    base = SampledPairFrf(plant, [], dt, 'tcp_displacement_x', 'tcp_force_x')
    open_peak = maximise_near_poles(lambda f: abs(base(f)), base.poles, *band).value
    peak = maximise_near_poles(lambda f: abs(frf(f)), frf.poles, *band).value
    assert shipped.peak_reduction == pytest.approx(open_peak / peak, rel=1e-3)
    # without the rotors and cascade the TCP damper alone would give another reduction
    alone = [law for law in laws if not isinstance(getattr(law, 'law', None), FeedDrives)]
    frf_locked = SampledPairFrf(plant, alone, dt, 'tcp_displacement_x', 'tcp_force_x')
    locked = maximise_near_poles(lambda f: abs(frf_locked(f)), frf_locked.poles, *band).value
    assert abs(open_peak / locked - shipped.peak_reduction) > 0.05 * shipped.peak_reduction


def test_sweep_closes_a_drives_scenario_on_the_rotors(tmp_path):
    """loop_columns of a drives scenario: python-control's continuous loop and radius."""
    outputs = list(OUTPUTS) + ['tcp_displacement_y', 'tcp_displacement_z']
    _, plant = drives_plant(n_modes=60, outputs=outputs)
    settings = make_settings([str(_scenario(tmp_path))], n_points=400)
    assert settings.drives[str(_scenario(tmp_path))] == DriveSet(load_drives(), ALL)
    loops = compute.loops_of(settings)
    dt = 1 / settings.sample_rate
    freq = np.linspace(settings.freq[0], settings.freq[1], int(settings.freq[2]))
    row = loop_columns(plant, loops, freq, settings.band, dt, 10.0, [])
    label = next(iter(loops))
    driven = DrivenPlant(plant, load_drives())
    cascade = FeedDrives(load_drives()).continuous()
    h = _written_out_frf(driven, cascade, freq)
    lo, hi = settings.band
    band = (freq >= lo) & (freq <= hi)
    assert row[f'peak_xx_{label}'] == pytest.approx(np.abs(h[band]).max(), rel=1e-6)
    assert row[f'rho_{label}'] == pytest.approx(
        _control_radius(driven, [FeedDrives(load_drives()).discrete(dt)], dt), abs=1e-9)
    assert abs(row[f'peak_xx_{label}'] / row['peak_xx_open'] - 1) > 0.05     # not locked


def test_design_fixed_row_of_a_drives_scenario_runs_on_the_drives():
    """A fixed scenario row of drives_struts: the judge's loop is the DrivenPlant's."""
    _, full = drives_plant()
    _, plant = drives_plant(n_modes=60)
    params = load_drives()
    stiffness = StrutStiffness(np.full((5, 2), 2e4), np.full((5, 2), 3e6),
                               collocated_statics(plant))
    model = DesignModel('small', plant, full, {}, params, stiffness)
    family = design_rows.scenario_family('drives', 'drives_struts', 'encoders', 'motors')
    assert family.machine == 'drives'
    judge = Judge(model, family, TuneSettings(sample_rate=5000.0, band=(2.0, 400.0)))
    dt = judge.settings.dt
    ctrls = judge.controllers({})
    loop = SampledLoop(judge.machine(), ctrls, dt)
    direct = SampledLoop(DrivenPlant(plant, params), [FeedDrives(params).discrete(dt)], dt)
    freq = np.linspace(20.0, 400.0, 50)
    mine = loop.output('tcp_displacement_x', 'tcp_force_x')(freq)
    want = direct.output('tcp_displacement_x', 'tcp_force_x')(freq)
    assert np.allclose(mine, want, rtol=1e-9, atol=0)
    locked = SampledLoop(plant, [], dt).output('tcp_displacement_x', 'tcp_force_x')(freq)
    assert np.abs(mine / locked - 1).max() > 0.05
    # the struts 1+2 share: the drives stay on every strut
    two = judge.controllers({}, struts=(1, 2))
    assert sorted(p for c in two for p in c.actuator_ports) == sorted(
        f'strut{i}_motor_force' for i in ALL)


def test_design_fixed_row_extra_delay_delays_the_iff_not_the_drives(tmp_path):
    """One more sample on a fixed HAC-LAC row: the drives keep their delay, the IFF gets it."""
    from pentapod_sim.sim.law_models import Dynamics
    scn = _scenario(tmp_path, '    drive_iff_gain: 150.0\n    drive_iff_omega: 2.3\n'
                              '    filter_order: 2\n    bandwidth_hz: 500.0\n')
    family = design_rows.scenario_family('hac', str(scn), 'cells', 'motors')
    params, dt = load_drives(), 1 / 5000.0
    context = {'drives': params, 'extra': 1}
    (fixed,) = family.laws({}, ALL, context)
    (mine,) = fixed.discrete(dt)
    ref = FeedDrives(params, ALL, 150.0, 2.3, Dynamics(2, 500.0, delay_steps=1)).discrete(dt)
    for m in 'abcd':
        assert np.array_equal(getattr(mine, m), getattr(ref, m)), m
    other = dataclasses.replace(params, rotor_mass=2 * params.rotor_mass)
    with pytest.raises(ConfigError, match="not the design model's drives"):
        family.laws({}, ALL, dict(context, drives=other))


def test_dynamics_table_refuses_a_scenario_without_viscous_dampers_before_any_model(
        monkeypatch, tmp_path):
    def no_model(*args, **kwargs):
        raise AssertionError('a model was built')
    monkeypatch.setattr(dynamics, 'load_or_build_model', no_model)
    with pytest.raises(ConfigError, match="'hac_lac_struts' has no viscous dampers"):
        dynamics.rows(['P1'], ['strut_damping_12', 'hac_lac_struts'], tmp_path)


@pytest.mark.parametrize('scenario', ['drives_struts', 'hac_lac_struts'])
def test_sweep_of_p1_with_the_drives_is_the_loop_written_out(scenario):
    """
    The sweep's own P1 pose (3066 DOF, 90 modes) with the drives' scenarios, written out.

    Its xx peak is the FRF of the closed loop solved directly, its dominant-mode ζ a pole of
    python-control's closed loop. Rotor forces [N] and modal coordinates differ by orders of
    magnitude: HAC-LAC's eigen-decomposition FRF needs the balanced loop (unbalanced its
    eigenvectors are too ill-conditioned and the pose failed).
    """
    from pentapod_sim.modes.frame_reduction import build_model
    from pentapod_sim.modes.solver import solve_modes
    from pentapod_sim.plant.build import plant_from_fe, reduce_plant
    settings = make_settings([scenario], n_points=400)
    pose = np.array([0.0, 0.0, 0.85, 0.0, 0.0])             # P1 (config/positions.yaml)
    row = compute.evaluate(pose, settings)
    fe = build_model(settings.machine, pose)
    modes = solve_modes(fe.K, fe.M, f_max=max(settings.mode_f_max,
                                              settings.reduction.modes_f_max))
    plant_all, keep = plant_from_fe(fe, settings.reduction, progress=lambda msg: None,
                                    modes=modes)
    plant = reduce_plant(plant_all, keep, settings.reduction.static_correction)
    driven = DrivenPlant(plant, load_drives())
    (law,) = scenario_laws(read_scenario(scenario).sections, 1 / settings.sample_rate)
    cascade = law.law.continuous()
    a, b, c, d = driven.state_matrices()
    outs, ins = list(driven.output_names), list(driven.input_names)
    s_idx = [outs.index(p) for p in cascade.sensor_ports]
    a_idx = [ins.index(p) for p in cascade.actuator_ports]
    put = np.zeros((len(ins), len(a_idx)))
    put[a_idx, np.arange(len(a_idx))] = 1
    assert not np.any(d[s_idx][:, a_idx])
    sys_p = control.ss(a, b @ put, c[s_idx], np.zeros((len(s_idx), len(a_idx))))
    k = control.ss(cascade.a, cascade.b, cascade.c, cascade.d)
    poles = control.feedback(sys_p, k, sign=1).poles()
    near = poles[np.argmin(np.abs(np.abs(poles) - 2 * np.pi * row['dom_f_xx']))]
    assert row[f'zeta_xx_{scenario}'] == pytest.approx(-near.real / abs(near), rel=1e-6)
    freq = np.linspace(settings.freq[0], settings.freq[1], int(settings.freq[2]))
    lo, hi = settings.band
    h = _written_out_frf(driven, cascade, freq[(freq >= lo) & (freq <= hi)])
    assert row[f'peak_xx_{scenario}'] == pytest.approx(np.abs(h).max(), rel=1e-6)
    assert row[f'zeta_xx_{scenario}'] > 10 * row['zeta_xx_open']      # locked: 0.1 %
