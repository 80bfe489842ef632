"""The arrays of the fused numba kernels (:mod:`sshade.arap.kernels`) in one vertex
numbering: the mesh's, or a cache-friendly one (:func:`rcm_order`, reverse Cuthill-McKee of
the Laplacian's pattern), in which the kernels' gathers from neighbouring vertices and
cells hit the cache.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import reverse_cuthill_mckee

from ..errors import SShaDeError

__all__ = ["KernelData", "rcm_order", "permute_csr", "as_u32", "REORDER_MIN_VERTICES"]

#: vertices from which the solvers renumber the mesh for locality by default
#: (:func:`rcm_order`; below, everything fits in the L2 cache).
REORDER_MIN_VERTICES = 20_000


def rcm_order(L) -> np.ndarray:
    """A cache-friendly vertex numbering: reverse Cuthill-McKee of the pattern of ``L``.

    Parameters
    ----------
    L : (n, n) scipy.sparse matrix with a symmetric pattern (the cotangent Laplacian).

    Returns
    -------
    perm : (n,) int64, ``perm[new] = old``.
    """
    return np.asarray(reverse_cuthill_mckee(sp.csr_matrix(L), symmetric_mode=True), np.int64)


def permute_csr(ptr, idx, val, perm, inv):
    """Rows of a CSR taken in the order ``perm`` (row ``i`` of the result is row
    ``perm[i]``), column indices mapped by ``inv``; the entries of a row keep their order
    (so a row's sum is rounded as before).

    Parameters
    ----------
    ptr : (r + 1,) int row pointers; idx : (nnz,) int column indices or None; val :
    (nnz, ...) values or None. perm : (r,) int64, ``perm[new] = old``; inv : (c,) int64
    or None, new column numbers (None: kept).

    Returns
    -------
    ``(ptr (r + 1,) int64, idx (nnz,) or None, val (nnz, ...) or None, src (nnz,) int64)``,
    ``src`` the old position of every entry.
    """
    lens = np.diff(ptr)[perm]
    nptr = np.zeros(len(perm) + 1, np.int64)
    np.cumsum(lens, out=nptr[1:])
    src = np.repeat(ptr[:-1][perm] - nptr[:-1], lens) + np.arange(nptr[-1], dtype=np.int64)
    nidx = None if idx is None else (idx[src] if inv is None else inv[idx[src]])
    return nptr, nidx, None if val is None else np.ascontiguousarray(val[src]), src


@dataclass(eq=False)
class KernelData:
    """The arrays of the fused numba kernels, in one vertex numbering.

    Attributes
    ----------
    perm : (n,) int64 or None, ``perm[new] = old`` (None: the mesh's numbering); ``inv``
        its inverse (``inv[old] = new``). Cells are numbered as vertices.
    kt : ``(ptr (n + 1,) uint64, idx (nnz,) uint32, val (nnz, 3) float64)``, the three
        blocks of ``K^T`` as one CSR with 3-vector values: the covariance of cell ``k`` is
        ``M_k[c, d] = sum_jj val[jj, d] U[idx[jj], c]`` (``scipy``'s ``KT @ U``, same
        entries in the same order).
    kv : same for ``K``: ``K(R)[v] = sum_d sum_jj val[jj, d] R[idx[jj], :, d]``.
    edges, edge_vec, cell_ptr, pair_edge, pair_w : the operators' arrays renumbered
        (edges sorted by their smaller new end point; every edge keeps its orientation and
        every cell the order of its pairs, so the cell energies are summed term by term in
        the same order in every numbering).
    edge_w : (ne,) float64, the operators' edge weights in this numbering's edge order;
        ``einv`` (ne,) int64 or None maps the mesh's edges to it (``x[einv]``: an edge
        array of this numbering in the mesh's edge order; None: the same order).

    Index arrays (``idx``, ``edges``, ``pair_edge``) are uint32 and pointer arrays
    (``ptr``, ``cell_ptr``) uint64: unsigned indices spare numba's negative-index
    wraparound (a quarter of the energy kernel's time).
    """

    perm: np.ndarray | None
    inv: np.ndarray | None
    kt: tuple
    kv: tuple
    edges: np.ndarray
    edge_vec: np.ndarray
    cell_ptr: np.ndarray
    pair_edge: np.ndarray
    pair_w: np.ndarray
    edge_w: np.ndarray
    einv: np.ndarray | None

    @classmethod
    def build(cls, ops, perm: np.ndarray | None = None) -> KernelData:
        """From ``ops`` (:class:`sshade.arap.operators.ArapOperators`) in the numbering
        ``perm`` (``perm[new] = old``; None: identity)."""
        n = ops.n
        kt, kv = ops.kt, ops.kv
        if perm is None:
            return cls(None, None, _u32csr(kt), _u32csr(kv), as_u32(ops.edges), ops.edge_vec,
                       np.ascontiguousarray(ops.cell_ptr, np.uint64), as_u32(ops.pair_edge), ops.pair_w,
                       np.ascontiguousarray(ops.edge_w, np.float64), None)
        perm = np.ascontiguousarray(perm, np.int64)
        inv = np.empty(n, np.int64)
        inv[perm] = np.arange(n, dtype=np.int64)
        ptr, idx, val, src = permute_csr(*kt, perm, inv)
        kt, kv = (ptr, idx, val), (ptr, idx, np.ascontiguousarray(kv[2][src]))  # kv: kt's pattern
        es, ed = inv[ops.edges[:, 0]], inv[ops.edges[:, 1]]
        eperm = np.argsort(np.minimum(es, ed) * n + np.maximum(es, ed), kind="stable")
        einv = np.empty(len(eperm), np.int64)
        einv[eperm] = np.arange(len(eperm), dtype=np.int64)
        edges = np.ascontiguousarray(np.stack([es, ed], 1)[eperm])
        cell_ptr, pair_edge, _, src = permute_csr(ops.cell_ptr, ops.pair_edge, None, perm, einv)
        return cls(perm, inv, _u32csr(kt), _u32csr(kv), as_u32(edges), np.ascontiguousarray(ops.edge_vec[eperm]),
                   np.ascontiguousarray(cell_ptr, np.uint64), as_u32(pair_edge), np.ascontiguousarray(ops.pair_w[src]),
                   np.ascontiguousarray(ops.edge_w[eperm], np.float64), einv)

    def local_arrays(self) -> tuple:
        """Arguments of the local kernel after ``U``."""
        return (*self.kt, self.edges, self.edge_vec, self.cell_ptr, self.pair_edge, self.pair_w)


def as_u32(a) -> np.ndarray:
    """C-contiguous uint32 copy of a non-negative index array (< 2^32)."""
    a = np.asarray(a)
    if a.size and (a.min() < 0 or a.max() >= 2 ** 32):
        raise SShaDeError("index out of the uint32 range")
    return np.ascontiguousarray(a, np.uint32)


def _u32csr(c) -> tuple:
    """``(ptr uint64, idx uint32, val)``."""
    return np.ascontiguousarray(c[0], np.uint64), as_u32(c[1]), np.ascontiguousarray(c[2], np.float64)
