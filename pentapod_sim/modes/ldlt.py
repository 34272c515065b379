"""
Symmetric indefinite LDL^T of ``K - sigma M`` with Intel MKL PARDISO, and its inertia.

SuperLU (scipy) orders by minimum degree and keeps L and U: on the plate frame's shell
meshes that is 4-5 times PARDISO's fill (METIS nested dissection, one triangle) and 5 times
its factorisation time (``bench/bench_frame.py``, row ``factorisation``). PARDISO (matrix
type -2, Bunch-Kaufman pivoting in supernodes) also reports the inertia of the factorisation
(numbers of positive and negative pivots), which is the Sturm count the spectrum slicing
needs. It comes with the ``pypardiso`` package (MKL's wheels; x86-64 only); where it is not
installed the solver stays with SuperLU (:func:`pentapod_sim.modes.sturm.factorize_shifted`).

The pencil ``K - sigma M`` has the same pattern at every shift, so PARDISO's analysis
(METIS ordering and symbolic factorisation, phase 11) is done once per pattern, process and
number of MKL threads (one made on 3 threads and factorised on 2 crashed the process):
a released factorisation leaves its handle, numerical factor freed and analysis kept, for the
next matrix of that pattern, which then needs only phase 22. At 763,350 DOF (the paper-scale
frame's interior) the analysis took 6.3 s and the numerical factorisation 9.3 s (measured
by hand, docs/modes.md, 'Factorisation'). pypardiso's ``factorize`` always runs both
phases; phase 22 alone goes through its ``set_phase`` and ``_call_pardiso`` (the one call that
is not its public interface). Otherwise ``set_iparm``, ``factorize``, ``solve``,
``get_iparm`` and ``free_memory`` are used. Parameters set (1-based iparm, as
MKL's documentation): 1 = 1 (own settings), 2 = 2 (METIS ordering), 8 = 0 (iterative
refinement only after perturbed pivots), 10 = 8 (pivot perturbation 1e-8), 11 = 13 = 0 (no
scaling or matching: the pencils here are well scaled), 18 = -1 (report the factors'
non-zeros), 21 = 1 (Bunch-Kaufman 1x1 and 2x2 pivots). A pivot PARDISO had to perturb
(iparm 14) is one within 1e-8 of zero: the shift sits on an eigenvalue, which the count may
then put on either side, as SuperLU's at such a shift; the spectrum slicing checks every
interval's count and moves such a shift (:mod:`pentapod_sim.modes.slicing`).

MKL's threads (``MKL_NUM_THREADS``, else ``OMP_NUM_THREADS``, which tools/env.sh sets to 1;
default: one per core) work in the factorisation and in the solves of blocks. At the
paper-scale frame's interior, on 2 cores of an idle machine, 2 threads against 1: numerical
factorisation 5.3 against 8.7 s, a solve of 16 vectors 0.77 against 0.96 s. The frame
reduction sets its own (:func:`pentapod_sim.modes.frame_reduction.frame_threads`).
"""
from __future__ import annotations

import functools
import hashlib
import os
from typing import Any

import numpy as np
import numpy.typing as npt
import scipy.sparse as sp

Array = npt.NDArray[np.float64]
_SETTINGS = {1: 1, 2: 2, 8: 0, 10: 8, 11: 0, 13: 0, 18: -1, 21: 1}

#: The analysed handle left by the last released factorisation: (pattern key, handle). One
#: only, of this process (a forked process gets a copy of it, which the key's pid excludes).
_spare: tuple[tuple[Any, ...], Any] | None = None


@functools.lru_cache(maxsize=1)
def _mkl() -> Any:
    """MKL's runtime library, as pypardiso loads it."""
    import pypardiso
    return pypardiso.PyPardisoSolver(mtype=-2).libmkl


