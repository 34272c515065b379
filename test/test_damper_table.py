"""
The "which damper to build" table on a small FE model: every row measured like the others.

A row's peak reduction is checked against the study's own sampled-loop FRF code, its check-
model margins against the truncation check of :mod:`pentapod_sim.sim.stability`, and the
table's files (CSV, Markdown, figure) against its rows.
"""
from dataclasses import replace

import numpy as np
import pytest
from statespace_fixtures import all_modes, small_model

from pentapod_damper.design.report import (
    best_strut_law,
    markdown,
    markdown_records,
    plot,
    read_csv,
    records,
    verdict,
    write_csv,
)
from pentapod_damper.design.rows import default_rows
from pentapod_damper.design.table import damper_table
from pentapod_damper.design.verify import verify_best
from pentapod_damper.scenario_laws import scenario_laws
from pentapod_damper.study.analytic import SampledPairFrf
from pentapod_sim.plant import ports
from pentapod_sim.plant.build import from_modal_data
from pentapod_sim.plant.drives import DriveParams, link_stiffness
from pentapod_sim.plant.frf_peaks import maximise_near_poles
from pentapod_sim.plant.ports import INPUT_NAMES, OUTPUT_NAMES
from pentapod_sim.scenario.files import read_scenario
from pentapod_sim.sim.controllers import controller_of
from pentapod_sim.sim.design_models import collocated_statics, DesignModel
from pentapod_sim.sim.law_families import StrutStiffness
from pentapod_sim.sim.law_models import Dynamics
from pentapod_sim.sim.loop_frf import SampledLoop
from pentapod_sim.sim.stability import check_loop
from pentapod_sim.sim.tuning import Judge, TuneSettings

RATE = 5000.0


@pytest.fixture(scope='module')
def table():
    fe = small_model(5)
    omega, phi = all_modes(fe)
    points = {**fe.points, **ports.load_points(fe.points, fe.stiffness_groups)}
    everything = from_modal_data(omega / (2 * np.pi), ports.modal_points(points, phi),
                                 fe.strut_frames, INPUT_NAMES, OUTPUT_NAMES, 0.001)
    plant = from_modal_data(omega[:40] / (2 * np.pi), ports.modal_points(points, phi[:, :40]),
                            fe.strut_frames, INPUT_NAMES, OUTPUT_NAMES, 0.001)
    plant.meta['kept_modes'] = list(range(1, 41))
    everything.meta['check_f_max_hz'] = float(omega.max() / (2 * np.pi))
    stiffness = StrutStiffness(np.full((5, 2), 2e4), np.full((5, 2), 3e6),
                               collocated_statics(plant))
    model = DesignModel('small', plant, everything, {}, DriveParams(
        20.0, 30.0, 0.02, 20.0, 1000.0, 1), stiffness,
        energy={'frame': np.full(omega.size, 0.7), 'struts': np.full(omega.size, 0.3)},
        energy_freq_hz=omega / (2 * np.pi))
    settings = TuneSettings(sample_rate=RATE, grid_points=2, gain_points=3,
                            refine_iterations=0, band=(1.0, 400.0))
    return model, damper_table(model, settings)


def test_every_row_and_what_it_includes(table):
    _, tab = table
    assert [r.law for r in tab.rows] == [s.name for s in default_rows()]
    for row in tab.rows:
        assert row.dynamics_included == (row.law != 'ideal viscous bending (paper)')
        shares = np.array([row.share12_peak, row.share12_rms])
        assert np.all(np.isnan(shares)) != row.strut_law


def test_tcp_damper_row_against_the_studys_sampled_frf(table):
    model, tab = table
    laws = scenario_laws(read_scenario('tcp_damping').sections, 1 / RATE)
    frf = SampledPairFrf(model.plant, laws, 1 / RATE, 'tcp_displacement_x', 'tcp_force_x')
    peak = maximise_near_poles(lambda f: np.abs(frf(f)), frf.poles, 1.0, 400.0)
    row = tab.row('TCP damper')
    assert row.peak_reduction == pytest.approx(tab.baseline_peak / peak.value, rel=1e-6)


