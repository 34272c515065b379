"""Cause analysis: one elasticity at a time (closed form), strain-energy shares, TCP direction."""
import csv

import numpy as np
from numpy.testing import assert_allclose
import pytest
import scipy.linalg as sla
import scipy.sparse as sp

from pentapod_sim.fe.model import FEModel
from pentapod_sim.modes.cause_plots import plot_energy_shares, plot_mode_distribution
from pentapod_sim.modes.causes import (
    analyse_causes,
    mass_mac,
    neuber_frequencies,
    rigidified_stiffness,
    strain_energy_shares,
    tcp_directions,
)
from pentapod_sim.modes.solver import solve_modes

M1, M2 = 50.0, 20.0            # kg
K_SOFT, K_STIFF = 1.0e5, 1.0e8  # N/m: ground - m1 (soft), m1 - m2 (stiff)


def make_model(groups: dict, M, points=None) -> FEModel:
    """A FEModel holding only what the cause analysis reads."""
    K = sum(groups.values()).tocsr()
    return FEModel(K=K, M=sp.csr_matrix(M), stiffness_groups=groups, points=points or {},
                   point_positions={}, strut_frames=np.zeros((5, 3, 3)))


def two_mass_chain() -> FEModel:
    soft = sp.csr_matrix(np.array([[K_SOFT, 0.0], [0.0, 0.0]]))
    stiff = sp.csr_matrix(K_STIFF * np.array([[1.0, -1.0], [-1.0, 1.0]]))
    return make_model({'soft': soft, 'stiff': stiff}, sp.diags([M1, M2]))


def two_dof_roots(k11: float, k22: float, k12: float,
                  det: float) -> tuple[np.ndarray, np.ndarray]:
    """
    omega^2 of [[k11, k12], [k12, k22]] with masses M1, M2 and the mode ratios x2/x1.

    Quadratic formula in its cancellation-free form: the large root directly, the small one
    from the product of the roots, det = k11 k22 - k12^2 given in closed form.
    """
    b = k11 * M2 + k22 * M1
    high = (b + np.sqrt(b ** 2 - 4 * M1 * M2 * det)) / (2 * M1 * M2)
    w2 = np.array([det / (M1 * M2 * high), high])
    return w2, (w2 * M1 - k11) / k12


class TestTwoMassChain:
    def test_energy_shares_follow_closed_form(self):
        model = two_mass_chain()
        modes = solve_modes(model.K, model.M, n_modes=2)
        w2, ratio = two_dof_roots(K_SOFT + K_STIFF, K_STIFF, -K_STIFF, K_SOFT * K_STIFF)
        assert_allclose(modes.omega ** 2, w2, rtol=1e-10)
        e_soft, e_stiff = K_SOFT * 1.0, K_STIFF * (ratio - 1.0) ** 2   # x1 = 1
        shares = strain_energy_shares(model.stiffness_groups, modes)
        assert_allclose(shares[:, 0], e_soft / (e_soft + e_stiff), rtol=1e-8)
        assert_allclose(shares.sum(axis=1), 1.0)

    def test_soft_group_causes_the_low_mode(self):
        table = analyse_causes(two_mass_chain(), solve_modes(*_km(two_mass_chain()), n_modes=2))
        assert table.cause == ('soft', 'stiff')
        assert table.neuber_cause == ('soft', 'stiff')
        assert table.tcp_direction == ('-', '-')   # no point 'tcp' in this model

    @pytest.mark.parametrize('alpha', [1e2, 1e4, 1e6])
    def test_one_elasticity_frequencies_follow_closed_form(self, alpha):
        model = two_mass_chain()
        modes = solve_modes(model.K, model.M, n_modes=2)
        freq, mac = neuber_frequencies(model.stiffness_groups, model.M, modes, alpha=alpha,
                                       band_factor=10.0)
        det = alpha * K_SOFT * K_STIFF
        soft_only, _ = two_dof_roots(K_SOFT + alpha * K_STIFF, alpha * K_STIFF,
                                     -alpha * K_STIFF, det)
        stiff_only, _ = two_dof_roots(alpha * K_SOFT + K_STIFF, K_STIFF, -K_STIFF, det)
        # LAPACK's relative accuracy on the small root degrades like eps * condition number
        rtol = max(1e-15 * alpha * K_STIFF / K_SOFT, 1e-10)
        assert_allclose(freq[0, 0], np.sqrt(soft_only[0]) / (2 * np.pi), rtol=rtol)
        # only once alpha * K_SOFT exceeds K_STIFF is m1 held and the stiff spring's mode the
        # lowest one of the stiff-only model; for alpha=100 it is still the upper root
        root = 0 if alpha * K_SOFT > K_STIFF else 1
        assert_allclose(freq[1, 1], np.sqrt(stiff_only[root]) / (2 * np.pi), rtol=1e-9)
        assert mac[0, 0] > 0.99
        # rigid limit: both masses move together on the soft spring
        limit = np.sqrt(K_SOFT / (M1 + M2)) / (2 * np.pi)
        assert abs(freq[0, 0] / limit - 1.0) < 10.0 * K_SOFT / (alpha * K_STIFF) + rtol

    def test_dunkerley_estimate_of_the_share(self):
        # for the fundamental mode (f / f_soft_only)^2 approximates the soft group's share
        model = two_mass_chain()
        modes = solve_modes(model.K, model.M, n_modes=2)
        freq, _ = neuber_frequencies(model.stiffness_groups, model.M, modes)
        share = strain_energy_shares(model.stiffness_groups, modes)[0, 0]
        assert_allclose((modes.frequencies[0] / freq[0, 0]) ** 2, share, rtol=1e-3)


