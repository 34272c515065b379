"""Study building blocks against independent computations (no ROS)."""
from pathlib import Path

import numpy as np
import pytest
import yaml

from fixtures.demo_model import demo_model
from pentapod_damper.laws import ProofMassActuator, tcp_damper
from pentapod_damper.scenario_laws import continuous_dampers, scenario_laws
from pentapod_damper.study.analytic import discrete_frf, improvement_share, pma_requirements
from pentapod_damper.study.config import load_study_config
from pentapod_damper.study.pipeline import scenario_analytic
from pentapod_damper.study.records import PositionModel, StudyResults
from pentapod_damper.study.runs import study_scenario
from pentapod_damper.study.tables import peak_rows, struts12_share, summary_rows
from pentapod_sim.errors import ConfigError
from pentapod_sim.plant.frf import closed_loop_frf
from pentapod_sim.plant.ports import collocated_output
from pentapod_sim.scenario.files import read_scenario
from pentapod_sim.sim.closed_loop import simulate
from pentapod_sim.sim.stepping import DiscretePlant

DT = 1.0 / 5000.0


@pytest.fixture(scope='module')
def plant():
    return demo_model(n_modes=6, f_min=20.0, f_max=300.0, zeta=0.02, feedthrough=1e-8)


@pytest.mark.parametrize('laws', [[], [tcp_damper(['x', 'y'], 3000.0)],
                                  [ProofMassActuator(['x'], 5.0, 400.0, DT)]])
def test_sampled_loop_frf_is_the_dtft_of_the_stepped_impulse_response(plant, laws):
    """discrete_frf equals the DTFT of an impulse response stepped by the lockstep core."""
    core = DiscretePlant(plant.discretize(DT))
    n = 60000
    excitation = np.zeros((n, len(core.input_names)))
    excitation[0, core.input_names.index('tcp_force_x')] = 1.0
    for law in laws:
        law.reset()
    response = simulate(core, laws, excitation)
    freq = np.array([7.0, 33.0, 81.5, 140.0, 410.0])
    z = np.exp(2j * np.pi * freq * DT)
    powers = z[None, :] ** -np.arange(n)[:, None]
    ana = discrete_frf(plant, laws, DT, freq, 'tcp_force_x')
    for out in ('tcp_displacement_x', 'tcp_velocity_y', 'pma_mount_velocity_x'):
        dtft = response.output(out) @ powers
        np.testing.assert_allclose(ana.outputs[out], dtft, rtol=2e-3,
                                   atol=2e-3 * np.abs(dtft).max())


def test_sampled_loop_approaches_the_continuous_loop_at_low_frequency(plant):
    """With the sample far above the modes, the one-sample delay hardly matters."""
    dampers = {'tcp_force_x': 2000.0}
    freq = np.array([5.0, 15.0, 25.0])
    cont = closed_loop_frf(plant, dampers, freq).pair('tcp_displacement_x', 'tcp_force_x')
    disc = discrete_frf(plant, [tcp_damper(['x'], 2000.0)], 1e-5, freq, 'tcp_force_x')
    np.testing.assert_allclose(disc.outputs['tcp_displacement_x'], cont, rtol=1e-3)


def test_pma_requirements_match_a_direct_harmonic_balance():
    """Proof mass driven by a_m = g v: stroke = x_m - x, force = m g v (harmonic balance)."""
    freq = np.array([5.0, 40.0, 300.0])
    w = 2 * np.pi * freq
    v = (0.3 + 0.4j) * np.ones(3)           # mount velocity per newton
    mass, gain, amp = 5.0, 4000.0, 10.0
    stroke, force = pma_requirements(v, freq, mass, gain, amp)
    x_mount = amp * v / (1j * w)
    x_mass = amp * gain * v / (1j * w) ** 2
    np.testing.assert_allclose(stroke, np.abs(x_mass - x_mount), rtol=1e-12)
    np.testing.assert_allclose(force, mass * gain * np.abs(amp * v), rtol=1e-12)


def test_improvement_share():
    assert improvement_share(10.0, 4.0, 2.0) == pytest.approx(0.75)
    assert np.isnan(improvement_share(1.0, 1.0, 1.0))


