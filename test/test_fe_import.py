"""
FE matrices in: the own model through each text format and back, a MAPDL file a library ships.

Also units, triangles, penalties, offsets and the errors a user's file can cause.

Checks are independent of the reader: the round trips against the model that was written
(frequencies, shapes at the ports, FRFs of the plant built from it, to 1e-9), the MAPDL
example against a dense solve of the library's own matrices and Euler-Bernoulli's cantilever.
"""
from dataclasses import replace
from pathlib import Path

import numpy as np
from numpy.testing import assert_allclose
import pytest
import scipy.linalg as sla
import scipy.sparse as sp
import yaml

from pentapod_sim.errors import ConfigError, ModelFileError
from pentapod_sim.fe.assembly import build_model
from pentapod_sim.fe.imported import abaqus
from pentapod_sim.fe.imported.build import load_fe_model
from pentapod_sim.fe.imported.export import export_fe_model
from pentapod_sim.fe.machine_data import load_machine
from pentapod_sim.modes.causes import strain_energy_shares
from pentapod_sim.modes.solver import solve_modes
from pentapod_sim.plant.build import plant_from_fe
from pentapod_sim.plant.config import load_reduction_config
from pentapod_sim.plant.frf import modal_frf

F_MAX = 300.0       # Hz: enough modes to test, a fraction of the solve time of 750 Hz


@pytest.fixture(scope='module')
def own():
    return build_model(load_machine(), 'P1')


@pytest.fixture(scope='module')
def own_modes(own):
    return solve_modes(own.K, own.M, f_max=F_MAX)


def _cfg():
    return replace(load_reduction_config(), modes_f_max=F_MAX)


def _same_modes(a, b, rtol=1e-9):
    assert a.n_modes == b.n_modes
    assert_allclose(b.frequencies, a.frequencies, rtol=rtol)


@pytest.mark.parametrize('fmt', ['matrix-market', 'abaqus'])
def test_own_model_round_trips_to_the_same_modes_and_frfs(own, own_modes, tmp_path, fmt):
    back = load_fe_model(export_fe_model(own, tmp_path, fmt))
    assert back.n_dof == own.n_dof and back.meta['dropped_dofs'] == 0
    assert set(back.stiffness_groups) == set(own.stiffness_groups)
    modes = solve_modes(back.K, back.M, f_max=F_MAX)
    _same_modes(own_modes, modes)
    for name, T in own.points.items():            # the same DOF order: shapes compare directly
        assert_allclose(back.points[name].toarray(), T.toarray(), rtol=0, atol=1e-15)
    assert_allclose(back.strut_frames, own.strut_frames, atol=1e-15)
    shares = strain_energy_shares(back.stiffness_groups, modes)
    order = list(own.stiffness_groups)
    assert_allclose(shares, strain_energy_shares({g: back.stiffness_groups[g] for g in order},
                                                 own_modes), atol=1e-9)
    freq = np.linspace(5.0, 250.0, 400)
    plant_own, _ = plant_from_fe(own, _cfg(), progress=lambda msg: None)
    plant_back, _ = plant_from_fe(back, _cfg(), progress=lambda msg: None)
    h_own, h_back = modal_frf(plant_own, freq).H, modal_frf(plant_back, freq).H
    peak = np.abs(h_own).max(axis=-1)                 # (outputs, inputs); a pair that is zero
    scale = np.sqrt(peak.max(axis=1)[:, None] * peak.max(axis=0)[None, :])   # by symmetry is
    assert np.max(np.abs(h_back - h_own).max(axis=-1) / scale) < 1e-9        # judged on its row


def test_strut_frames_follow_from_the_joints(own, tmp_path):
    """Without strut_frames in the description they come from the joint points (same rule)."""
    path = export_fe_model(own, tmp_path, 'matrix-market')
    text = yaml.safe_load(path.read_text())
    del text['strut_frames']
    path.write_text(yaml.safe_dump(text))
    assert_allclose(load_fe_model(path).strut_frames, own.strut_frames, atol=1e-12)


