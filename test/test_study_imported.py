"""
The study on an imported FE model: the own machine exported and read back gives the same study.

The own FE model at P1 is written as Matrix Market files with its description
(:func:`pentapod_sim.fe.imported.export.export_fe_model`) and the study runs on it through
the command line (``--fe-model``), then on the own machine at P1; every table of the two runs
must agree. The reference is the own machine's study, computed by the same code from the
machine file: what the comparison checks is the import and that every stage (plant, check
model, loops, bending dampers, PMA, damping per mode) runs on an imported model.
"""
import csv
import math
import os
from pathlib import Path

import pytest
import yaml

from pentapod_damper.study.__main__ import main
from pentapod_damper.study.config import default_path
from pentapod_sim.fe.assembly import build_model
from pentapod_sim.fe.imported.export import export_fe_model
from pentapod_sim.fe.machine_data import load_machine

#: Scenarios of the short study: the struts-1+2 share needs the first three, a PMA the table
#: of PMA requirements.
SCENARIOS = ['baseline', 'strut_damping_all', 'strut_damping_12', 'tcp_damping', 'pma_1kg']
#: Tables compared, and the columns that name a row rather than hold a result.
TABLES = ('summary', 'stability', 'peaks', 'struts12_share', 'bending_models', 'pma',
          'pma_highpass', 'damping')
LABELS = ('position', 'label')
#: Wall-clock columns (how fast a run went, not what it gave).
WALL = ('steps_per_s',)


def _short_study(tmp_path: Path) -> Path:
    doc = yaml.safe_load(default_path().read_text())
    doc.update(positions=['P1'], scenarios=SCENARIOS)
    doc['step_response']['position'] = 'P1'
    doc['damping']['scenarios'] = ['baseline']     # `scenario ... tcp_damping`: no damping run
    doc['excitation']['period'] = 0.5          # s: the testbed run of `scenario` below
    path = tmp_path / 'study.yaml'
    path.write_text(yaml.safe_dump(doc))
    return path


def _rows(folder: Path, name: str) -> list[dict[str, str]]:
    with open(folder / f'{name}.csv', newline='') as stream:
        return list(csv.DictReader(stream))


def _same(a: str, b: str, rtol: float) -> bool:
    try:
        x, y = float(a), float(b)
    except ValueError:
        return a == b
    return (math.isnan(x) and math.isnan(y)) or abs(x - y) <= rtol * max(abs(x), abs(y))


def _compare(own: Path, imported: Path, rtol: float) -> None:
    for name in TABLES:
        mine, theirs = _rows(own, name), _rows(imported, name)
        assert len(mine) == len(theirs) > 0, name
        for a, b in zip(mine, theirs):
            assert list(a) == list(b), name
            for column in a:
                if column in LABELS or column in WALL or column == 'model_hash':
                    continue
                assert _same(a[column], b[column], rtol), (name, column, a[column], b[column])


@pytest.fixture(scope='module')
def exported(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp('imported')
    return export_fe_model(build_model(load_machine(), 'P1'), folder, 'matrix-market',
                           stem='own_p1')


@pytest.mark.slow
def test_short_study_on_the_exported_own_model_gives_the_same_tables(tmp_path, exported):
    config = _short_study(tmp_path)
    own, imported = tmp_path / 'own', tmp_path / 'imported'
    assert main(['--config', str(config), '--positions', 'P1', '--analytic-only',
                 '--out', str(own)]) == 0
    assert main(['--config', str(config), '--fe-model', str(exported), '--analytic-only',
                 '--out', str(imported)]) == 0
    _compare(own, imported, rtol=1e-6)
    # the report is made from the tables alone: made again, it is the same
    first = (imported / 'report.md').read_text().splitlines()
    assert main(['report', '--out', str(imported)]) == 0
    again = (imported / 'report.md').read_text().splitlines()
    assert [line for line in again if not line.startswith('Generated')] == [
        line for line in first if not line.startswith('Generated')]
    assert '## Damping per mode' in again and '![' in ''.join(again)
    positions = {r['position'] for r in _rows(imported, 'summary')}
    assert positions == {'own_p1'}            # the model is named after its file
    assert (imported / 'models' / 'plant_own_p1.npz').is_file()
    assert len(_rows(imported, 'summary')) == len(SCENARIOS)


@pytest.mark.ros
@pytest.mark.slow
def test_a_testbed_run_on_the_imported_model_measures_what_the_own_model_does(
        tmp_path, exported, capsys, monkeypatch):
    """``scenario`` with ``--fe-model``: the plant node runs the imported plant; same FRF."""
    # the session's reserved domain and LOCALHOST discovery (conftest.py); this checkout
    assert os.environ.get('ROS_DOMAIN_ID') and os.environ.get('ROS_AUTOMATIC_DISCOVERY_RANGE')
    monkeypatch.setenv('PYTHONPATH', str(Path(__file__).resolve().parents[1]))
    config = _short_study(tmp_path)
    lines = {}
    for label, where in (('own', ['P1']), ('imported', ['P1', '--fe-model', str(exported)])):
        assert main(['scenario', *where, 'tcp_damping', '--config', str(config),
                     '--out', str(tmp_path / label)]) == 0
        out = capsys.readouterr().out
        lines[label] = next(line for line in out.splitlines()
                            if line.split()[1:2] == ['tcp_damping'])
    own, imported = (lines[k].split() for k in ('own', 'imported'))
    assert imported[0] == 'own_p1' and own[0] == 'P1'
    # peak, peak and RMS reduction, deviation of the run from the sampled loop [dB]
    for a, b in zip(own[2:6], imported[2:6]):
        assert _same(a, b, 1e-3), (lines['own'], lines['imported'])
    assert math.isfinite(float(imported[5]))          # the run was compared with the loop
