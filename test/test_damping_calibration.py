"""
Damping calibrated from measured FRFs: a synthetic measurement of the own model is calibrated back.

The "measurement" is made from the model's modes at P1 with known damping (2-12x the nominal
0.1 % on the eight dominant TCP modes, 0.1 % elsewhere), two dominant modes shifted (+1.5 %,
-1 %), 2 % complex noise on every line, written as UFF 58 by the project's writer and read
back through pyuff. Calibration must pair every dominant mode with its model mode, recover
its damping ratio within 5 % and bring the updated FRFs' peaks within 1 dB of the measurement;
the damping file it writes must set those ratios in the plant.
"""
from dataclasses import replace

import numpy as np
from numpy.testing import assert_allclose
import pytest
import yaml

from pentapod_sim.analysis.calibration import report
from pentapod_sim.analysis.calibration.fill import band_values, rayleigh_fit
from pentapod_sim.analysis.calibration.pairing import mac_matrix, pair_modes
from pentapod_sim.analysis.calibration.settings import CalibrationSettings
from pentapod_sim.analysis.calibration.update import calibrate, model_receptance, sub_bands
from pentapod_sim.analysis.measured.frf_files import MeasuredFrfs, read_uff58, write_uff58
from pentapod_sim.analysis.measured.labels import parse_label
from pentapod_sim.analysis.measured.model_dofs import label_rows
from pentapod_sim.errors import ConfigError
from pentapod_sim.fe.assembly import build_model
from pentapod_sim.fe.machine_data import load_machine
from pentapod_sim.modes.solver import solve_modes
from pentapod_sim.plant.build import plant_from_fe
from pentapod_sim.plant.config import default_path, load_reduction_config
from pentapod_sim.plant.damping_file import load_damping_file, write_damping_file

POINTS = ['tcp'] + [f'strut{i}_wp_end' for i in range(1, 6)] + [f'strut{i}_span6'
                                                                for i in range(1, 6)]
DOMINANT_HZ = (26.69, 27.96, 65.51, 72.23, 91.61, 97.26, 103.87, 131.99)
FACTORS = (2, 12, 3, 5, 6, 8, 4, 10)          # x the nominal 0.1 %
SHIFTS = {65.51: 1.015, 97.26: 0.99}
BAND = (20.0, 140.0)


@pytest.fixture(scope='module')
def case(tmp_path_factory):
    fe = build_model(load_machine(), 'P1')
    modes = solve_modes(fe.K, fe.M, f_max=400.0)
    f = modes.frequencies
    dominant = [int(np.argmin(np.abs(f - x))) for x in DOMINANT_HZ]
    assert_allclose(f[dominant], DOMINANT_HZ, atol=0.01)   # the model these numbers are for
    zeta = np.full(f.size, 0.001)
    zeta[dominant] = 0.001 * np.array(FACTORS)
    f_true = f.copy()
    for x, factor in SHIFTS.items():
        f_true[int(np.argmin(np.abs(f - x)))] *= factor
    responses = [parse_label(f'{p}:{c}') for p in POINTS for c in 'xyz']
    references = [parse_label(f'tcp:{c}') for c in 'xyz']
    c = np.asarray(label_rows(fe, responses) @ modes.shapes)
    b = np.asarray(label_rows(fe, references) @ modes.shapes).T
    freq = np.arange(15.0, 145.0, 0.01)
    H = model_receptance(c, b, 2 * np.pi * f_true, zeta, np.zeros((c.shape[0], 3)), freq)
    rng = np.random.default_rng(29)
    H = H * (1 + 0.02 * (rng.standard_normal(H.shape) + 1j * rng.standard_normal(H.shape))
             / np.sqrt(2))
    folder = tmp_path_factory.mktemp('measured')
    numbers = {p: k + 1 for k, p in enumerate(POINTS)}
    path = write_uff58(folder / 'measured.uff',
                       MeasuredFrfs(freq, H, responses, references), numbers)
    measured = read_uff58(path, {n: p for p, n in numbers.items()})
    cal = calibrate(fe, f, modes.shapes, 0.001, measured, CalibrationSettings(band=BAND),
                    progress=lambda msg: None)
    return {'fe': fe, 'f': f, 'zeta': zeta, 'f_true': f_true, 'dominant': dominant,
            'cal': cal, 'measured': measured, 'folder': folder}


def test_uff58_measurement_reads_back_with_its_labels(case):
    m = case['measured']
    assert [str(r) for r in m.responses[:3]] == ['tcp:+x', 'tcp:+y', 'tcp:+z']
    assert m.H.shape == (33, 3, m.freq.size) and m.quantity == 'displacement'


def test_dominant_modes_are_paired_with_their_model_modes(case):
    cal = case['cal']
    for j in case['dominant']:
        hit = np.flatnonzero(cal.pairing.model == j)
        assert hit.size == 1, f'model mode at {case["f"][j]:.2f} Hz is not paired'
        i = cal.pairing.measured[hit[0]]
        assert_allclose(cal.identified_hz[i], case['f_true'][j], rtol=2e-3)
        assert cal.pairing.mac[hit[0]] > 0.95


def test_damping_of_the_dominant_modes_within_5_percent(case):
    cal = case['cal']
    for j in case['dominant']:
        i = cal.pairing.measured[np.flatnonzero(cal.pairing.model == j)[0]]
        assert abs(cal.identified_zeta[i] / case['zeta'][j] - 1) < 0.05, case['f'][j]
        assert abs(cal.zeta_after[j] / case['zeta'][j] - 1) < 0.05


