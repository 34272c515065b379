"""Sparse products in row blocks on threads (pentapod_sim.modes.row_split) against scipy's."""
import threading

import numpy as np
import pytest
import scipy.sparse as sp

from pentapod_sim.modes import row_split


def _matrix(n=300, seed=1):
    A = sp.random(n, n, density=0.03, random_state=seed, format='csr')
    A = (A + A.T).tolil()
    A[10:40, :] = 0.0               # empty rows: a block may hold none
    A[:, 10:40] = 0.0
    return A.tocsr()


@pytest.mark.parametrize('parts', [1, 2, 3, 7])
@pytest.mark.parametrize('columns', [None, 1, 16])
def test_a_split_product_is_scipys_to_the_bit(parts, columns):
    A = _matrix()
    rng = np.random.default_rng(parts)
    X = rng.standard_normal(300 if columns is None else (300, columns))
    split = row_split.RowSplit(A, parts)
    assert split.bounds[0] == 0 and split.bounds[-1] == 300
    assert 1 <= len(split.blocks) <= parts
    assert np.array_equal(split @ X, A @ X)
    assert np.array_equal(split @ np.asfortranarray(X), A @ X)


def test_more_parts_than_rows_with_entries():
    A = sp.csr_matrix(np.diag([0.0, 2.0, 0.0, 3.0]))
    X = np.arange(8.0).reshape(4, 2)
    assert np.array_equal(row_split.RowSplit(A, 6) @ X, A @ X)


def test_the_blocks_run_in_threads_at_the_same_time(monkeypatch):
    """Every block's product starts before any ends: they run side by side, not in turn."""
    A = _matrix()
    split = row_split.RowSplit(A, 3)
    started, barrier = [], threading.Barrier(3, timeout=10)

    class Block:
        def __init__(self, block):
            self.block = block

        def __matmul__(self, X):
            started.append(threading.get_ident())
            barrier.wait()           # raises BrokenBarrierError if the blocks ran in turn
            return self.block @ X

    split.blocks = [Block(b) for b in split.blocks]
    X = np.ones((300, 4))
    assert np.array_equal(split @ X, A @ X)
    assert len(set(started)) == 3


def test_the_setting_is_one_thread_unless_set_and_comes_back():
    A = _matrix()
    assert row_split.split(A) is A
    with row_split.threads(3):
        assert isinstance(row_split.split(A), row_split.RowSplit)
        assert len(row_split.split(A).blocks) == 3
        with pytest.raises(RuntimeError):
            with row_split.threads(2):
                raise RuntimeError
        assert len(row_split.split(A).blocks) == 3
    assert row_split.split(A) is A
    with pytest.raises(ValueError, match='threads=0'):
        with row_split.threads(0):
            pass