def _km(model: FEModel):
    return model.K, model.M


def rigid_body_on_springs() -> FEModel:
    """6-DOF rigid body: translational springs ('installation'), rotational ones ('frame')."""
    mass, inertia = 10.0, np.array([1.0, 2.0, 3.0])         # kg, kg m^2
    k_trans = mass * np.array([1.0e4, 2.0e4, 4.0e4])         # N/m -> omega^2 1e4, 2e4, 4e4
    k_rot = inertia * np.array([1.5e4, 3.0e4, 5.0e4])        # N m/rad -> 1.5e4, 3e4, 5e4
    groups = {'installation': sp.diags(np.r_[k_trans, 0, 0, 0]).tocsr(),
              'frame': sp.diags(np.r_[0, 0, 0, k_rot]).tocsr()}
    return make_model(groups, sp.diags(np.r_[[mass] * 3, inertia]),
                      points={'tcp': sp.identity(6, format='csr')})


class TestRigidBody:
    def test_directions_causes_and_one_elasticity_frequencies(self):
        model = rigid_body_on_springs()
        modes = solve_modes(model.K, model.M, n_modes=6)
        assert_allclose(modes.omega ** 2, [1e4, 1.5e4, 2e4, 3e4, 4e4, 5e4], rtol=1e-10)
        table = analyse_causes(model, modes)
        assert table.tcp_direction == ('x', 'rx', 'y', 'ry', 'z', 'rz')
        expected = ('installation', 'frame') * 3
        assert table.cause == expected and table.neuber_cause == expected
        # uncoupled: the elastic group alone reproduces each mode exactly, with MAC 1
        col = np.array([0 if c == 'installation' else 1 for c in expected])
        assert_allclose(table.neuber_frequency[np.arange(6), col], modes.frequencies,
                        rtol=1e-9)
        assert_allclose(table.neuber_mac[np.arange(6), col], 1.0, rtol=1e-9)
        assert_allclose(table.energy_shares[np.arange(6), col], 1.0)

    def test_rotation_length_weighs_rotations_against_translations(self):
        model = rigid_body_on_springs()
        modes = solve_modes(model.K, model.M, n_modes=6)
        # a mode with translation 1 m and rotation 0.5 rad: rotation wins only beyond 2 m
        T = np.zeros((6, 6))
        T[0, 0], T[3, 0] = 1.0, 0.5
        mixed = type(modes)(modes.frequencies[:1], np.eye(6)[:, :1])
        assert tcp_directions(mixed, T, rotation_length=1.0) == ('x',)
        assert tcp_directions(mixed, T, rotation_length=3.0) == ('rx',)


class TestLargerStructure:
    def test_shares_match_dense_computation_on_sliced_solve(self):
        # 600 DOF (above the dense limit): random SPD groups, independent dense reference
        rng = np.random.default_rng(7)
        n = 600
        groups = {}
        for g in range(3):
            A = sp.random(n, n, density=3.0 / n, random_state=10 + g, format='csr')
            groups[f'g{g}'] = (A @ A.T * 10.0 ** (5 + g)).tocsr()
        groups['g0'] = groups['g0'] + sp.identity(n) * 1e3
        model = make_model(groups, sp.diags(rng.uniform(1.0, 3.0, n)))
        modes = solve_modes(model.K, model.M, n_modes=40, modes_per_window=10)
        lam, phi = sla.eigh(model.K.toarray(), model.M.toarray())
        dense = np.array([[phi[:, j] @ Kg.toarray() @ phi[:, j] / lam[j]
                           for Kg in groups.values()] for j in range(40)])
        assert_allclose(strain_energy_shares(groups, modes), dense, atol=1e-8)