def test_units_mm_tonne_give_the_si_model(own, tmp_path):
    """A mm-t-s model of the same machine (matrices and nodes rescaled) reads as the SI one."""
    path = export_fe_model(own, tmp_path, 'abaqus')
    text = yaml.safe_load(path.read_text())
    length, mass = 1e-3, 1e3
    translation = own.dofs.components < 3
    s = sp.diags(np.where(translation, 1.0 / length, 1.0))     # SI DOF -> mm DOF
    labels = np.column_stack([own.dofs.nodes, own.dofs.components])
    for key, matrix in [('mass', own.M)] + [(g, k) for g, k in own.stiffness_groups.items()]:
        name = text['mass'] if key == 'mass' else text['stiffness'][key]
        abaqus.write(tmp_path / name, s.power(-1) @ matrix @ s.power(-1) / (mass * length ** 2),
                     labels)
    abaqus.write_nodes(tmp_path / text['nodes'], own.dofs.labels, own.dofs.xyz / length)
    for point in text['points'].values():
        if 'offset' in point:
            point['offset'] = [v / length for v in point['offset']]
    text.update(length_unit=length, mass_unit=mass)
    path.write_text(yaml.safe_dump(text))
    back = load_fe_model(path)
    assert_allclose(back.K.toarray(), own.K.toarray(), rtol=1e-12, atol=1e-12 * abs(own.K).max())
    assert_allclose(back.M.toarray(), own.M.toarray(), rtol=1e-12, atol=1e-12 * abs(own.M).max())
    assert_allclose(back.meta['rigid_body_mass_kg'], [sum(own.mass_parts.values())] * 3,
                    rtol=1e-9)
    for name in ('tcp', 'strut1_wp_end'):
        assert_allclose(back.point_positions[name], own.point_positions[name], atol=1e-12)


def _mapdl_example():
    from ansys.mapdl.reader import examples
    return Path(examples.__file__).parent


@pytest.fixture(scope='module')
def hex_beam(tmp_path_factory):
    """The cantilever a library ships (file.full, HexBeam.cdb; in, lbf s^2/in), tip as 'tcp'."""
    folder = tmp_path_factory.mktemp('mapdl')
    example = _mapdl_example()
    path = folder / 'hexbeam.yaml'
    path.write_text(yaml.safe_dump({
        'format': 'mapdl-full', 'matrices': str(example / 'file.full'),
        'nodes': str(example / 'HexBeam.cdb'), 'length_unit': 0.0254,
        'mass_unit': 175.126835, 'points': {'tcp': {'node': _tip_node(example)}}}))
    return path


def _tip_node(example: Path) -> int:
    from ansys.mapdl import reader
    archive = reader.Archive(str(example / 'HexBeam.cdb'), parse_vtk=False)
    xyz = archive.nodes
    tip = np.flatnonzero(np.all(np.isclose(xyz[:, :3], [0.5, 0.5, 5.0]), axis=1))
    return int(archive.nnum[tip[0]])


def test_mapdl_full_example_matches_the_library_matrices_and_a_cantilever(hex_beam):
    from ansys.mapdl import reader
    fe = load_fe_model(hex_beam)
    full = reader.read_binary(str(_mapdl_example() / 'file.full'))
    assert fe.n_dof == full.neqn - len(full.const) == 900
    _, k, m = full.load_km(sort=True)
    k, m = (k + sp.triu(k, 1).T).toarray(), (m + sp.triu(m, 1).T).toarray()
    free = np.diag(k) != 0
    dense = np.sqrt(sla.eigh(k[np.ix_(free, free)], m[np.ix_(free, free)],
                             eigvals_only=True)[:10]) / (2 * np.pi)
    modes = solve_modes(fe.K, fe.M, n_modes=10)
    assert_allclose(modes.frequencies, dense, rtol=1e-9)
    # 1 x 1 x 5 in cantilever, E = 16.9e6 psi, rho = 4.1408e-4 lbf s^2/in^4: Euler-Bernoulli
    # f1 = 1.8751^2 / (2 pi) sqrt(E I / (rho A L^4)); shear (L/h = 5) lowers it by a few %
    euler = 1.87510407 ** 2 / (2 * np.pi) * np.sqrt(16.9e6 / 12 / (4.1408e-4 * 5.0 ** 4))
    assert 0.97 * euler < modes.frequencies[0] < euler
    assert_allclose(fe.point_positions['tcp'], [0.5 * 0.0254, 0.5 * 0.0254, 5 * 0.0254])


@pytest.mark.parametrize('fmt', ['matrix-market', 'abaqus'])
def test_mapdl_example_round_trips_through_the_text_formats(hex_beam, tmp_path, fmt):
    fe = load_fe_model(hex_beam)
    back = load_fe_model(export_fe_model(fe, tmp_path, fmt))
    _same_modes(solve_modes(fe.K, fe.M, n_modes=12), solve_modes(back.K, back.M, n_modes=12))
    assert_allclose(back.points['tcp'].toarray(), fe.points['tcp'].toarray(), atol=0)


def _two_node_files(folder: Path, lines: list[str], nodes: str = '1, 0, 0, 0\n2, 1, 0, 0\n'):
    (folder / 'k.mtx').write_text('** stiffness\n' + '\n'.join(lines) + '\n')
    (folder / 'm.mtx').write_text('1,1,1,1,2.0\n2,1,2,1,3.0\n')
    (folder / 'n.inp').write_text('*Heading\n*NODE, NSET=ALL\n' + nodes)
    path = folder / 'm.yaml'
    path.write_text(yaml.safe_dump({'format': 'abaqus', 'length_unit': 1.0, 'mass_unit': 1.0,
                                    'mass': 'm.mtx', 'stiffness': 'k.mtx', 'nodes': 'n.inp',
                                    'points': {'tcp': {'node': 2}}}))
    return path