def test_scenario_files_give_the_papers_laws():
    dt = 2e-4
    laws = scenario_laws(read_scenario(_scenario('pma_1kg')).sections, dt)
    assert continuous_dampers(laws) == {'pma_force_x': pytest.approx(20000.0)}
    laws = scenario_laws(read_scenario(_scenario('axial_damping')).sections, dt)
    assert continuous_dampers(laws) == {f'strut{i}_axial_force': pytest.approx(20000.0)
                                        for i in range(1, 6)}     # buildable: 200 Hz low-pass
    assert {law.dynamics.bandwidth_hz for law in laws} == {200.0}
    from pentapod_damper.study.dynamics import ideal_laws
    assert continuous_dampers(ideal_laws('axial_damping', dt)) == {
        f'strut{i}_axial_force': pytest.approx(50000.0) for i in range(1, 6)}   # the paper's
    assert scenario_laws(read_scenario(_scenario('baseline')).sections, dt) == []


def test_filtered_pma_has_no_viscous_equivalent():
    law = ProofMassActuator(['x'], 1.0, 100.0, DT, highpass_hz=5.0)
    with pytest.raises(ConfigError, match='no viscous equivalent'):
        continuous_dampers([law])


def test_a_run_applies_study_settings_and_adds_a_recorder(tmp_path):
    """The study's typed settings reach every node's typed parameters, and its file."""
    cfg = load_study_config(period=1.5, sample_rate=2500.0)
    run = study_scenario('pma_5kg', 'P1', tmp_path / 'm.npz', cfg, tmp_path / 'bag',
                         {'model_hash': 'abc'}, initial_state=tmp_path / 'x0.npz')
    plant = run.plant.params
    assert (plant.position, plant.duration, plant.model_file) == (
        'P1', 1.5 * (cfg.settle_periods + cfg.periods), str(tmp_path / 'm.npz'))
    assert plant.initial_state_file == str(tmp_path / 'x0.npz')
    exciter = run.node('exciter').params
    assert (exciter.kind, exciter.amplitude, exciter.period) == ('multisine', cfg.amplitude, 1.5)
    assert exciter.settle_periods == cfg.settle_periods
    for name in ('plant', 'exciter', 'pma'):
        assert run.node(name).params.dt == cfg.dt == 1 / 2500.0, name
        assert run.node(name).params.wait_for_subscribers == ('recorder',), name
    rec = run.node('recorder').params
    assert rec.bag_name == 'bag' and yaml.safe_load(rec.run_info)['model_hash'] == 'abc'
    assert run.node('pma').params.proof_mass == 5.0
    assert [n.name for n in run.nodes] == ['exciter', 'pma', 'recorder', 'plant']  # file order
    doc = run.write(tmp_path / 'scenario.yaml').read_text()      # the run's one file
    assert '/**' not in doc and doc.count("'sample_rate': 2500.0") == 3


@pytest.mark.parametrize('override, message', [
    ({'direction': 'w'}, "excitation.direction = 'w'"),
    ({'band': (0.0, 5000.0)}, 'excitation.band'),
    ({'period': -1.0}, 'period = -1.0'),
    ({'scenarios': ('tcp_damping',)}, 'must start with baseline'),
])
def test_bad_study_config_names_the_value(override, message):
    with pytest.raises(ConfigError, match=message.replace('(', r'\(').replace(')', r'\)')):
        load_study_config(**override)


def test_missing_key_is_named(tmp_path):
    path = tmp_path / 'study.yaml'
    doc = yaml.safe_load(Path(load_study_config.__globals__['default_path']()).read_text())
    del doc['excitation']['period']
    path.write_text(yaml.safe_dump(doc))
    with pytest.raises(ConfigError, match=r'study\.yaml: excitation\.period: missing key'):
        load_study_config(path)


def _scenario(name: str) -> Path:
    return Path(__file__).resolve().parents[1] / 'config' / 'scenarios' / f'{name}.yaml'


@pytest.mark.parametrize('override, message', [
    ({'check_policy': 'ignore'}, 'truncation_check.policy'),
    ({'pma_band': (400.0, 10.0)}, 'pma_requirements.band'),
    ({'check_f_min': 0.0}, 'truncation_check.f_min'),
    ({'damping_band': (2.0, 1600.0)}, 'damping.band'),
    ({'damping_scenarios': ('tcp_dampnig',)}, r"damping\.scenarios\[0\].*'tcp_damping'"),
    ({'damping_periods': 0}, 'damping.periods'),
])
def test_bad_check_and_pma_settings_name_the_key(override, message):
    with pytest.raises(ConfigError, match=message):
        load_study_config(**override)


