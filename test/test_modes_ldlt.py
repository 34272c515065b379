"""MKL PARDISO's LDL^T as the modal solver's factorisation: inertia, solves, slicing."""
import numpy as np
from numpy.testing import assert_allclose
import pytest
import scipy.linalg as sla
import scipy.sparse as sp
from test_modes_solver import chain_frequencies, fixed_free_chain, random_structure

from pentapod_sim.errors import ModalError
from pentapod_sim.modes import sturm
from pentapod_sim.modes.ldlt import PardisoLDLT
from pentapod_sim.modes.solver import solve_modes
from pentapod_sim.modes.sturm import choose_backend, factor_at, sturm_count


def test_inertia_matches_dense_eigh_at_many_shifts():
    K, M = random_structure(300, seed=3)
    lam = sla.eigh(K.toarray(), M.toarray(), eigvals_only=True)
    for i in (0, 3, 40, 151, 298):
        shift = 0.5 * (lam[i] + lam[i + 1])
        assert sturm_count(K, M, shift, 'pardiso') == i + 1 == sturm_count(K, M, shift,
                                                                              'superlu')
    assert sturm_count(K, M, -1.0, 'pardiso') == 0
    assert sturm_count(K, M, 2 * lam[-1], 'pardiso') == 300


def test_solves_vectors_and_blocks_of_the_indefinite_matrix():
    K, M = random_structure(400, seed=5)
    lam = sla.eigh(K.toarray(), M.toarray(), eigvals_only=True)
    shift = 0.5 * (lam[57] + lam[58])
    factor = factor_at(K, M, shift, 'pardiso')
    assert isinstance(factor.lu, PardisoLDLT) and factor.count == 58
    # the factor L holds at least the pattern of the matrix's lower triangle
    assert factor.lu.factor_nnz >= sp.tril(K - shift * M).nnz
    A = (K - shift * M).toarray()
    rng = np.random.default_rng(0)
    for b in (rng.standard_normal(400), rng.standard_normal((400, 7))):
        x = factor.lu.solve(b)
        assert x.shape == b.shape
        assert_allclose(A @ x, b, rtol=0, atol=1e-9 * np.abs(b).max())


def test_slicing_on_pardiso_gives_the_closed_form_chain_with_its_count():
    n = 3000
    K, M = fixed_free_chain(n)
    exact = chain_frequencies(n)
    f_max = 0.5 * (exact[99] + exact[100])
    res = solve_modes(K, M, f_max=f_max, modes_per_window=25, factorisation='pardiso')
    assert res.stats['factorisation'] == 'pardiso'
    assert res.sturm_count == res.n_modes == 100
    assert_allclose(res.frequencies, exact[:100], rtol=1e-9)


def test_auto_takes_pardiso_for_large_problems_only():
    assert choose_backend(sturm.PARDISO_MIN_DOF - 1) == 'superlu'
    assert choose_backend(sturm.PARDISO_MIN_DOF) == 'pardiso'
    assert choose_backend(10 ** 6, 'superlu') == 'superlu'
    with pytest.raises(ValueError, match="'lapack' is not one of"):
        choose_backend(10, 'lapack')


def test_pardiso_asked_for_where_missing_is_named(monkeypatch):
    monkeypatch.setattr(sturm, '_pardiso_available', lambda: False)
    assert choose_backend(10 ** 6) == 'superlu'
    with pytest.raises(ModalError, match='pip install pypardiso'):
        choose_backend(10, 'pardiso')