def test_updated_peaks_within_1_db_of_the_measurement(case):
    cal, m = case['cal'], case['measured']
    rows = report.error_rows(cal, m.responses, m.references)
    counted = [r for r in rows if r['peaks']]
    assert len(counted) > 60
    assert max(r['peak_db_after'] for r in counted) < 1.0
    assert max(r['peak_db_before'] for r in counted) > 10.0      # the nominal 0.1 % is not
    driving = [r for r in rows if r['response'] == r['reference']]
    assert all(r['rms_db_after'] < r['rms_db_before'] for r in driving)


def test_report_files(case):
    cal, m, folder = case['cal'], case['measured'], case['folder']
    rows = report.pairing_rows(cal)
    assert {r['model_mode'] for r in rows} >= {j + 1 for j in case['dominant']}
    text = report.format_pairing(rows)
    assert len(text.splitlines()) == len(rows) + 1
    png = report.overlay_plot(cal, m.responses, m.references, folder / 'overlay.png')
    assert png.read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'


def test_damping_file_sets_the_plant_damping(case, tmp_path):
    cal = case['cal']
    path = write_damping_file(tmp_path / 'damping.yaml', cal.damping, 'test')
    back = load_damping_file(path)
    assert_allclose(back.ratios(case['f']), cal.zeta_after, rtol=1e-12)
    cfg_file = tmp_path / 'reduction.yaml'
    text = yaml.safe_load(default_path().read_text())
    text.update(damping_file='damping.yaml', modes_f_max=200.0)
    cfg_file.write_text(yaml.safe_dump(text))
    plant, _ = plant_from_fe(case['fe'], load_reduction_config(cfg_file),
                             progress=lambda msg: None)
    for j in case['dominant']:
        k = int(np.argmin(np.abs(plant.frequencies_hz - case['f'][j])))
        assert abs(plant.zeta[k] / case['zeta'][j] - 1) < 0.05


def test_damping_file_and_groups_together_are_refused(tmp_path):
    text = yaml.safe_load(default_path().read_text())
    text.update(damping_file='d.yaml', damping_groups=[{'f_min': 1.0, 'f_max': 2.0,
                                                        'ratio': 0.01}])
    path = tmp_path / 'r.yaml'
    path.write_text(yaml.safe_dump(text))
    with pytest.raises(ConfigError, match='damping_file replaces damping_groups'):
        load_reduction_config(path)


def test_rayleigh_fit_recovers_its_coefficients():
    omega = 2 * np.pi * np.array([20.0, 50.0, 90.0, 140.0])
    alpha, beta = 0.8, 1.5e-5
    assert_allclose(rayleigh_fit(omega, alpha / (2 * omega) + beta * omega / 2),
                    (alpha, beta), rtol=1e-9)
    # a decreasing trend cannot need a negative beta: NNLS keeps both >= 0
    a, b = rayleigh_fit(omega, [0.01, 0.004, 0.002, 0.001])
    assert a >= 0 and b >= 0


def test_band_values_are_medians_and_empty_bands_take_the_overall_median():
    rows = band_values([10, 12, 30, 31, 33], [0.01, 0.03, 0.002, 0.004, 0.003], [0, 20, 40, 60])
    assert rows == [(0.0, 20.0, 0.02), (20.0, 40.0, 0.003), (40.0, 60.0, 0.004)]


def test_pairing_is_a_global_assignment_gated_by_mac_and_frequency():
    model = np.eye(4)[:, :3]
    model[:, 1] += 0.3 * model[:, 0]
    measured = model[:, [1, 0]]                  # two measured modes, swapped order
    pairs = pair_modes([50.0, 20.0], measured, [20.0, 50.0, 80.0], model, mac_min=0.8)
    assert pairs.model.tolist() == [0, 1] and pairs.measured.tolist() == [1, 0]
    assert_allclose(pairs.mac, 1.0)
    far = pair_modes([30.0, 20.0], measured, [20.0, 50.0, 80.0], model,
                     frequency_tolerance=0.1)   # 30 Hz is 40 % from the 50 Hz mode
    assert far.model.tolist() == [0]
    assert_allclose(np.diag(mac_matrix(model, model)), 1.0)


def test_sub_bands_split_between_model_modes_and_overlap():
    bands = sub_bands(np.arange(10.0, 101.0, 10.0), (5.0, 105.0), 4)
    assert len(bands) == 3 and bands[0][0] == 5.0 and bands[-1][1] == 105.0
    assert bands[0][1] > bands[1][0] and 40.0 < bands[1][0] < 50.0


def test_settings_errors_name_the_key():
    from pentapod_sim.schema import build
    with pytest.raises(ConfigError, match='fill_edges'):
        build(CalibrationSettings, {'fill': 'bands'}, 'cal.yaml')
    with pytest.raises(ConfigError, match="mac_mn: unknown key; did you mean 'mac_min'"):
        build(CalibrationSettings, {'mac_mn': 0.9}, 'cal.yaml')
    assert replace(CalibrationSettings(), names={'3': 'tcp'}).node_names == {3: 'tcp'}


def test_a_new_calibration_gives_a_new_plant_cache_key(tmp_path, monkeypatch):
    import shutil

    from pentapod_sim.plant import build, config
    for name in ('machine.yaml', 'positions.yaml'):
        shutil.copy(default_path().parent / name, tmp_path / name)
    text = yaml.safe_load(default_path().read_text())
    text['damping_file'] = 'damping.yaml'
    (tmp_path / 'reduction.yaml').write_text(yaml.safe_dump(text))
    monkeypatch.setattr(build, 'config_dir', lambda: tmp_path)
    monkeypatch.setattr(config, 'config_dir', lambda: tmp_path)
    (tmp_path / 'damping.yaml').write_text('modes: []\ndefault_ratio: 0.002\n')
    first = build.model_cache_key('P1')
    (tmp_path / 'damping.yaml').write_text('modes: []\ndefault_ratio: 0.003\n')
    assert build.model_cache_key('P1') != first
