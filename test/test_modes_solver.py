"""Sparse modal solver: Sturm counts, spectrum slicing, closed-form chain frequencies."""
import numpy as np
from numpy.testing import assert_allclose
import pytest
import scipy.linalg as sla
import scipy.sparse as sp

from pentapod_sim.errors import ModalError
from pentapod_sim.modes import slicing, window_pool
from pentapod_sim.modes.solver import DENSE_LIMIT, solve_modes
from pentapod_sim.modes.sturm import factor_at, factorize_shifted, inertia_count, sturm_count
from pentapod_sim.modes.windows import METHODS

slicing_next_shift = slicing._next_shift


def fixed_free_chain(n: int, k: float = 2.0e6, m: float = 3.0):
    """N equal masses m [kg] in a row, springs k [N/m], first spring to ground, last mass free."""
    main = np.full(n, 2.0 * k)
    main[-1] = k
    off = -k * np.ones(n - 1)
    K = sp.diags([main, off, off], [0, 1, -1], format='csr')
    return K, sp.identity(n, format='csr') * m


def chain_frequencies(n: int, k: float = 2.0e6, m: float = 3.0) -> np.ndarray:
    """Closed form of the fixed-free chain: omega_j = 2 sqrt(k/m) sin((2j-1) pi / (2(2n+1)))."""
    j = np.arange(1, n + 1)
    return 2.0 * np.sqrt(k / m) * np.sin((2 * j - 1) * np.pi / (2 * (2 * n + 1))) / (2 * np.pi)


def random_structure(n: int, seed: int = 0):
    """Random sparse SPD stiffness and diagonal mass, a generic non-chain test pair."""
    rng = np.random.default_rng(seed)
    A = sp.random(n, n, density=4.0 / n, random_state=seed, format='csr')
    K = (A @ A.T + sp.diags(rng.uniform(0.01, 0.1, n))) * 1e6
    M = sp.diags(rng.uniform(1.0, 5.0, n))
    return K.tocsr(), M.tocsr()


def _record_windows(monkeypatch) -> list[int]:
    """The modes each window of a serial slicing run asks for (0: a count only), in order."""
    asked: list[int] = []
    solve = window_pool._Solver.__call__

    def recorded(self, sigma, k):
        asked.append(k)
        return solve(self, sigma, k)

    monkeypatch.setattr(window_pool._Solver, '__call__', recorded)
    return asked


class TestSturmCount:
    def test_matches_dense_eigh_at_many_shifts(self):
        K, M = random_structure(300)
        lam = sla.eigh(K.toarray(), M.toarray(), eigvals_only=True)
        for i in (0, 3, 40, 151, 299):
            shift = 0.5 * (lam[i] + lam[i + 1]) if i < 299 else 2 * lam[-1]
            assert sturm_count(K, M, shift) == np.count_nonzero(lam < shift)

    def test_below_spectrum_is_zero_and_above_is_n(self):
        K, M = fixed_free_chain(500)
        w_max = 2 * np.pi * chain_frequencies(500)[-1]
        assert sturm_count(K, M, -1.0) == 0
        assert sturm_count(K, M, 1.01 * w_max ** 2) == 500

    def test_inertia_from_factorisation_of_indefinite_matrix(self):
        # K - s M with s between known eigenvalues is indefinite; diag(U) gives its inertia
        K, M = fixed_free_chain(1000)
        w = 2 * np.pi * chain_frequencies(1000)
        lu = factorize_shifted(K, M, 0.5 * (w[9] ** 2 + w[10] ** 2))
        assert inertia_count(lu) == 10