def _pattern_key(upper: sp.csr_matrix) -> tuple[Any, ...]:
    """
    What identifies a sparsity pattern, and the process and MKL thread count that analysed it.

    An analysis made with another number of MKL threads crashed the numerical factorisation
    (SIGSEGV or a hang; the frame reduction sets its own threads: test_shell_frame.py,
    test_a_reduction_on_other_threads_than_a_kept_analysis_ends).
    """
    return (os.getpid(), int(_mkl().MKL_Get_Max_Threads()), upper.shape,
            hashlib.sha1(upper.indptr).hexdigest(), hashlib.sha1(upper.indices).hexdigest())


def _take_spare(key: tuple[Any, ...]) -> Any:
    """The spare handle if it was analysed for ``key``, else None (a stale one is freed)."""
    global _spare
    spare, _spare = _spare, None
    if spare is None:
        return None
    if spare[0] == key:
        return spare[1]
    spare[1].free_memory(everything=True)
    return None


def available() -> bool:
    """True if MKL PARDISO can be loaded (``pypardiso`` and MKL's runtime installed)."""
    try:
        import pypardiso
        pypardiso.PyPardisoSolver(mtype=-2)
    except (ImportError, OSError):
        return False
    return True


class PardisoLDLT:
    """
    ``A = P L D L^T P^T`` of a symmetric matrix, kept for repeated solves.

    Parameters
    ----------
    A : (n, n) sparse matrix
        Symmetric (only its upper triangle is read).

    Attributes
    ----------
    n_negative, n_positive : int
        Negative and positive pivots of D (the inertia; a zero pivot counts in neither).
    perturbed : int
        Pivots PARDISO perturbed (> 0: the shift is on an eigenvalue to about 1e-8).
    factor_nnz : int
        Non-zeros of the factor L (the fill).
    """

    def __init__(self, A: sp.spmatrix) -> None:
        import pypardiso  # optional: MKL's wheels (requirements.txt, x86-64 only)
        self._upper = sp.triu(A, format='csr').astype(np.float64)
        self._upper.sort_indices()
        self.shape = self._upper.shape
        self._key = _pattern_key(self._upper)
        self._solver = _take_spare(self._key)
        #: the analysis (ordering, symbolic factorisation) was reused from an earlier matrix
        self.reused_analysis = self._solver is not None
        if self._solver is None:
            self._solver = pypardiso.PyPardisoSolver(mtype=-2)
            for index, value in _SETTINGS.items():
                self._solver.set_iparm(index, value)
            # pypardiso keeps a copy of the matrix to recognise it in solve(); ours never
            # changes
            self._solver.factorize(self._upper)
        else:                                   # numerical factorisation only
            self._solver.set_phase(22)
            self._solver._call_pardiso(self._upper, np.zeros((self.shape[0], 1)))
            self._solver.factorized_A = self._upper   # solve() compares against it
        self.n_positive = int(self._solver.get_iparm(22))
        self.n_negative = int(self._solver.get_iparm(23))
        self.perturbed = int(self._solver.get_iparm(14))
        self.factor_nnz = int(self._solver.get_iparm(18))

    def solve(self, b: npt.ArrayLike) -> Array:
        """``A^-1 b`` for a vector (n,) or a block of vectors (n, k)."""
        if self._solver is None:
            raise RuntimeError('this factorisation was freed')
        rhs = np.asarray(b, dtype=np.float64)
        if rhs.ndim == 2:
            # pypardiso passes the block column by column (Fortran order)
            return np.asarray(self._solver.solve(self._upper, np.asfortranarray(rhs)))
        return np.asarray(self._solver.solve(self._upper, rhs))

    def negative_pivots(self) -> int:
        """Number of negative pivots (Sylvester: eigenvalues of the pencil below the shift)."""
        return self.n_negative

    def free(self) -> None:
        """Release MKL's memory of this factorisation; its analysis stays for the next one."""
        global _spare
        solver, self._solver = getattr(self, '_solver', None), None
        if solver is None:
            return                              # freed already
        solver.free_memory(everything=False)    # the numerical factor; the analysis stays
        if _spare is not None:
            _spare[1].free_memory(everything=True)
        _spare = (self._key, solver)

    def __del__(self) -> None:
        try:
            self.free()
        except Exception:           # interpreter shutting down: MKL may be gone already
            pass
