"""The shell element against closed forms, and the plate frame's mesh and assembly (coarse)."""
import dataclasses
import os

import numpy as np
import pytest
import scipy.linalg as sla
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from pentapod_sim.errors import ConfigError
from pentapod_sim.fe import beam
from pentapod_sim.fe.machine_data import load_machine, machine_from_dict
from pentapod_sim.fe.shell import assemble, shell_element_matrices, ShellMesh
from pentapod_sim.schema import read_mapping

E, NU, RHO = 2.1e11, 0.3, 7850.0


def _grid_triangles(ni, nj, index):
    """
    6-node triangles on a (2 ni + 1) x (2 nj + 1) point grid; index(i, j) -> node.

    The diagonals alternate (a mesh with one diagonal direction is stiffer in bending).
    """
    tris = []
    for a in range(0, 2 * ni, 2):
        for b in range(0, 2 * nj, 2):
            p = {(da, db): index(a + da, b + db) for da in range(3) for db in range(3)}
            if (a + b) % 4 == 0:
                tris.append([p[0, 0], p[2, 0], p[2, 2], p[1, 0], p[2, 1], p[1, 1]])
                tris.append([p[0, 0], p[2, 2], p[0, 2], p[1, 1], p[1, 2], p[0, 1]])
            else:
                tris.append([p[0, 0], p[2, 0], p[0, 2], p[1, 0], p[1, 1], p[0, 1]])
                tris.append([p[2, 0], p[2, 2], p[0, 2], p[2, 1], p[1, 2], p[1, 1]])
    return np.array(tris)


def _solve(K, M, free, k):
    lam = spla.eigsh(K[free][:, free], k, M[free][:, free], sigma=0.0, which='LM')[0]
    return np.sqrt(np.sort(lam)) / (2 * np.pi)


def test_simply_supported_plate_matches_kirchhoff():
    """Square plate 0.6 m, 8 mm, simply supported: the (1,1), (1,2), (2,2) modes."""
    a, t, n = 0.6, 0.008, 10
    g = np.linspace(0.0, a, 2 * n + 1)
    xyz = np.array([[x, y, 0.0] for x in g for y in g])
    tri = _grid_triangles(n, n, lambda i, j: i * (2 * n + 1) + j)
    mesh = ShellMesh(xyz, tri, np.full(len(tri), t), np.zeros(len(tri), int), ('plate',))
    k, m, dofs = shell_element_matrices(mesh, E, NU, RHO)
    K, M = assemble(k, dofs, 6 * len(xyz)), assemble(m, dofs, 6 * len(xyz))
    edge = np.flatnonzero(np.isclose(xyz[:, 0] % a, 0) | np.isclose(xyz[:, 1] % a, 0))
    fixed = np.concatenate([6 * edge + 2, [0, 1, 6 * (2 * n)]])     # w on edges, in-plane
    f = _solve(K, M, np.setdiff1d(np.arange(6 * len(xyz)), fixed), 4)
    d = E * t ** 3 / (12 * (1 - NU ** 2))
    exact = np.pi / 2 * np.array([2, 5, 5, 8]) / a ** 2 * np.sqrt(d / (RHO * t))
    # quadratic Mindlin triangles with reduced shear integration, 5 elements per half-wave of
    # the (2, 2) mode, t / h = 0.13: up to 2.5 % stiff (the mesh-convergence table of
    # docs/model.md shows what this does to the frame)
    assert f == pytest.approx(exact, rel=0.025)