def _dense_peak(plant, dampers, freq, cfg) -> float:
    """Largest |H| TCP xx: coarse grid, then 40001 points within 1 Hz of its maximum."""
    inputs = ['tcp_force_x', *dampers]
    outputs = ['tcp_displacement_x', *(collocated_output(i, 'velocity') for i in dampers)]
    small = plant.select(inputs, outputs)

    def mag(f):
        return np.abs(closed_loop_frf(small, dampers, f).pair('tcp_displacement_x',
                                                               'tcp_force_x'))
    coarse = freq[(freq >= cfg.band[0]) & (freq <= cfg.f_max)]
    top = coarse[np.argmax(mag(coarse))]
    return float(mag(np.linspace(top - 1.0, top + 1.0, 40_001)).max())


def test_report_rows_use_exact_peaks_and_the_truncation_check(tmp_path):
    """Peaks, reductions and the struts-1+2 share against a dense grid of the closed loop."""
    scenarios = ('baseline', 'strut_damping_all', 'strut_damping_12', 'tcp_damping')
    cfg = load_study_config(positions=('P1',), scenarios=scenarios)
    model_plant = demo_model(n_modes=6, f_min=20.0, f_max=300.0, zeta=0.01, seed=4)
    model = PositionModel('P1', model_plant, tmp_path / 'm.npz', 'hash')
    res = StudyResults(cfg, np.linspace(*cfg.freq_grid[:2], int(cfg.freq_grid[2])))
    for scn in scenarios:
        res.analytic[('P1', scn)] = scenario_analytic(model, scn, cfg, res.freq)
    peak = {scn: _dense_peak(model_plant, res.analytic[('P1', scn)].dampers, res.freq, cfg)
            for scn in scenarios}
    rows = {r.scenario: r for r in summary_rows(res)}
    for scn in scenarios:
        assert rows[scn].peak_um_per_N == pytest.approx(peak[scn] * 1e6, rel=1e-6)
        assert rows[scn].peak_reduction == pytest.approx(peak['baseline'] / peak[scn],
                                                         rel=1e-6)
        assert rows[scn].sampled_loop == 'stable on the plant (no check model)'
        assert rows[scn].plant_margin > 0
    share = struts12_share(res)[0].peak_share
    base, part, full = (peak[s] for s in ('baseline', 'strut_damping_12', 'strut_damping_all'))
    assert share == pytest.approx((base - part) / (base - full), rel=1e-5)
    grid = {r['scenario']: r['grid_peak_um_per_N'] for r in peak_rows(res)}
    assert all(grid[s] <= rows[s].peak_um_per_N * (1 + 1e-12) for s in scenarios)


def test_positions_without_the_step_position_are_a_named_error(tmp_path, capsys):
    """--positions P1 while the PMA step runs are at P2: one line naming both, exit 1."""
    from pentapod_damper.study.__main__ import main
    assert main(['--analytic-only', '--positions', 'P1', '--out', str(tmp_path)]) == 1
    err = capsys.readouterr().err
    assert 'step_response.position = P2 is not among the positions P1' in err
    assert 'Traceback' not in err


def test_report_of_a_folder_without_a_run_names_what_it_lacks(tmp_path, capsys):
    from pentapod_damper.study.__main__ import main
    (tmp_path / 'summary.csv').write_text('position\n')
    assert main(['report', '--out', str(tmp_path)]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f'study report: {tmp_path} is not the folder')
    assert 'stability.csv' in err[0] and 'summary.csv' not in err[0]
    assert 'study_settings.json' in err[0]


def test_a_table_a_stage_adds_is_written_and_shown_in_the_report(tmp_path):
    """The way in for a new stage's table: CSV file and report section, no report code."""
    import dataclasses

    from pentapod_damper.study.records import Table
    from pentapod_damper.study.report import read_csv, rewrite_report, write_report
    cfg = dataclasses.replace(load_study_config(), positions=(), scenarios=())
    res = StudyResults(cfg, np.linspace(1.0, 10.0, 10), tmp_path)
    res.tables.append(Table('damper_choice', 'Which damper to build', 'Cheapest first.',
                            [{'damper': 'tcp', 'cost': 2.5}, {'damper': 'pma', 'cost': 11}]))
    text = write_report(res, tmp_path).read_text()
    assert read_csv(tmp_path / 'damper_choice.csv') == [{'damper': 'tcp', 'cost': '2.5'},
                                                       {'damper': 'pma', 'cost': '11'}]
    section = text.split('## Which damper to build\n\nCheapest first.\n\n')[1].split('\n\n')[0]
    assert section.splitlines() == ['| damper | cost |', '|---|---|', '| tcp | 2.5 |',
                                    '| pma | 11 |']
    assert rewrite_report(tmp_path, cfg).read_text().split('\n', 3)[3] == text.split('\n', 3)[3]