class TestSharedFactorisation:
    def test_one_factorisation_solves_and_counts(self):
        K, M = random_structure(400, seed=5)
        lam = sla.eigh(K.toarray(), M.toarray(), eigvals_only=True)
        shift = 0.5 * (lam[57] + lam[58])
        factor = factor_at(K, M, shift)
        assert factor.count == 58 == sturm_count(K, M, shift)
        b = np.random.default_rng(0).standard_normal(400)
        x = factor.lu.solve(b)
        assert_allclose((K - shift * M) @ x, b, rtol=0, atol=1e-9 * np.abs(b).max())

    def test_slicing_factorises_once_per_window_and_counts_right(self):
        n = 3000
        K, M = fixed_free_chain(n)
        exact = chain_frequencies(n)
        res = solve_modes(K, M, n_modes=120, modes_per_window=25)
        # one factorisation per window (solves and Sturm count) plus the count at the end;
        # counting at separate edges took 2 per window
        assert res.stats['windows'] >= 4
        assert res.stats['factorisations'] <= res.stats['windows'] + 1 + res.stats['retries']
        assert_allclose(res.frequencies, exact[:120], rtol=1e-9)
        f_max = 0.5 * (exact[99] + exact[100])
        res = solve_modes(K, M, f_max=f_max, modes_per_window=25)
        assert res.sturm_count == res.n_modes == 100
        assert res.stats['factorisations'] <= res.stats['windows'] + 2 + res.stats['retries']

    def test_a_window_that_does_not_reach_down_gets_a_window_in_its_gap(self, monkeypatch):
        # every shift extrapolated three times too far: each window's lowest mode lies above
        # the cut it should continue from; the gap's modes come from a window solved there
        n = 3000
        K, M = fixed_free_chain(n)
        exact = chain_frequencies(n)
        real = slicing._next_shift

        def too_far(lam, a, target):
            return a + 3.0 * (real(lam, a, target) - a)

        monkeypatch.setattr(slicing, '_next_shift', too_far)
        asked = _record_windows(monkeypatch)
        res = solve_modes(K, M, n_modes=150, modes_per_window=25, workers=1)
        assert res.stats['gap_windows'] >= 2 and res.stats['retries'] == 0
        assert_allclose(res.frequencies, exact[:150], rtol=1e-9)
        assert_allclose(res.shapes.T @ (M @ res.shapes), np.eye(150), atol=1e-8)
        # a gap window asks for the modes the Sturm count says are missing, not for 1.5 times
        # a whole window's
        assert min(asked) < slicing.WINDOW_PAD * 25

    def test_the_last_window_asks_for_the_modes_left_below_f_max(self, monkeypatch):
        n = 3000
        K, M = fixed_free_chain(n)
        exact = chain_frequencies(n)
        asked = _record_windows(monkeypatch)
        f_max = 0.5 * (exact[59] + exact[60])         # 60 modes: 41 in the first window
        res = solve_modes(K, M, f_max=f_max, modes_per_window=40, workers=1,
                          share_last_windows=True)
        assert res.sturm_count == res.n_modes == 60
        assert_allclose(res.frequencies, exact[:60], rtol=1e-9)
        solving = [k for k in asked if k]
        # one window after the first, for the 20 or so left (with the margin), not a whole
        # window's 52 (as without share_last_windows)
        assert len(solving) == 2 and solving[1] < 0.75 * slicing.WINDOW_PAD * 40
        asked.clear()
        solve_modes(K, M, f_max=f_max, modes_per_window=40, workers=1)
        assert [k for k in asked if k][1] == int(slicing.WINDOW_PAD * 40)
        # the last window takes all that is left when that is up to 1.25 windows
        asked.clear()
        f_max = 0.5 * (exact[99] + exact[100])        # 100 modes: about 39 left
        res = solve_modes(K, M, f_max=f_max, modes_per_window=60, workers=1,
                          share_last_windows=True)
        assert res.sturm_count == res.n_modes == 100
        assert_allclose(res.frequencies, exact[:100], rtol=1e-9)
        assert len([k for k in asked if k]) == 2
        # more than that left: shared by equal windows
        asked.clear()
        f_max = 0.5 * (exact[159] + exact[160])       # 160 modes: about 119 left
        res = solve_modes(K, M, f_max=f_max, modes_per_window=40, workers=1,
                          share_last_windows=True)
        assert res.sturm_count == res.n_modes == 160
        assert_allclose(res.frequencies, exact[:160], rtol=1e-9)
        later = [k for k in asked if k][1:]       # each sized to a share, none a whole 52
        assert len(later) >= 3 and max(later) < slicing.WINDOW_PAD * 40

    def test_shift_on_an_eigenvalue_still_gives_every_mode_once(self, monkeypatch):
        # every window shift put on an eigenvalue (closed form, exact to rounding): K - s M is
        # singular to rounding and its inertia may count that eigenvalue on either side
        n = 2000
        K, M = fixed_free_chain(n)
        exact = chain_frequencies(n)
        lam_exact = (2 * np.pi * exact) ** 2
        hits = []

        def on_an_eigenvalue(lam, a, target):
            j = int(np.argmin(np.abs(lam_exact - slicing_next_shift(lam, a, target))))
            hits.append(j)
            return float(lam_exact[j])

        monkeypatch.setattr(slicing, '_next_shift', on_an_eigenvalue)
        res = solve_modes(K, M, n_modes=80, modes_per_window=20)
        assert len(hits) >= 3
        assert_allclose(res.frequencies, exact[:80], rtol=1e-9)
        G = res.shapes.T @ (M @ res.shapes)
        assert_allclose(G, np.eye(80), atol=1e-8)

        # now make the race happen: the eigenvalue at the shift comes back on the other side
        # of the shift than the inertia counted it; the slicer must move that shift
        solve = window_pool.window_eigs

        def other_side(K, M, factor, k, method, tol, checkpoint=None):
            lam, phi = solve(K, M, factor, k, method, tol, checkpoint)
            j = np.flatnonzero(lam_exact == factor.sigma)
            if j.size:
                i = int(np.argmin(np.abs(lam - factor.sigma)))
                lam[i] = factor.sigma * (1 - 1e-13 if factor.count == j[0] else 1 + 1e-13)
            return lam, phi

        monkeypatch.setattr(window_pool, 'window_eigs', other_side)
        res = solve_modes(K, M, n_modes=80, modes_per_window=20)
        assert res.stats['retries'] >= 1
        assert_allclose(res.frequencies, exact[:80], rtol=1e-9)


