"""
Sparse matrix times dense block on several threads: the matrix split into blocks of rows.

scipy's CSR product runs on one core, with the GIL released, so blocks of rows multiplied in
threads at the same time use the others. Each row's sum is the one scipy computes without
the split, so the product is the same to the bit. At the paper-scale frame's interior (763k
DOF, 39 M non-zeros) ``K @ X`` with 128 columns took 2.16 s on one thread and 1.21 s in two
halves on two (idle machine, docs/modes.md 'Paper scale'). Neither scipy nor numpy threads
sparse products, and MKL's sparse BLAS has no binding among the dependencies, hence this.

The number of threads is a setting of the process (:func:`threads`, 1 unless a caller such
as the frame reduction sets more), so the eigensolvers' sparse products follow the caller's
choice without a parameter through every layer; with one thread :func:`split` returns the
matrix itself.
"""
from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
import contextlib
from typing import Iterator

import numpy as np
import numpy.typing as npt
import scipy.sparse as sp

Array = npt.NDArray[np.float64]

_threads = 1


@contextlib.contextmanager
def threads(n: int) -> Iterator[None]:
    """Sparse products of :func:`split` matrices on ``n`` threads within the block."""
    global _threads
    if n < 1:
        raise ValueError(f'threads={n} must be at least 1')
    before, _threads = _threads, n
    try:
        yield
    finally:
        _threads = before


class RowSplit:
    """A CSR matrix in row blocks of about equal non-zeros; ``@`` multiplies them in threads."""

    def __init__(self, A: sp.spmatrix, parts: int) -> None:
        A = sp.csr_matrix(A)
        self.shape = A.shape
        ends = np.searchsorted(A.indptr, np.linspace(0, A.nnz, parts + 1)[1:-1])
        inner = sorted({int(e) for e in ends if 0 < e < A.shape[0]})
        self.bounds = [0, *inner, A.shape[0]]
        self.blocks = [A[lo:hi] for lo, hi in zip(self.bounds[:-1], self.bounds[1:])]

    def __matmul__(self, X: Array) -> Array:
        X = np.asarray(X)
        out = np.empty((self.shape[0], *X.shape[1:]), dtype=np.result_type(X, np.float64))

        def part(i: int) -> None:
            out[self.bounds[i]:self.bounds[i + 1]] = self.blocks[i] @ X

        with ThreadPoolExecutor(len(self.blocks)) as pool:
            list(pool.map(part, range(len(self.blocks))))
        return out


def split(A: sp.spmatrix) -> sp.spmatrix | RowSplit:
    """``A`` for products on the threads set by :func:`threads` (``A`` itself on one)."""
    return A if _threads == 1 else RowSplit(A, _threads)
