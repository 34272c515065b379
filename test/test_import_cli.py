"""
The commands on an imported model: `modes --fe-model`, `statespace build --fe-model`, `calibrate`.

The own model exported to Abaqus text and read back must give the same plant file as the own
model; `calibrate` on a synthetic measurement of that model must write a damping file that
recovers the damping given to it; a user's mistake is one error line and exit code 1.
"""
import numpy as np
from numpy.testing import assert_allclose
import pytest
import yaml

from pentapod_sim.analysis.calibration.update import model_receptance
from pentapod_sim.analysis.measured.frf_files import MeasuredFrfs, write_uff58
from pentapod_sim.analysis.measured.labels import parse_label
from pentapod_sim.analysis.measured.model_dofs import label_rows
from pentapod_sim.cli import calibrate, modes, statespace
from pentapod_sim.fe.assembly import build_model
from pentapod_sim.fe.imported.export import export_fe_model
from pentapod_sim.fe.machine_data import load_machine
from pentapod_sim.modes.solver import solve_modes
from pentapod_sim.plant.config import default_path
from pentapod_sim.plant.damping_file import load_damping_file
from pentapod_sim.plant.model import PlantModel
from pentapod_sim.registry import executables


@pytest.fixture(scope='module')
def files(tmp_path_factory):
    folder = tmp_path_factory.mktemp('import_cli')
    fe = build_model(load_machine(), 'P1')
    description = export_fe_model(fe, folder / 'model', 'abaqus', stem='p1')
    cfg = yaml.safe_load(default_path().read_text())
    cfg.update(modes_f_max=200.0)
    reduction = folder / 'reduction.yaml'
    reduction.write_text(yaml.safe_dump(cfg))
    return fe, description, reduction, folder


def test_calibrate_is_an_executable():
    assert executables()['calibrate'] == 'pentapod_sim.cli.calibrate:main'


def test_modes_on_an_imported_model(files, capsys):
    fe, description, _, folder = files
    assert modes.main(['--fe-model', str(description), '--f-max', '60', '--no-neuber',
                       '--out', str(folder / 'modes')]) == 0
    text = capsys.readouterr().out
    assert f'imported {description} (abaqus): {fe.n_dof} DOF (0 dropped)' in text
    assert (folder / 'modes' / 'modes.csv').is_file()
    f = np.genfromtxt(folder / 'modes' / 'modes.csv', delimiter=',', names=True)['frequency_hz']
    assert_allclose(f, solve_modes(fe.K, fe.M, f_max=60.0).frequencies, rtol=1e-9)


def test_statespace_build_on_the_imported_model_equals_the_own_plant(files):
    _, description, reduction, folder = files
    for args in (['--fe-model', str(description)], ['--position', 'P1']):
        assert statespace.main(['build', *args, '--config', str(reduction), '--out',
                                str(folder / 'plants')]) == 0
    back = PlantModel.load(folder / 'plants' / 'plant_p1.npz')
    own = PlantModel.load(folder / 'plants' / 'plant_P1.npz')
    assert_allclose(back.frequencies_hz, own.frequencies_hz, rtol=1e-9)
    freq = np.linspace(5.0, 190.0, 300)
    from pentapod_sim.plant.frf import modal_frf
    h_own, h_back = modal_frf(own, freq).H, modal_frf(back, freq).H
    peak = np.abs(h_own).max(axis=-1)
    scale = np.sqrt(peak.max(axis=1)[:, None] * peak.max(axis=0)[None, :])
    assert np.max(np.abs(h_back - h_own).max(axis=-1) / scale) < 1e-9


@pytest.fixture(scope='module')
def shaker(files):
    """A shaker test of the model: TCP x, y forces, 18 responses, 0.4 % and 0.9 % damping."""
    fe, _, _, folder = files
    m = solve_modes(fe.K, fe.M, f_max=200.0)
    points = ['tcp'] + [f'strut{i}_wp_end' for i in range(1, 6)]
    responses = [parse_label(f'{p}:{c}') for p in points for c in 'xyz']
    references = [parse_label(f'tcp:{c}') for c in 'xy']
    c = np.asarray(label_rows(fe, responses) @ m.shapes)
    b = np.asarray(label_rows(fe, references) @ m.shapes).T
    zeta = np.full(m.n_modes, 0.001)
    zeta[:2] = [0.004, 0.009]                      # 26.7 and 28.0 Hz
    freq = np.arange(20.0, 46.0, 0.005)
    H = model_receptance(c, b, 2 * np.pi * m.frequencies, zeta, np.zeros((18, 2)), freq)
    numbers = {p: k + 1 for k, p in enumerate(points)}
    uff = write_uff58(folder / 'shaker.uff', MeasuredFrfs(freq, H, responses, references),
                      numbers)
    return uff, numbers, m


def test_calibrate_writes_a_damping_file_that_recovers_the_damping(files, shaker, capsys):
    fe, description, reduction, folder = files
    uff, numbers, m = shaker
    settings = folder / 'calibration.yaml'
    settings.write_text(yaml.safe_dump({'band': [22.0, 44.0],
                                        'names': {str(n): p for p, n in numbers.items()}}))
    out = folder / 'cal'
    assert calibrate.main(['--measured', str(uff), '--model', str(description), '--settings',
                           str(settings), '--config', str(reduction), '--out', str(out),
                           '--modes-uff']) == 0
    text = capsys.readouterr().out
    assert 'paired with the' in text and 'written:' in text
    damping = load_damping_file(out / 'damping.yaml')
    assert_allclose(damping.ratios(m.frequencies[:2]), [0.004, 0.009], rtol=0.02)
    for name in ('pairing.csv', 'frf_errors.csv', 'overlay.png', 'modes.uff', 'ports.csv'):
        assert (out / name).is_file(), name


@pytest.mark.parametrize('argv,match', [
    (['--measured', 'missing.uff', '--model', 'P1'], 'missing.uff: not a readable UFF file'),
    (['--measured', '{uff}', '--model', 'P9'], "no position 'P9'"),
    (['--measured', '{uff}', '--model', 'P1', '--fill', 'bands'], 'fill_edges'),
])
def test_user_mistakes_are_one_line(files, shaker, capsys, argv, match):
    argv = [a.replace('{uff}', str(shaker[0])) for a in argv]
    assert calibrate.main(argv + ['--out', str(files[3] / 'bad')]) == 1
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line.startswith('calibrate: error:')]
    assert len(lines) == 1 and match in lines[0] and 'Traceback' not in err, err