def _primme_missing_is_named(K, M, **kwargs) -> bool:
    """True (after checking the error) where the optional package primme is not installed."""
    try:
        import primme  # noqa: F401
    except ImportError:
        with pytest.raises(ModalError, match='pip install primme'):
            solve_modes(K, M, method='primme', **kwargs)
        return True
    return False


@pytest.mark.parametrize('method', sorted(METHODS))
def test_window_solvers_match_dense_eigh(method):
    """
    ARPACK and PRIMME windows: the frequencies and shapes of dense LAPACK eigh.

    PRIMME is optional (not in requirements.txt): without it the error must name the package.
    """
    n = 900
    K, M = random_structure(n, seed=3)
    if method == 'primme' and _primme_missing_is_named(K, M, n_modes=70):
        return
    lam, phi = sla.eigh(K.toarray(), M.toarray())
    res = solve_modes(K, M, n_modes=70, modes_per_window=12, method=method)
    assert res.stats['method'].startswith(METHODS[method])
    assert_allclose(res.omega ** 2, lam[:70], rtol=1e-8)
    mac = (phi[:, :70].T @ (M @ res.shapes)).diagonal() ** 2
    assert_allclose(mac, 1.0, atol=1e-6)
    assert res.stats['max_residual'] < 1e-6


@pytest.mark.parametrize('method', sorted(METHODS))
def test_window_solvers_match_chain_closed_form_with_f_max(method):
    n = 2500
    K, M = fixed_free_chain(n)
    exact = chain_frequencies(n)
    f_max = 0.5 * (exact[136] + exact[137])
    if method == 'primme' and _primme_missing_is_named(K, M, f_max=f_max):
        return
    res = solve_modes(K, M, f_max=f_max, modes_per_window=30, method=method)
    assert res.sturm_count == res.n_modes == 137
    assert_allclose(res.frequencies, exact[:137], rtol=1e-9)