def test_check_margins_are_the_truncation_checks(table):
    model, tab = table
    dt = 1 / RATE
    laws = scenario_laws(read_scenario('strut_damping_all').sections, dt)
    for extra, margin in ((0, 'check_margin'), (1, 'check_margin_extra')):
        delayed = [type(law)(law.actuator_ports, law.gains,
                             Dynamics(law.dynamics.order, law.dynamics.bandwidth_hz,
                                      law.dynamics.damping, law.dynamics.delay_steps + extra,
                                      law.dynamics.hold), dt) for law in laws]
        check = check_loop(model.plant, model.check, [controller_of(law) for law in delayed],
                           dt, 'warn')
        row = tab.row('velocity feedback (buildable today)')
        assert getattr(row, margin) == pytest.approx(check.check_margin, abs=1e-9)


def test_files_say_what_the_rows_say(table, tmp_path):
    _, tab = table
    path = write_csv([tab], tmp_path / 'dampers.csv')
    lines = read_csv(path)
    assert [line['law'] for line in lines] == [r.law for r in tab.rows]
    for line, row in zip(lines, tab.rows):
        assert float(line['peak_reduction']) == pytest.approx(row.peak_reduction)
    text = markdown(tab)
    assert markdown_records(lines) == text
    for row in tab.rows:
        assert f'| {row.law} |' in text
    assert 'small' in verdict(lines)
    assert plot(tab, tmp_path / 'dampers.png').stat().st_size > 10_000


def test_stroke_of_the_series_actuator_is_its_extension(table):
    """
    A series actuator's stroke is its extension, a parallel one's its port's motion.

    IFF's actuator sits in series with the nut: its extension is the strut's motion against
    the gimbal plus the link's deformation, ``delta + F / k_a`` (F the load cell force), which
    the row's stroke (force over k_a) must equal; a moment pair strokes by its port's rotation.
    """
    model, tab = table
    spec = next(s for s in default_rows() if s.name == 'IFF')
    judge = Judge(model, spec.family, tab.settings)
    row = tab.row('IFF')
    loop = SampledLoop(judge.machine(), judge.controllers(row.gains), judge.settings.dt)
    out, inp = judge.settings.pair
    freq = np.geomspace(*judge.settings.band, 20000)
    rms = []
    for i in range(1, 6):
        k_a = link_stiffness(model.plant, i)
        extension = (loop.output(f'strut{i}_drive_displacement', inp)(freq)
                     + loop.output(f'strut{i}_force', inp)(freq) / k_a)
        rms.append(np.sqrt(np.trapezoid(np.abs(extension) ** 2, freq) / np.ptp(freq)))
    assert row.stroke_unit == 'm/N'
    assert row.stroke_rms_per_n == pytest.approx(max(rms), rel=2e-2)
    lag = tab.row('lag displacement, bending')
    assert lag.stroke_unit == 'rad/N' and lag.stroke_rms_per_n > 0
    assert np.isnan(tab.row('PMA 5 kg, 5 Hz high-pass').stroke_rms_per_n)


def test_verified_law_margins_are_the_full_truncation_check(table):
    """The verdict's law, checked on the full check model: the truncation check's margins."""
    model, tab = table
    full = replace(model, full_check=model.check, driven={})
    verified = verify_best(tab, full)
    best = best_strut_law(records(verified))
    assert best is not None
    row = verified.row(best['law'])
    spec = next(s for s in default_rows() if s.name == row.law)
    judge = Judge(model, spec.family, tab.settings)
    for extra, margin in ((0, row.full_check_margin), (1, row.full_check_margin_extra)):
        check = check_loop(model.plant, model.check, judge.controllers(row.gains, extra),
                           judge.settings.dt, 'warn')
        assert margin == pytest.approx(check.check_margin, abs=1e-9)
    assert verified.full_check_modes == model.check.n_modes
    assert 'on the full check model' in verdict(records(verified))
    assert np.isnan(verified.row('TCP damper').full_check_margin)     # not a strut law
