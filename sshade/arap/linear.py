"""The global step's linear solver: ONE sparse factorisation of the free-free block of the
cotangent Laplacian, reused by every iteration and solved for the 3 coordinate columns at
once (:class:`LaplacianSolver`).

Back ends (:data:`LINEAR_SOLVERS`): cholespy (CHOLMOD; the default, its solve, paid every
iteration, was the fastest of those measured), scipy's ``splu`` with COLAMD ordering (the
fallback when cholespy cannot be imported) and libigl's ``min_quad_with_fixed`` (Eigen's
sparse LLT).
"""
from __future__ import annotations

import time

import igl
import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu

from ..errors import SShaDeError

try:  # optional at run time: scipy's splu is the fallback
    from cholespy import CholeskySolverD, MatrixType
except ImportError:  # pragma: no cover
    CholeskySolverD = MatrixType = None

__all__ = ["LINEAR_SOLVERS", "LaplacianSolver"]

LINEAR_SOLVERS = ("auto", "cholespy", "scipy", "igl")


class LaplacianSolver:
    """One sparse factorisation of ``A = L[free][:, free]`` (SPD), reused for every solve.

    Parameters
    ----------
    A : (n_f, n_f) scipy.sparse matrix, symmetric positive definite.
    backend : ``"auto"`` (cholespy, else scipy), ``"cholespy"`` (CHOLMOD via the cholespy
        wheel), ``"scipy"`` (``scipy.sparse.linalg.splu`` with COLAMD ordering) or
        ``"igl"`` (libigl's ``min_quad_with_fixed``, Eigen's sparse LLT).

    Attributes
    ----------
    backend : str, the backend in use. factor_s : float, seconds spent factorising.

    Raises
    ------
    SShaDeError on an unknown backend, ``"cholespy"`` requested but not importable, or a
    matrix that is not positive definite (e.g. a connected component without a handle).
    """

    def __init__(self, A, backend: str = "auto"):
        if backend not in LINEAR_SOLVERS:
            raise SShaDeError(f"unknown linear solver {backend!r}; use one of {LINEAR_SOLVERS}")
        A = sp.csc_matrix(A)
        A.sort_indices()
        self.n = A.shape[0]
        t0 = time.perf_counter()
        if backend in ("auto", "cholespy"):
            if CholeskySolverD is None:
                if backend == "cholespy":
                    raise SShaDeError("linear solver 'cholespy' requested but the cholespy package is not installed")
                backend = "scipy"
            else:
                backend = "cholespy"
                self._f = self._cholespy(A)
        if backend == "scipy":
            try:
                self._f = splu(A, permc_spec="COLAMD")
            except RuntimeError as e:
                raise SShaDeError(f"the free-vertex Laplacian is singular ({e}); "
                                  "is there a connected component without a handle?") from e
        elif backend == "igl":
            self._f = igl.min_quad_with_fixed_data()
            igl.min_quad_with_fixed_precompute(A, np.zeros(0, np.int64), sp.csc_matrix((0, self.n)), True, self._f)
        self.backend = backend
        self.factor_s = time.perf_counter() - t0

    def _cholespy(self, A):
        """CHOLMOD's factor of the CSC matrix ``A`` (cholespy)."""
        try:
            return CholeskySolverD(self.n, A.indptr.astype(np.int32), A.indices.astype(np.int32),
                                   np.ascontiguousarray(A.data, np.float64), MatrixType.CSC)
        except ValueError as e:
            raise SShaDeError(f"the free-vertex Laplacian is not positive definite ({e}); "
                              "is there a connected component without a handle?") from e

    def solve(self, B: np.ndarray) -> np.ndarray:
        """Solve ``A X = B``.

        Parameters
        ----------
        B : (n_f, k) float64.

        Returns
        -------
        X : (n_f, k) float64.
        """
        B = np.ascontiguousarray(B, np.float64)
        if self.backend == "cholespy":
            X = np.empty_like(B)
            self._f.solve(B, X)
            return X
        if self.backend == "scipy":
            return self._f.solve(B)
        return igl.min_quad_with_fixed_solve(self._f, -B, np.zeros((0, B.shape[1])), np.zeros((0, B.shape[1])))
