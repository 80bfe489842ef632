"""ARAP-SR's per-iteration products in one numbering: the local step as one numba call
(:func:`sshade.arap.kernels.sr_local_kernel`: every cell's covariance, then the
neighbours' rotations and the polar decompositions batch by batch, then every cell's
energy), the right-hand side ``K(R)`` and the smoothness sum, on rotations kept in the
reverse Cuthill-McKee numbering
of large meshes (:func:`sshade.arap.kernel_data.rcm_order`), where the kernels' gathers hit
the cache; the mesh's numbering below :data:`sshade.arap.kernel_data.REORDER_MIN_VERTICES`.
Every sum keeps the mesh's order, so each number is the one the scipy formulas give in the
mesh's numbering, bit for bit, and a sweep gives the rotations of the scipy path (the
colour classes in turn, :func:`gs_order`). Used by :mod:`sshade.arap.smooth_rotations`;
measurements: docs/implementation.md.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from .kernel_data import KernelData, as_u32, permute_csr, rcm_order
from .kernels import sr_local_kernel
from .threads import numba_threads, resolve_threads

__all__ = ["SRLocal", "edge_sq_sum", "gs_order"]


@njit(cache=True, nogil=True)
def edge_sq_sum(Rf, s, d, we, order, buf):  # pragma: no cover - compiled
    """``sum_e we_e ||Rf[s_e] - Rf[d_e]||^2`` for (n, 9) float64 ``Rf``, (ne,) int64 ``s``
    and ``d``, (ne,) float64 ``we``: the terms computed in the edges' order into ``buf``
    (ne,) float64, then summed one by one in the order ``order`` (ne,) int64 (``arange``:
    the edges' own), so the same float in every numbering of the same edges."""
    for e in range(len(s)):
        a, b = s[e], d[e]
        sq = 0.0
        for k in range(9):
            x = Rf[a, k] - Rf[b, k]
            sq += x * x
        buf[e] = we[e] * sq
    tot = 0.0
    for e in range(len(order)):
        tot += buf[order[e]]
    return tot


def gs_order(classes: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """The Gauss-Seidel order of the cells: the colour classes in turn.

    Parameters
    ----------
    classes : list of (k_c,) int64 arrays partitioning ``arange(n)``, each an independent
        set.

    Returns
    -------
    ``(cells (n,) int64, bptr (len(classes) + 1,) int64)``: batch ``b`` is class ``b``,
    ``cells[bptr[b]:bptr[b + 1]]``.
    """
    cells = np.concatenate(classes).astype(np.int64) if classes else np.zeros(0, np.int64)
    bptr = np.r_[0, np.cumsum([len(c) for c in classes])].astype(np.int64)
    return cells, bptr


class SRLocal:
    """ARAP-SR's local step, right-hand side and smoothness on rotations in the kernel's
    numbering (module docstring), for one :class:`sshade.arap.operators.ArapOperators`.

    Parameters
    ----------
    ops : ArapOperators (spokes). adj : (n, n) scipy.sparse.csr_matrix, sorted indices,
    the smoothness weights ``a_ij`` of both directions. classes : list of (k_c,) int64
    colour classes (mesh numbering). edge_w : (ne,) float64 ``a_e`` of ``ops.edges``.
    wR : float >= 0, the weight of the neighbours' rotations. reorder : bool.
    """

    def __init__(self, ops, adj, classes: list[np.ndarray], edge_w: np.ndarray, wR: float, reorder: bool):
        self.ops, self.n, self.wR = ops, ops.n, float(wR)
        n = self.n
        perm = rcm_order(ops.L) if reorder else np.arange(n, dtype=np.int64)  # perm[new] = old
        self.kd = kd = KernelData.build(ops, perm)
        self.perm, self.inv = kd.perm, kd.inv
        ptr, idx, val = permute_csr(adj.indptr.astype(np.int64), adj.indices.astype(np.int64), adj.data, kd.perm,
                                    kd.inv)[:3]
        self.graph = (ptr if self.wR > 0 else np.zeros(n + 1, np.int64), idx, val)
        self.edge_w = np.empty_like(edge_w)
        self.edge_w[kd.einv] = edge_w  # the kernel's edge order
        self.s, self.d = np.asarray(kd.edges[:, 0], np.int64), np.asarray(kd.edges[:, 1], np.int64)
        every = np.arange(n, dtype=np.int64)
        self.jacobi_order = (every, np.array([0, n], np.int64))
        self.gs = gs_order([np.sort(kd.inv[c]) for c in classes])
        self.rows = as_u32(every)
        self.threads = resolve_threads(None, n)

    def to_kernel(self, R: np.ndarray) -> np.ndarray:
        """(n, 3, 3) rotations of the mesh's numbering as a new C-contiguous array in the
        kernel's."""
        return np.ascontiguousarray(np.asarray(R, np.float64).take(self.perm, axis=0))

    def from_kernel(self, Rk: np.ndarray) -> np.ndarray:
        """Inverse of :meth:`to_kernel`: a new (n, 3, 3) array in the mesh's numbering."""
        return Rk.take(self.inv, axis=0)

    def step(self, U: np.ndarray, Rk: np.ndarray, jacobi: bool) -> float:
        """One local step: every rotation of ``Rk`` ((n, 3, 3) C-contiguous, kernel
        numbering) set in place, all from the previous ones (``jacobi``, or ``wR = 0``)
        or by Gauss-Seidel batches (:func:`gs_order`); ``U`` (n, 3) in the mesh's
        numbering. Returns ``E(U, R)`` of ARAP-SR (mesh units^2), the cells' energies
        summed in the mesh's order."""
        Uk = np.ascontiguousarray(np.asarray(U, np.float64).take(self.perm, axis=0))
        Ek = np.empty(self.n)
        if jacobi or self.wR == 0:
            Rold = Rk.copy() if self.wR > 0 else Rk  # wR = 0: no neighbour read
            order = self.jacobi_order
        else:
            Rold, order = Rk, self.gs
        M = np.empty((self.n, 3, 3))  # the covariances (scratch of this call: two threads may share a problem)
        args = (Uk, *self.kd.local_arrays(), *order, *self.graph, self.wR, Rold, Rk, M, Ek)
        if self.threads > 1:  # the serial kernel's bits (sshade.arap.kernels.sr_local_kernel)
            with numba_threads(self.threads):
                sr_local_kernel(True)(*args, self.threads)
        else:
            sr_local_kernel()(*args)
        E = float(Ek.take(self.inv).sum())  # in the mesh's order
        return 2.0 * E + self.wR * (self.smoothness(Rk) if self.wR > 0 else 0.0)

    def smoothness(self, Rk: np.ndarray) -> float:
        """``sum_i c_i sum_{j in N(i)} ||R_i - R_j||_F^2`` of ``Rk`` (kernel numbering),
        summed over the mesh's edges in their order (:func:`edge_sq_sum`'s float),
        dimensionless."""
        return 2.0 * float(edge_sq_sum(Rk.reshape(self.n, 9), self.s, self.d, self.edge_w, self.kd.einv,
                                                 np.empty(len(self.s))))

    def rhs(self, Rk: np.ndarray) -> np.ndarray:
        """``K(R)`` ((n, 3) float64, the mesh's numbering) of ``Rk`` (kernel numbering),
        each row summed as :meth:`sshade.arap.operators.ArapOperators.rhs` sums it."""
        out = self.ops.rhs_rows(Rk, self.rows, np.zeros((self.n, 3)), np.empty((self.n, 3)), self.threads, self.kd)
        return out.take(self.inv, axis=0)
