"""Block shift-invert Lanczos windows (method 'block'): closed forms, dense eigh, its limits."""
import numpy as np
from numpy.testing import assert_allclose
import pytest
import scipy.linalg as sla
import scipy.sparse as sp
from test_modes_solver import chain_frequencies, fixed_free_chain

from pentapod_sim.errors import ModalError
from pentapod_sim.modes.sturm import factor_at, ShiftedFactor
from pentapod_sim.modes.windows import block_lanczos, mass_normalise, window_eigs


def _nearest(values: np.ndarray, sigma: float, k: int) -> np.ndarray:
    return np.sort(values[np.argsort(np.abs(values - sigma))[:k]])


def test_chain_window_matches_closed_form():
    """A window inside the spectrum of the fixed-free chain: the k eigenvalues nearest sigma."""
    n, k = 2000, 40
    K, M = fixed_free_chain(n)
    lam_exact = (2 * np.pi * chain_frequencies(n)) ** 2
    sigma = 0.5 * (lam_exact[300] + lam_exact[301])
    factor = factor_at(K, M, sigma)
    lam, phi = window_eigs(K, M, factor, k, 'block', 1e-8)
    assert_allclose(lam, _nearest(lam_exact, sigma, k), rtol=1e-10)
    assert mass_normalise(K, M, lam, phi).max() < 1e-8
    assert_allclose(phi.T @ (M @ phi), np.eye(k), atol=1e-10)
    # a basis of k + 4 blocks: it must restart (thick restart) and still get there
    log = []
    lam, phi = block_lanczos(K, M, factor, k, 1e-8, lambda: log.append(1), block=8,
                             max_dim=k + 32)
    assert len(log) > (k + 32) // 8 + 1                   # more solves than one basis holds
    assert_allclose(np.sort(lam), _nearest(lam_exact, sigma, k), rtol=1e-10)
    assert mass_normalise(K, M, lam, phi).max() < 1e-8


def _pencil_with_repeated_pair(n: int = 300, seed: int = 1):
    """Dense K, M (as sparse) whose eigenvalues are set: 1..n, with 150 twice and 151.0001."""
    rng = np.random.default_rng(seed)
    lam = np.arange(1.0, n + 1.0) * 1e4
    lam[150] = lam[149]                     # an exactly repeated eigenvalue
    lam[151] = lam[149] * (1 + 1e-6)        # and a close third
    U, _ = np.linalg.qr(rng.standard_normal((n, n)))
    m = rng.uniform(1.0, 3.0, n)
    root = np.sqrt(m)
    K = (root[:, None] * (U * lam) @ U.T) * root[None, :]   # M^1/2 U diag(lam) U^T M^1/2
    return sp.csr_matrix(0.5 * (K + K.T)), sp.diags(m, format='csr'), lam


def test_dense_pencil_with_repeated_pair_matches_eigh():
    """Both vectors of a repeated eigenvalue are found, with the same eigenspace as eigh's."""
    K, M, lam_set = _pencil_with_repeated_pair()
    lam_ref, phi_ref = sla.eigh(K.toarray(), M.toarray())
    assert_allclose(lam_ref, np.sort(lam_set), rtol=1e-9)      # the pencil is what it says
    sigma, k = lam_set[149] * 1.00005, 20
    lam, phi = block_lanczos(K, M, factor_at(K, M, sigma, 'superlu'), k, 1e-8, None, block=4)
    order = np.argsort(lam)
    lam, phi = lam[order], phi[:, order]
    assert_allclose(lam, _nearest(lam_ref, sigma, k), rtol=1e-10)
    assert np.count_nonzero(np.abs(lam / lam_set[149] - 1) < 1e-9) == 2
    mass_normalise(K, M, lam, phi)
    pair = np.flatnonzero(np.abs(lam / lam_set[149] - 1) < 1e-9)
    ref = np.flatnonzero(np.abs(lam_ref / lam_set[149] - 1) < 1e-9)
    # the same plane: the M-projections of eigh's pair on ours have singular values 1
    overlap = np.linalg.svd(phi_ref[:, ref].T @ (M @ phi[:, pair]), compute_uv=False)
    assert_allclose(overlap, 1.0, atol=1e-8)


def test_too_small_a_space_names_the_window():
    K, M = fixed_free_chain(2000)
    lam_exact = (2 * np.pi * chain_frequencies(2000)) ** 2
    sigma = 0.5 * (lam_exact[300] + lam_exact[301])
    factor = factor_at(K, M, sigma)
    with pytest.raises(ModalError, match=f'around {sigma:.6g} rad'):
        block_lanczos(K, M, factor, 40, 1e-8, None, block=8, max_dim=64, restarts=0)


class _CountingLU:
    """A factorisation that counts its solves (right-hand sides) and calls."""

    def __init__(self, lu):
        self.lu, self.calls, self.vectors = lu, 0, 0

    def solve(self, rhs):
        self.calls += 1
        self.vectors += rhs.shape[1] if rhs.ndim == 2 else 1
        return self.lu.solve(rhs)


def test_checkpoint_before_every_block_solve_and_its_exception_ends_the_window():
    K, M = fixed_free_chain(2000)
    lam_exact = (2 * np.pi * chain_frequencies(2000)) ** 2
    base = factor_at(K, M, 0.5 * (lam_exact[300] + lam_exact[301]))
    lu = _CountingLU(base.lu)
    factor = ShiftedFactor(base.sigma, lu, base.count, base.seconds)
    checks = []
    block_lanczos(K, M, factor, 40, 1e-8, lambda: checks.append(lu.calls), block=8)
    assert lu.calls > 3 and lu.vectors == 8 * lu.calls      # blocks of 8 in one call each
    assert checks == list(range(lu.calls))                 # one check before each solve

    class Stop(Exception):
        pass

    def stop_at_third():
        if lu.calls == 2:
            raise Stop
    lu.calls = 0
    with pytest.raises(Stop):
        block_lanczos(K, M, factor, 40, 1e-8, stop_at_third, block=8)
    assert lu.calls == 2                                    # no solve after the stop