class TestSolveModes:
    def test_chain_lowest_modes_match_closed_form(self):
        n = 3000
        K, M = fixed_free_chain(n)
        res = solve_modes(K, M, n_modes=120, modes_per_window=25)
        assert res.stats['windows'] >= 4   # the slicing path was exercised
        assert_allclose(res.frequencies, chain_frequencies(n)[:120], rtol=1e-9)
        assert_allclose(res.omega, 2 * np.pi * res.frequencies)

    def test_shapes_are_mass_normalised_and_orthogonal(self):
        K, M = fixed_free_chain(2000)
        res = solve_modes(K, M, n_modes=90, modes_per_window=20)
        G = res.shapes.T @ (M @ res.shapes)
        assert_allclose(G, np.eye(90), atol=1e-8)
        # each column is an eigenvector: K phi = omega^2 M phi
        R = K @ res.shapes - (M @ res.shapes) * res.omega ** 2
        assert np.abs(R).max() < 1e-6 * np.abs(K @ res.shapes).max()

    def test_f_max_returns_all_modes_below_with_sturm_count(self):
        n = 2500
        K, M = fixed_free_chain(n)
        exact = chain_frequencies(n)
        f_max = 0.5 * (exact[136] + exact[137])   # 137 modes below
        res = solve_modes(K, M, f_max=f_max, modes_per_window=30)
        assert res.sturm_count == 137
        assert res.n_modes == 137
        assert_allclose(res.frequencies, exact[:137], rtol=1e-9)
        assert res.count_below(f_max) == 137

    def test_repeated_eigenvalues_are_neither_lost_nor_doubled(self):
        # two identical, uncoupled chains: every eigenvalue has multiplicity two
        K1, M1 = fixed_free_chain(1500)
        K, M = sp.block_diag([K1, K1], format='csr'), sp.block_diag([M1, M1], format='csr')
        res = solve_modes(K, M, n_modes=100, modes_per_window=15)
        assert_allclose(res.frequencies, np.repeat(chain_frequencies(1500)[:50], 2), rtol=1e-9)
        G = res.shapes.T @ (M @ res.shapes)
        assert_allclose(G, np.eye(100), atol=1e-8)

    def test_random_structure_matches_dense_eigh(self):
        n = 900
        K, M = random_structure(n, seed=3)
        lam, phi = sla.eigh(K.toarray(), M.toarray())
        res = solve_modes(K, M, n_modes=70, modes_per_window=12)
        assert_allclose(res.omega ** 2, lam[:70], rtol=1e-8)
        # same shapes up to sign: mass-weighted MAC of matching columns is one
        mac = (phi[:, :70].T @ (M @ res.shapes)).diagonal() ** 2
        assert_allclose(mac, 1.0, atol=1e-6)

    def test_dense_path_for_small_problems(self):
        n = DENSE_LIMIT - 10
        K, M = fixed_free_chain(n)
        res = solve_modes(K, M, n_modes=n)
        assert res.stats['method'] == 'dense eigh'
        assert_allclose(res.frequencies, chain_frequencies(n), rtol=1e-9)

    def test_both_limits_give_at_most_n_modes_below_f_max(self):
        n = 1200
        K, M = fixed_free_chain(n)
        exact = chain_frequencies(n)
        f_max = 0.5 * (exact[59] + exact[60])
        few = solve_modes(K, M, n_modes=20, f_max=f_max)
        assert few.n_modes == 20 and few.sturm_count == 60
        many = solve_modes(K, M, n_modes=200, f_max=f_max, modes_per_window=25)
        assert many.n_modes == 60 and many.sturm_count == 60

    def test_progress_reports_growing_counts(self):
        K, M = fixed_free_chain(2000)
        calls = []
        solve_modes(K, M, n_modes=80, modes_per_window=20,
                    progress=lambda found, wanted, msg: calls.append((found, wanted, msg)))
        found = [c[0] for c in calls]
        assert len(calls) >= 3 and found == sorted(found) and found[-1] >= 80
        assert all(c[1] == 80 and 'Hz' in c[2] for c in calls)

    def test_shapes_at_reads_observed_dofs(self):
        K, M = fixed_free_chain(800)
        res = solve_modes(K, M, n_modes=10)
        T = sp.csr_matrix(([1.0, 1.0], ([0, 1], [799, 0])), shape=(2, 800))
        assert_allclose(res.shapes_at(T), res.shapes[[799, 0], :])
        with pytest.raises(ValueError, match='799'):
            res.shapes_at(np.ones((1, 799)))


class TestBadInput:
    @pytest.mark.parametrize(('kwargs', 'match'), [
        ({}, 'n_modes, f_max'),
        ({'n_modes': 0}, 'n_modes=0'),
        ({'n_modes': 10_000}, 'n_modes=10000'),
        ({'f_max': -5.0}, 'f_max=-5.0'),
    ])
    def test_rejected_requests_name_the_value(self, kwargs, match):
        K, M = fixed_free_chain(500)
        with pytest.raises(ValueError, match=match):
            solve_modes(K, M, **kwargs)

    def test_unknown_method_is_named(self):
        K, M = fixed_free_chain(500)
        with pytest.raises(ValueError, match="'lobpcg'"):
            solve_modes(K, M, n_modes=3, method='lobpcg')

    def test_size_mismatch(self):
        K, _ = fixed_free_chain(500)
        with pytest.raises(ValueError, match='equal size'):
            solve_modes(K, sp.identity(499), n_modes=3)

    def test_off_diagonal_pivot_is_refused(self):
        # a zero diagonal forces SuperLU off the diagonal: then it is no inertia
        A = sp.csc_matrix(np.array([[0.0, 1.0], [1.0, 0.0]]))
        with pytest.raises(ModalError, match='pivoted off the diagonal'):
            inertia_count(factorize_shifted(A, sp.identity(2, format='csc'), 0.0))