def _box_mesh(width, height, thickness, length, n_side, n_len):
    """Closed box section (mid-surface) along z, 6-node triangles, corners on even indices."""
    corners = np.array([[-width, -height], [width, -height], [width, height],
                        [-width, height]]) / 2
    loop = []
    for c in range(4):
        for s in range(2 * n_side):
            loop.append(corners[c] + (corners[(c + 1) % 4] - corners[c]) * s / (2 * n_side))
    loop = np.array(loop)
    n_loop = len(loop)
    zs = np.linspace(0.0, length, 2 * n_len + 1)
    xyz = np.array([[p[0], p[1], z] for z in zs for p in loop])
    tri = _grid_triangles(n_len, n_loop // 2, lambda i, j: i * n_loop + j % n_loop)
    return ShellMesh(xyz, tri, np.full(len(tri), thickness), np.zeros(len(tri), int), ('box',))


def test_box_cantilever_bends_like_a_timoshenko_beam():
    """Box 300 x 300 x 12 (outer), 2.4 m, clamped: the first bending pair vs beam theory."""
    w, t, length = 0.30, 0.012, 2.4
    mesh = _box_mesh(w - t, w - t, t, length, 3, 24)
    k, m, dofs = shell_element_matrices(mesh, E, NU, RHO)
    n = 6 * mesh.n_nodes
    K, M = assemble(k, dofs, n), assemble(m, dofs, n)
    clamped = np.flatnonzero(mesh.xyz[:, 2] == 0.0)
    free = np.setdiff1d(np.arange(n), (6 * clamped[:, None] + np.arange(6)).ravel())
    f_shell = _solve(K, M, free, 2)
    # the same cantilever from the project's Timoshenko beam element, 40 elements
    sec = beam.rhs_section(w, w, t)
    n_el = 40
    length_el = np.full(n_el, length / n_el)
    k_loc, m_loc = beam.local_matrices(length_el, E, E / (2 * (1 + NU)), RHO, sec.area, sec.iy,
                                       sec.iz, sec.torsion, 5 / 6)
    kb, mb = np.zeros((6 * (n_el + 1),) * 2), np.zeros((6 * (n_el + 1),) * 2)
    for e in range(n_el):
        s = slice(6 * e, 6 * e + 12)
        kb[s, s] += k_loc[e]
        mb[s, s] += m_loc[e]
    f_beam = np.sqrt(sla.eigh(kb[6:, 6:], mb[6:, 6:], eigvals_only=True)[:2]) / (2 * np.pi)
    # two equal bending modes; the shell's section deforms a little near the clamp (no
    # diaphragm there), and its next mode is a distortion of the section no beam has
    assert f_shell == pytest.approx(f_beam, rel=0.02)


def test_element_matrices_are_symmetric_and_rigid_motions_cost_nothing():
    mesh = _box_mesh(0.2, 0.1, 0.01, 0.4, 1, 2)
    k, m, dofs = shell_element_matrices(mesh, E, NU, RHO)
    K = assemble(k, dofs, 6 * mesh.n_nodes).toarray()
    M = assemble(m, dofs, 6 * mesh.n_nodes).toarray()
    assert np.allclose(K, K.T, rtol=0, atol=1e-9 * abs(K).max())
    assert sla.eigvalsh(M)[0] > 0.0
    rigid = np.zeros((6 * mesh.n_nodes, 6))
    for j in range(3):
        rigid[j::6, j] = 1.0                                   # translations
    for j, (a, b) in enumerate(((1, 2), (2, 0), (0, 1))):     # rotations about x, y, z
        rigid[3 + j::6, 3 + j] = 1.0
        rigid[a::6, 3 + j] = -mesh.xyz[:, b]
        rigid[b::6, 3 + j] = mesh.xyz[:, a]
    assert abs(K @ rigid).max() <= 1e-6 * abs(K).max()
    # the mass of a rigid translation is the plates' mass
    area = 2 * (0.2 + 0.1) * 0.4
    assert rigid[:, 0] @ M @ rigid[:, 0] == pytest.approx(RHO * 0.01 * area, rel=1e-9)


def test_shells_switch_needs_its_section():
    data = read_mapping(load_machine().source)
    data['frame']['model'] = 'shells'
    bad = dict(data)
    bad.pop('shell_frame')
    with pytest.raises(ConfigError, match='shell_frame section is missing'):
        machine_from_dict(bad)
    data['frame']['model'] = 'plates'
    with pytest.raises(ConfigError, match='frame.model.*beams, shells'):
        machine_from_dict(data)


def test_beam_frame_stays_the_default():
    assert load_machine().frame.model == 'beams'


def shell_machine(element_size=0.3, f_interest=300.0, mode_multiple=1.5):
    """The shipped machine on the plate frame, coarse (tests of a few seconds)."""
    m = load_machine()
    sh = dataclasses.replace(m.shell_frame, element_size=element_size, f_interest=f_interest,
                             mode_multiple=mode_multiple)
    return dataclasses.replace(m, frame=dataclasses.replace(m.frame, model='shells'),
                               shell_frame=sh)


@pytest.fixture(scope='module')
def coarse_frame(tmp_path_factory):
    """The coarse plate frame reduced once into a fresh cache folder: (reduced frame, folder)."""
    from pentapod_sim.modes.frame_reduction import ensure_reduced_frame
    cache = str(tmp_path_factory.mktemp('frames'))
    return ensure_reduced_frame(shell_machine(), cache), cache


def test_reduced_frame_matches_the_full_frame(coarse_frame):
    """Craig-Bampton vs the full frame on its feet springs: modes below f_interest, MAC."""
    from pentapod_sim.fe.frame_model import frame_fe, interface_dofs
    from pentapod_sim.modes.causes import mass_mac
    from pentapod_sim.modes.solver import solve_modes

    m = shell_machine()
    fe = frame_fe(m)
    red, _ = coarse_frame
    assert red.meta['f_cut_hz'] == m.shell_frame.mode_multiple * m.shell_frame.f_interest
    inst = m.installation
    k_foot = np.tile([inst.foot_stiffness_x, inst.foot_stiffness_y, inst.foot_stiffness_z,
                      0, 0, 0], 5)
    feet = [f'foot{i}' for i in range(1, 6)]
    full_k = fe.K.tolil()
    red_k = sum(red.groups.values())
    for name, k6 in zip(feet, k_foot.reshape(5, 6)):
        for d, k in zip(interface_dofs(fe, name), k6):
            full_k[d, d] += k
        for d, k in zip(interface_dofs(red, name), k6):
            red_k[d, d] += k
    f_top = m.shell_frame.f_interest
    full = solve_modes(full_k.tocsr(), fe.M, f_max=f_top)
    lam, phi = sla.eigh(red_k, red.M)
    f_red = np.sqrt(lam) / (2 * np.pi)
    n = full.n_modes
    assert n >= 10
    # Rayleigh-Ritz: the reduced model is stiffer, never softer (a mode just below f_top may
    # move just above it)
    assert np.all(f_red[:n] >= full.frequencies * (1 - 1e-9))
    # the targets: within 0.5 %, interface MAC > 0.99 for every mode below f_top
    # (measured with the residual pseudo-modes at 1.5 x: 0.010 %, lowest MAC 1.0000; without
    # them 2.2 % and 0.49, at 2 x 0.90 % and 0.92)
    assert red.meta['n_residual'] == red.n_boundary
    assert f_red[:n] == pytest.approx(full.frequencies, rel=0.005)
    b_full = np.concatenate([interface_dofs(fe, p) for p in red.interface])
    mac = mass_mac(full.shapes[b_full], phi[:red.n_boundary, :n], sp.identity(len(b_full)))
    assert np.diag(mac).min() > 0.99


@pytest.fixture(scope='module')
def coarse_shells(coarse_frame):
    """P1 on the coarse plate frame (:func:`coarse_frame`); and the cache folder."""
    from pentapod_sim.fe.assembly import build_model
    _, cache = coarse_frame
    return build_model(shell_machine(), 'P1', frame_cache=cache), cache


def test_plate_frame_model_keeps_the_contract(coarse_shells):
    from pentapod_sim.fe.assembly import GROUPS, WALL_GROUP
    model, _ = coarse_shells
    assert set(model.stiffness_groups) == set(GROUPS) | {WALL_GROUP}
    scale = abs(model.K).max()
    assert abs(sum(model.stiffness_groups.values()) - model.K).max() <= 1e-12 * scale
    assert abs(model.K - model.K.T).max() <= 1e-9 * scale
    for i in range(1, 6):
        ring = model.point_positions[f'bp_ring{i}']
        assert ring == pytest.approx(model.point_positions[f'strut{i}_at_bp'])
    # a rigid translation: the kinetic energy is the machine's whole mass
    m = model.M
    for axis in range(3):
        r = np.zeros(model.n_dof)
        free = model.dofs.components == axis
        r[free] = 1.0
        # modal coordinates do not move in a rigid translation of the interface (Psi of a
        # rigid motion is the rigid motion)
        assert r @ (m @ r) == pytest.approx(sum(model.mass_parts.values()), rel=1e-6)
    assert model.meta['frame_model'] == 'shells'


def test_cached_frame_is_reused_and_gives_the_same_model(coarse_shells):
    from pentapod_sim.fe.assembly import build_model
    from pentapod_sim.fe.frame_model import FrameNotReducedError
    model, cache = coarse_shells
    again = build_model(shell_machine(), 'P1', frame_cache=cache)
    assert abs(again.K - model.K).max() == 0.0
    with pytest.raises(FrameNotReducedError, match='not reduced yet'):
        build_model(shell_machine(element_size=0.31), 'P1', frame_cache=cache)


def test_walls_are_a_group_and_plate_modes_are_local(coarse_shells):
    from pentapod_sim.modes.causes import analyse_causes
    from pentapod_sim.modes.solver import solve_modes
    model, _ = coarse_shells
    modes = solve_modes(model.K, model.M, f_max=300.0)
    table = analyse_causes(model, modes, neuber=False)
    assert 'frame_walls' in table.group_names
    local = np.asarray(table.local_frame)
    walls = table.energy_shares[:, table.group_names.index('frame_walls')]
    # wall plate modes exist, are local (the struts and platform hardly move) ...
    assert np.count_nonzero(local & (walls > 0.5)) >= 3
    # ... and hardly add to the TCP compliance (dc gain |phi_tcp|^2 / omega^2) ...
    gain = (modes.shapes_at(model.point('tcp'))[:3] ** 2).sum(axis=0) / modes.omega ** 2
    assert gain[local].max() < 1e-2 * gain.max()           # measured: 0.22 %
    # ... while the mode with the most TCP compliance (the frame on its feet, x) is not local
    # (the lowest mode may be: the door lintel's plate mode, its lower edge free)
    assert not local[int(np.argmax(gain))]


def _walls(machine):
    from pentapod_sim.fe.frame_mesh import frame_plates
    return [corners for corners, _, part in frame_plates(machine).plates if part == 'wall']


def test_the_door_bay_has_only_its_lintel():
    m = shell_machine()
    fr, sh = m.frame, m.shell_frame
    top = fr.column_height - fr.ring.height / 2          # wall top: the top ring's middle
    open_bay = dataclasses.replace(m, shell_frame=dataclasses.replace(sh, door_lintel=0.0))
    lintel = dataclasses.replace(m, shell_frame=dataclasses.replace(sh, door_lintel=0.7))
    assert len(_walls(open_bay)) == sum(sh.walls) == 4
    walls = _walls(lintel)
    assert len(walls) == 5
    # the new plate spans the door bay's chord (columns 1 and 2, 38 and 142 deg), 0.7 m high
    extra = [w for w in walls if not any(np.allclose(w, v) for v in _walls(open_bay))]
    assert len(extra) == 1
    door = extra[0]
    assert door[:, 2].min() == pytest.approx(top - 0.7)
    assert door[:, 2].max() == pytest.approx(top)
    azimuths = np.sort(np.unique(np.round(np.degrees(np.arctan2(door[:, 1], door[:, 0])), 6)))
    assert azimuths == pytest.approx([38.0, 142.0])
    too_tall = dataclasses.replace(m, shell_frame=dataclasses.replace(sh, door_lintel=2.5))
    with pytest.raises(ConfigError, match='door_lintel 2.5'):
        _walls(too_tall)


def test_frame_cache_key_leaves_out_what_is_added_per_pose():
    from pentapod_sim.fe.frame_model import reduced_frame_path
    m = shell_machine()
    heavier_bed = dataclasses.replace(m, frame=dataclasses.replace(m.frame, bed_mass=900.0))
    stiffer_feet = dataclasses.replace(m, shell_frame=dataclasses.replace(
        m.shell_frame, foot_stiffness=(1e8, 1e8, 1e9)))
    longer_seat = dataclasses.replace(m, shell_frame=dataclasses.replace(
        m.shell_frame, seat_height=0.4))
    key = reduced_frame_path(m)
    assert reduced_frame_path(heavier_bed) == key
    assert reduced_frame_path(stiffer_feet) == key
    assert reduced_frame_path(longer_seat) != key


def _frame_alone_frequencies(element_size, n=6):
    from pentapod_sim.fe.frame_model import frame_on_feet
    from pentapod_sim.modes.solver import solve_modes
    K, M, _, _ = frame_on_feet(shell_machine(), element_size)
    return solve_modes(K, M, n_modes=n).frequencies


def test_the_frame_alone_converges_from_above_with_the_mesh():
    """
    The frame on its feet with the bed (no struts): its six lowest modes at 0.2 and 0.15 m.

    Measured (docs/model.md, "Mesh convergence of the plate frame"): every mode falls
    monotonically from 0.3 to 0.07 m, at about h^2 (x sway 28.4 -> 27.8 Hz, at most 3.4 %
    from 0.2 to 0.15 m). A locking shell (full integration of the transverse shear) is stiffer
    on coarse meshes and loses it faster (more than 5 %); a mode that is not there on one mesh
    (a coupling that changes with the mesh, a spurious mode) breaks the pairing.
    """
    coarse, fine = _frame_alone_frequencies(0.2), _frame_alone_frequencies(0.15)
    change = coarse / fine - 1.0
    assert np.all(change > 0.0), change          # the element converges from above
    assert np.all(change < 0.05), change


@pytest.mark.parametrize('part', ['whole', 'part'])
def test_the_symmetric_projection_equals_the_whole_product(monkeypatch, part):
    """Also for a matrix with entries on some DOFs only (a group), in chunks of rows."""
    from pentapod_sim.modes import frame_reduction
    monkeypatch.setattr(frame_reduction, 'PROJECT_ROWS', 37)
    rng = np.random.default_rng(4)
    A = sp.random(500, 500, density=0.02, random_state=4, format='csr')
    A = (A + A.T).tocsr()
    if part == 'part':           # rows and columns of 160 scattered DOFs only
        mine = np.zeros(500, dtype=bool)
        mine[rng.choice(500, 160, replace=False)] = True
        A = sp.csr_matrix(sp.diags(mine.astype(float)) @ A @ sp.diags(mine.astype(float)))
        A.eliminate_zeros()
        assert np.count_nonzero(np.diff(A.indptr)) <= 160
    for m in (frame_reduction.PROJECT_BLOCK - 1, 2 * frame_reduction.PROJECT_BLOCK + 37):
        B = rng.standard_normal((500, m))
        P = frame_reduction._symmetric_projection(A, B)
        np.testing.assert_allclose(P, B.T @ (A.toarray() @ B), rtol=0, atol=1e-10)
        assert np.array_equal(P, P.T)


def test_the_reduction_runs_with_its_threads_and_gives_them_back(monkeypatch, coarse_frame):
    """BLAS (and MKL) threads inside reduce_frame are its ``threads``; the process's after."""
    from threadpoolctl import threadpool_info

    from pentapod_sim.fe.frame_model import frame_fe
    from pentapod_sim.modes import frame_reduction, ldlt

    def limits():
        return {i['internal_api']: i['num_threads'] for i in threadpool_info()
                if i['user_api'] == 'blas'}

    class Enough(Exception):
        """The modes are not needed: the reduction stops at its modal solve."""

    seen = []

    def spy(*args, **kwargs):
        seen.append(limits())
        raise Enough

    fe = frame_fe(shell_machine())
    monkeypatch.setattr(frame_reduction, 'solve_modes', spy)
    ldlt.available()                     # MKL loaded (where installed) before the limits
    before = limits()
    with pytest.raises(Enough):
        frame_reduction.reduce_frame(fe, 300.0, lambda msg: None, threads=3)
    assert limits() == before
    assert seen[-1]['openblas'] == 3
    if ldlt.available():
        assert seen[-1]['mkl'] == 3
    # the default: one thread below THREADS_MIN_DOF DOF (the coarse frame), one per CPU above
    assert fe.n_dof < frame_reduction.THREADS_MIN_DOF
    assert coarse_frame[0].meta['threads'] == 1
    assert frame_reduction.frame_threads(frame_reduction.THREADS_MIN_DOF) == len(
        os.sched_getaffinity(0))


def test_a_reduction_on_two_threads_gives_the_same_frame(coarse_frame):
    """Threaded BLAS, MKL and sparse products (row_split): the coarse frame of one thread."""
    from pentapod_sim.fe.frame_model import frame_fe
    from pentapod_sim.modes.frame_reduction import reduce_frame
    one, _ = coarse_frame
    m = shell_machine()
    two = reduce_frame(frame_fe(m), m.shell_frame.mode_multiple * m.shell_frame.f_interest,
                       lambda msg: None, threads=2)
    assert (one.meta['threads'], two.meta['threads']) == (1, 2)
    assert two.meta['n_modes'] == one.meta['n_modes'] and two.frequencies.size > 50
    np.testing.assert_allclose(two.frequencies, one.frequencies, rtol=1e-9)
    # a mode's sign may differ: compare what does not depend on it
    for g, A in one.groups.items():
        np.testing.assert_allclose(np.abs(two.groups[g]), np.abs(A), rtol=0,
                                   atol=1e-9 * np.abs(A).max())
    np.testing.assert_allclose(np.abs(two.M), np.abs(one.M), rtol=0, atol=1e-9)


ANALYSED_WITH_OTHER_THREADS = r"""
import sys
from test_shell_frame import shell_machine
from pentapod_sim.fe.frame_model import frame_fe
from pentapod_sim.modes import frame_reduction


class Enough(Exception):
    pass


def stop(*args, **kwargs):
    raise Enough


fe = frame_fe(shell_machine())
real, frame_reduction.solve_modes = frame_reduction.solve_modes, stop
try:         # K_ii factorised on 2 MKL threads and released: its analysis is kept
    frame_reduction.reduce_frame(fe, 300.0, lambda msg: None, threads=2)
except Enough:
    pass
frame_reduction.solve_modes = real
frame = frame_reduction.reduce_frame(fe, 100.0, lambda msg: None, threads=1)
print(frame.meta['n_modes'])
"""


def test_a_reduction_on_other_threads_than_a_kept_analysis_ends():
    """
    PARDISO's kept analysis is for one MKL thread count (pentapod_sim.modes.ldlt).

    Reused by a numerical factorisation on another count (2 then 1, 3 then 2), it crashed
    (SIGSEGV) or hung the process (4 of 4 runs); in a process of its own, so that such an end
    fails this test.
    """
    from pathlib import Path
    import subprocess
    import sys
    root = Path(__file__).resolve().parents[1]
    env = {**os.environ, 'PYTHONPATH': os.pathsep.join(
        [str(root), str(root / 'test'), *filter(None, [os.environ.get('PYTHONPATH')])])}
    out = subprocess.run([sys.executable, '-c', ANALYSED_WITH_OTHER_THREADS], env=env,
                         capture_output=True, text=True, timeout=240)
    assert out.returncode == 0, (out.returncode, out.stderr[-2000:])
    assert int(out.stdout.split()[-1]) > 5, out.stdout
