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


def _pattern(seed: int):
    """A structure of its own pattern (no other test analyses it) and its exact eigenvalues."""
    K, M = random_structure(350, seed=seed)
    return K, M, sla.eigh(K.toarray(), M.toarray(), eigvals_only=True)


def test_a_second_shift_of_the_same_pattern_reuses_the_analysis_and_is_exact():
    K, M, lam = _pattern(seed=101)
    first = factor_at(K, M, 0.5 * (lam[20] + lam[21]), 'pardiso')
    assert first.count == 21 and not first.lu.reused_analysis
    first.lu.free()
    with pytest.raises(RuntimeError, match='freed'):
        first.lu.solve(np.ones(350))
    for i in (200, 7):                  # numerical factorisations only, at other shifts
        shift = 0.5 * (lam[i] + lam[i + 1])
        factor = factor_at(K, M, shift, 'pardiso')
        assert factor.lu.reused_analysis
        assert factor.count == i + 1
        b = np.random.default_rng(i).standard_normal((350, 3))
        assert_allclose((K - shift * M) @ factor.lu.solve(b), b, rtol=0, atol=1e-9)
        del factor                       # released: its analysis serves the next one
    other, _, _ = _pattern(seed=102)     # another pattern is analysed afresh
    assert not factor_at(other, M, 1.0, 'pardiso').lu.reused_analysis


def _count_in_fork(K, M, shift, queue):
    factor = factor_at(K, M, shift, 'pardiso')
    queue.put((factor.lu.reused_analysis, factor.count))


def test_a_forked_process_does_not_take_its_parents_analysis():
    import multiprocessing
    K, M, lam = _pattern(seed=103)
    factor_at(K, M, 0.5 * (lam[5] + lam[6]), 'pardiso').lu.free()   # leaves a spare here
    ctx = multiprocessing.get_context('fork')
    queue = ctx.Queue()
    child = ctx.Process(target=_count_in_fork, args=(K, M, 0.5 * (lam[50] + lam[51]), queue))
    child.start()
    reused, count = queue.get(timeout=60)
    child.join(timeout=60)
    assert (reused, count) == (False, 51)
    assert factor_at(K, M, 0.5 * (lam[9] + lam[10]), 'pardiso').lu.reused_analysis


def test_serial_slicing_factorises_every_later_shift_with_the_first_analysis(monkeypatch):
    from pentapod_sim.modes import ldlt
    made = []

    class Recorded(ldlt.PardisoLDLT):
        def __init__(self, A):
            super().__init__(A)
            made.append(self.reused_analysis)

    monkeypatch.setattr(ldlt, 'PardisoLDLT', Recorded)
    n = 2500
    K, M = fixed_free_chain(n)
    exact = chain_frequencies(n)
    f_max = 0.5 * (exact[119] + exact[120])
    res = solve_modes(K, M, f_max=f_max, modes_per_window=25, factorisation='pardiso',
                      workers=1, method='block')
    assert res.sturm_count == res.n_modes == 120
    assert_allclose(res.frequencies, exact[:120], rtol=1e-9)
    assert len(made) >= 5 and made[1:] == [True] * (len(made) - 1)