def test_abaqus_either_triangle_or_both_give_the_same_matrix(tmp_path):
    lower = ['1,1,1,1,3e3', '2,1,1,1,-1e3', '2,1,2,1,1e3']
    upper = ['1,1,1,1,3e3', '1,1,2,1,-1e3', '2,1,2,1,1e3']
    both = lower + ['1,1,2,1,-1e3']
    want = np.array([[3e3, -1e3], [-1e3, 1e3]])
    for lines in (lower, upper, both):
        (tmp_path / 'k.mtx').write_text('\n'.join(lines) + '\n')
        labels, k = abaqus.read(tmp_path / 'k.mtx')
        assert_allclose(k.toarray(), want)
        assert labels.tolist() == [[1, 0], [2, 0]]


def test_penalty_diagonal_and_internal_nodes(tmp_path):
    """A 1e36 diagonal (a boundary condition) is dropped; an internal node (label < 0) stays."""
    lines = ['1,1,1,1,1e36', '2,1,1,1,-1e3', '2,1,2,1,2e3', '-1,1,2,1,-1e3', '-1,1,-1,1,1e3']
    path = _two_node_files(tmp_path, lines)
    path.write_text(path.read_text().replace('points:\n  tcp:\n    node: 2\n', ''))
    (tmp_path / 'm.mtx').write_text('1,1,1,1,2.0\n2,1,2,1,3.0\n-1,1,-1,1,1.0\n')
    fe = load_fe_model(path)
    assert fe.n_dof == 2 and fe.meta['dropped_dofs'] == 1
    assert fe.dofs.nodes.tolist() == [-1, 2]
    omega2 = sla.eigh(fe.K.toarray(), fe.M.toarray(), eigvals_only=True)
    assert_allclose(omega2, sla.eigh([[1e3, -1e3], [-1e3, 2e3]], [[1.0, 0], [0, 3.0]],
                                     eigvals_only=True))


def test_offset_point_needs_rotations(tmp_path):
    path = _two_node_files(tmp_path, ['1,1,1,1,1e3', '2,1,2,1,1e3', '2,2,2,2,1e3',
                                      '2,3,2,3,1e3'])
    text = yaml.safe_load(path.read_text())
    text['points']['tcp']['offset'] = [0.0, 0.0, 0.1]
    path.write_text(yaml.safe_dump(text))
    with pytest.raises(ModelFileError, match="point 'tcp'.*rotation DOF r"):
        load_fe_model(path)


@pytest.mark.parametrize('change,error,match', [
    ({'format': 'abacus'}, ConfigError, "did you mean 'abaqus'"),
    ({'length_unit': 0}, ConfigError, 'length_unit = 0.0 m: must be > 0'),
    ({'stiffness': None}, ConfigError, 'missing key.*stiffness'),
    ({'points': {'tcp': {'node': 99}}}, ModelFileError, 'points.tcp.node = 99: no such node'),
    ({'points': {'tcp': {'node': 1}}}, ModelFileError, "point 'tcp': node 1 has no DOF uy"),
    ({'mass': 'missing.mtx'}, ModelFileError, 'missing.mtx: not a readable Abaqus matrix'),
])
def test_bad_descriptions_are_one_line_errors(tmp_path, change, error, match):
    path = _two_node_files(tmp_path, ['1,1,1,1,1e3', '2,1,2,1,1e3', '2,2,2,2,1e3',
                                      '2,3,2,3,1e3'])
    (tmp_path / 'm.mtx').write_text('1,1,1,1,2.0\n2,1,2,1,3.0\n2,2,2,2,3.0\n2,3,2,3,3.0\n')
    text = yaml.safe_load(path.read_text())
    text.update(change)
    path.write_text(yaml.safe_dump({k: v for k, v in text.items() if v is not None}))
    with pytest.raises(error, match=match) as info:
        load_fe_model(path)
    assert '\n' not in str(info.value)


def test_asymmetric_matrix_is_refused(tmp_path):
    path = _two_node_files(tmp_path, ['1,1,1,1,3e3', '2,1,1,1,-1e3', '1,1,2,1,-2e3',
                                      '2,1,2,1,1e3'])
    with pytest.raises(ModelFileError, match='stiffness: not symmetric'):
        load_fe_model(path)


def test_every_description_and_settings_key_is_in_the_docs():
    from dataclasses import fields

    from pentapod_sim.analysis.calibration.settings import CalibrationSettings
    from pentapod_sim.fe.imported.description import FEDescription
    text = (Path(__file__).resolve().parents[1] / 'docs' / 'own_machine.md').read_text()
    missing = [f.name for cls in (FEDescription, CalibrationSettings) for f in fields(cls)
               if not f.metadata.get('internal') and f'`{f.name}`' not in text]
    assert missing == []