class TestOutputs:
    def test_csv_has_one_row_per_mode_and_shares_sum_to_one(self, tmp_path):
        model = rigid_body_on_springs()
        table = analyse_causes(model, solve_modes(model.K, model.M, n_modes=6))
        table.to_csv(tmp_path / 'modes.csv')
        with open(tmp_path / 'modes.csv') as fh:
            rows = list(csv.DictReader(fh))
        assert [int(r['mode']) for r in rows] == list(range(1, 7))
        for r, f in zip(rows, table.frequencies):
            assert float(r['frequency_hz']) == pytest.approx(f)
            assert float(r['share_installation']) + float(r['share_frame']) == pytest.approx(1)
        assert rows[1]['tcp_direction'] == 'rx' and rows[1]['neuber_cause'] == 'frame'
        text = table.format_table(3)
        assert len(text.splitlines()) == 4 and 'installation' in text

    def test_plots_are_png_files(self, tmp_path):
        model = rigid_body_on_springs()
        table = analyse_causes(model, solve_modes(model.K, model.M, n_modes=6), neuber=False)
        assert table.neuber_cause is None
        plot_energy_shares(table, tmp_path / 'shares.png')
        plot_mode_distribution(table.frequencies, tmp_path / 'dist.png', bin_width=5.0)
        for name in ('shares.png', 'dist.png'):
            assert (tmp_path / name).read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'


class TestErrors:
    def test_unknown_group_and_bad_alpha(self):
        groups = two_mass_chain().stiffness_groups
        with pytest.raises(KeyError, match='frame.*soft, stiff'):
            rigidified_stiffness(groups, 'frame')
        with pytest.raises(ValueError, match='alpha=0.5'):
            rigidified_stiffness(groups, 'soft', alpha=0.5)

    def test_mac_of_a_mode_set_with_itself_is_identity(self):
        model = rigid_body_on_springs()
        modes = solve_modes(model.K, model.M, n_modes=6)
        assert_allclose(mass_mac(modes.shapes, modes.shapes, model.M), np.eye(6), atol=1e-12)


class TestModesCommand:
    """The `modes` command on the real default model, against a plain ARPACK solve."""

    def test_table_csv_and_count_agree_with_plain_eigsh(self, tmp_path, capsys):
        import scipy.sparse.linalg as spla

        from pentapod_sim.cli.modes import main
        from pentapod_sim.fe import assembly, machine_data

        assert main(['--position', 'P2', '--out', str(tmp_path), '--rows', '12']) == 0
        text = capsys.readouterr().out
        with open(tmp_path / 'modes.csv') as fh:
            rows = list(csv.DictReader(fh))
        model = assembly.build_model(machine_data.load_machine(), 'P2')
        lam = spla.eigsh(model.K, len(rows) + 3, model.M, sigma=0, return_eigenvectors=False)
        f_ref = np.sort(np.sqrt(lam)) / (2 * np.pi)
        # every mode below 750 Hz and no other: the next one is above the band
        assert f_ref[len(rows) - 1] < 750.0 < f_ref[len(rows)]
        assert_allclose([float(r['frequency_hz']) for r in rows], f_ref[:len(rows)], rtol=1e-8)
        assert f'modes below 750 Hz (Sturm count): {len(rows)}' in text
        assert f'{model.n_dof} DOF' in text
        assert len([ln for ln in text.splitlines() if ln[:4].strip().isdigit()]) == 12
        for name in ('energy_shares.png', 'mode_distribution.png'):
            assert (tmp_path / name).stat().st_size > 1000

    def test_workers_solve_the_slices_side_by_side(self, tmp_path, capsys):
        import scipy.sparse.linalg as spla

        from pentapod_sim.cli.modes import main
        from pentapod_sim.fe import assembly, machine_data

        assert main(['--position', 'P1', '--out', str(tmp_path), '--n-modes', '60',
                     '--modes-per-window', '12', '--workers', '2', '--no-neuber']) == 0
        assert '2 window process(es)' in capsys.readouterr().out
        with open(tmp_path / 'modes.csv') as fh:
            f = [float(r['frequency_hz']) for r in csv.DictReader(fh)]
        model = assembly.build_model(machine_data.load_machine(), 'P1')
        lam = spla.eigsh(model.K, 60, model.M, sigma=0, return_eigenvectors=False)
        assert_allclose(f, np.sort(np.sqrt(lam)) / (2 * np.pi), rtol=1e-8)
        assert main(['--position', 'P1', '--workers', '0']) == 2
        assert 'error: --workers must be >= 1, got 0' in capsys.readouterr().err

    def test_unknown_position_is_an_error_naming_it(self, tmp_path, capsys):
        from pentapod_sim.cli.modes import main

        assert main(['--position', 'P99', '--out', str(tmp_path)]) == 1
        assert 'P99' in capsys.readouterr().err
