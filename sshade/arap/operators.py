"""ARAP energies with libigl's cotangent weights: operators, energy and gradient.

Two energies (:data:`ENERGIES`), one rotation per vertex: ``"spokes"`` (Sorkine & Alexa
2007, SGP) and ``"spokes_and_rims"`` (Chao, Pinkall, Sanan, Schröder 2010, SIGGRAPH),
libigl's ``ARAP_ENERGY_TYPE_SPOKES`` / ``_SPOKES_AND_RIMS``. ``E(U, R) = tr(U^T L U) -
2 tr(U^T K(R)) + const``, ``L = -igl.cotmatrix``, so the global step is libigl's.
:class:`ArapOperators`, :func:`build_operators`, :func:`fit_rotations`, :func:`bbox_diag`;
kernels in :mod:`sshade.arap.kernels`. Conventions and derivation: docs/implementation.md
("Implementation notes: sshade/arap/operators.py").
"""
from __future__ import annotations

import contextlib
from dataclasses import dataclass, field

import igl
import numpy as np
import scipy.sparse as sp

from ..errors import SShaDeError
from ..mesh.bounds import bbox_diagonal
from ..mesh.validate import check_arrays
from .kernel_data import KernelData, as_u32, rcm_order
from .kernels import energy_kernel, fused, polar_kernel
from .threads import numba_threads, resolve_threads

__all__ = ["ENERGIES", "TRACE_MIN_ENERGY", "ArapOperators", "build_operators", "fit_rotations", "bbox_diag"]

#: the ARAP energies (libigl's ``ARAP_ENERGY_TYPE_SPOKES`` / ``..._SPOKES_AND_RIMS``)
ENERGIES = ("spokes", "spokes_and_rims")
#: The least ``|E| / sum_e w_e ||e_e||^2`` at which :meth:`ArapOperators.local_step` keeps
#: the energy's trace form; below it (nearly rigid states, where the form's terms cancel)
#: it sums the cells' energies pair by pair. The form's relative noise, its sums taken
#: pairwise as here, was at most ``1e-15 rest / |E|`` on four meshes
#: (benchmarks/records/arap_trace_energy.md), so about 1e-12 at most here.
TRACE_MIN_ENERGY = 1e-3


_NO_EDGES = np.empty(0)  # the edge-term scratch of a term-by-term local step (unread)
# Spokes' K^T within a face, off the diagonal: position (q, r) holds edge k = 3 - q - r
# (corner k + 1 to k + 2), + where r is its first corner
_SPOKE_EDGE = np.array([[0, 2, 1], [2, 1, 0], [1, 0, 2]])
_SPOKE_SIGN = np.array([[0.0, -1.0, 1.0], [1.0, 0.0, -1.0], [-1.0, 1.0, 0.0]])


def bbox_diag(V: np.ndarray) -> float:
    """Length of the bounding-box diagonal of ``V`` ((n, 3) float64), mesh units."""
    return bbox_diagonal(np.asarray(V, np.float64))


def _polar_numpy(M: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    U, s, Vt = np.linalg.svd(M)
    d = np.sign(np.linalg.det(U) * np.linalg.det(Vt))
    d[d == 0] = 1.0
    U[:, :, 2] *= d[:, None]
    return U @ Vt, s[:, 0] + s[:, 1] + d * s[:, 2]



def fit_rotations(M: np.ndarray, *, return_trace: bool = False, backend: str = "auto",
                  warm: np.ndarray | None = None):
    """Closest rotations to a batch of 3x3 matrices (polar decomposition, det fixed).

    ``R_k = argmax_{R in SO(3)} tr(R^T M_k)`` = ``U_k diag(1, 1, det(U_k V_k^T)) V_k^T``
    for ``M_k = U_k S_k V_k^T`` (Sorkine & Alexa 2007, §2; the reflection case flips the
    singular vector of the smallest singular value, as libigl's ``polar_svd`` does).

    Parameters
    ----------
    M : (k, 3, 3) float64, e.g. ``M_k = sum a e' e^T`` (deformed times rest).
    return_trace : bool, also return ``tr(R_k^T M_k)`` = ``s1 + s2 + sign * s3``.
    backend : ``"auto"`` (numba kernel when numba works, else numpy), ``"numba"`` or
        ``"numpy"`` (``numpy.linalg.svd`` on the stack). The numba kernel (cyclic Jacobi
        on ``M^T M`` in float64, vectorised across matrices, then ``U`` by Gram-Schmidt of
        ``M V``) agrees with the SVD to ~1e-13 and is much faster than the SVD.

    warm : (k, 3, 3) float64 C-contiguous array or None (numba backend only): right
        singular vectors of a previous, nearby ``M``, used as the Jacobi start and
        overwritten with the new ones (about halves the cost inside an iteration). Start
        it as ``np.broadcast_to(np.eye(3), (k, 3, 3)).copy()``.

    Returns
    -------
    R : (k, 3, 3) float64 rotations (det = +1).
    tr : (k,) float64, only with ``return_trace``.

    Raises
    ------
    SShaDeError on an unknown backend or ``"numba"`` when numba is unusable, or a ``warm``
    array of the wrong shape.
    """
    if backend not in ("auto", "numba", "numpy"):
        raise SShaDeError(f"unknown rotation backend {backend!r}")
    M = np.asarray(M, np.float64)
    kern = polar_kernel() if backend != "numpy" else False
    if backend == "numba" and not kern:
        raise SShaDeError("numba rotation backend requested but numba is unusable")
    if warm is not None and (not isinstance(warm, np.ndarray) or warm.shape != M.shape
                             or warm.dtype != np.float64 or not warm.flags.c_contiguous):
        raise SShaDeError(f"warm must be a C-contiguous float64 array of shape {M.shape}")
    if kern:
        R = np.empty((len(M), 3, 3))
        tr = np.empty(len(M))
        kern(M, R, tr, M if warm is None else warm, warm is not None)
    else:
        R, tr = _polar_numpy(M)
    return (R, tr) if return_trace else R


@dataclass(eq=False)
class ArapOperators:
    """Precomputed ARAP operators of a rest mesh for one energy (built once).

    Attributes
    ----------
    energy_type : str, ``"spokes"`` or ``"spokes_and_rims"``.
    n : int, number of vertices (= number of rotation cells).
    V : (n, 3) float64 rest positions. F : (m, 3) int64 faces.
    edges : (ne, 2) int64 undirected edges ``(s, d)``, ``s < d``.
    edge_vec : (ne, 3) float64 rest edge vectors ``v_s - v_d`` (mesh units).
    edge_w : (ne,) float64 cotangent weights ``w_sd = -cotmatrix[s, d]`` (dimensionless).
    pair_cell, pair_edge : (p,) int64, the (cell, edge) incidences of the energy.
    pair_w : (p,) float64 weight of edge ``pair_edge`` in cell ``pair_cell``
        (``w/2`` per end point for spokes; sums of ``c/3`` for spokes-and-rims).
    cell_ptr : (n + 1,) int64, the pairs of cell ``k`` are ``cell_ptr[k]:cell_ptr[k+1]``
        (pairs are sorted by cell).
    L : (n, n) scipy.sparse.csr_matrix, ``-igl.cotmatrix(V, F)`` (PSD, rows sum to 0).
    kt : ``(ptr (n + 1,), idx (nnz,), val (nnz, 3))`` int64, int64, float64: the three
        blocks of ``K^T`` as one CSR with 3-vector values on the pattern of ``L`` (the
        diagonal and both directions of every edge, columns sorted):
        ``M[k, c, d] = sum_jj val[jj, d] U[idx[jj], c]`` over row ``k``.
    kv : the same for ``K`` (the transposed values on the same pattern): ``K(R)[v] =
        sum_d sum_jj val[jj, d] R[idx[jj], :, d]``.
    K : (n, 3n) scipy.sparse.csr_matrix (a property, built on first use from ``kv``),
        ``[K_0 K_1 K_2]``: the right-hand side is ``K(R)[:, c] = sum_d K_d @ R[:, c, d]``
        (libigl's ``arap_rhs`` up to sign and layout).
    KT : (3n, n) scipy.sparse.csr_matrix (a property, from ``kt``), row ``3k + d`` is
        row ``k`` of ``K_d^T``: the covariances are ``M[k, c, d] = (K_d^T U)[k, c]``
        (libigl's ``covariance_scatter_matrix``), summed as ``kt`` sums them.
    rest_term : float, ``sum_e w_e ||e_e||^2`` (mesh units^2).
    mass : (n,) float64 Voronoi-hybrid vertex areas (``igl.massmatrix``), mesh units^2.
    diag : float, bounding-box diagonal of ``V``.

    The numba kernels use :class:`KernelData` (:meth:`kernel_data`), built on first use and
    kept, like scipy's :attr:`K` and :attr:`KT`, in ``_kdata``.
    """

    energy_type: str
    n: int
    V: np.ndarray
    F: np.ndarray
    edges: np.ndarray
    edge_vec: np.ndarray
    edge_w: np.ndarray
    pair_cell: np.ndarray
    pair_edge: np.ndarray
    pair_w: np.ndarray
    cell_ptr: np.ndarray
    L: sp.csr_matrix
    kt: tuple
    kv: tuple
    rest_term: float
    mass: np.ndarray
    diag: float
    _kdata: dict = field(default_factory=dict, repr=False)

    @property
    def KT(self) -> sp.csr_matrix:
        """(3n, n) scipy.sparse.csr_matrix, row ``3k + d`` = row ``k`` of ``K_d^T``
        (built once from :attr:`kt`)."""
        if "KT" not in self._kdata:
            ptr, idx, val = self.kt
            row = np.repeat(np.arange(self.n), np.diff(ptr))
            rows = (3 * row[:, None] + np.arange(3)).ravel()
            self._kdata["KT"] = sp.csr_matrix((val.ravel(), (rows, np.repeat(idx, 3))), shape=(3 * self.n, self.n))
        return self._kdata["KT"]

    @property
    def K(self) -> sp.csr_matrix:
        """(n, 3n) scipy.sparse.csr_matrix ``[K_0 K_1 K_2]`` (built once from :attr:`kv`)."""
        if "K" not in self._kdata:
            ptr, idx, val = self.kv
            row = np.repeat(np.arange(self.n), np.diff(ptr))
            self._kdata["K"] = sp.csr_matrix(
                (val.T.ravel(), (np.tile(row, 3), (idx + self.n * np.arange(3)[:, None]).ravel())),
                shape=(self.n, 3 * self.n))
        return self._kdata["K"]

    def kernel_data(self, reorder: bool = False) -> KernelData:
        """The arrays of the numba kernels (:class:`KernelData`), built once per numbering.

        Parameters
        ----------
        reorder : bool, False: the mesh's own vertex numbering; True: the reverse
            Cuthill-McKee numbering of ``L`` (:func:`sshade.arap.kernel_data.rcm_order`),
            in which the kernels' gathers from neighbouring vertices and cells hit the
            cache (faster on large, randomly numbered meshes).
        """
        key = bool(reorder)
        if key not in self._kdata:
            perm = rcm_order(self.L) if key else None
            self._kdata[key] = KernelData.build(self, perm)
        return self._kdata[key]

    # ------------------------------------------------------------------ local step
    def covariances(self, U: np.ndarray) -> np.ndarray:
        """Per-cell matrices ``M_k = sum_{e in cell k} a_ke e'_e e_e^T``.

        Parameters
        ----------
        U : (n, 3) float64 deformed positions.

        Returns
        -------
        M : (n, 3, 3) float64, ``M[k, c, d] = sum a e'_c e_d``. The covariance in Sorkine
            & Alexa's notation is ``S_k = sum w e e'^T = M_k^T``; the optimal rotation is
            ``R_k = polar(M_k)`` (:func:`fit_rotations`).
        """
        out = self.KT @ np.asarray(U, np.float64)  # (3n, 3): row 3k + d, column c
        return out.reshape(self.n, 3, 3).transpose(0, 2, 1)

    def local_step(self, U: np.ndarray, R: np.ndarray, Ek: np.ndarray, warm: np.ndarray | None = None,
                   threads: int = 1, data: KernelData | None = None, Et: np.ndarray | None = None) -> float:
        """The local step into preallocated arrays: optimal rotations ``R*(U)`` and ``E(U)``.

        With numba, ONE kernel over the cells does the covariance, the polar decomposition
        and the energy (parallel over blocks of cells for ``threads > 1``; the results do
        not depend on ``threads``); without, the numpy path of :meth:`rotations`. The
        energy: the cells' energies summed term by term, or with ``Et`` the trace form
        ``sum_e w_e ||e'_e||^2 + sum_e w_e ||e_e||^2 - 2 sum_k tr(R_k^T M_k)`` (one pass
        over the edges instead of the cells' pairs), which falls back to the term-by-term
        sum below :data:`TRACE_MIN_ENERGY`; either is summed in the mesh's order, the same
        float in every numbering.

        Parameters
        ----------
        U : (n, 3) float64 deformed positions.
        R : (n, 3, 3) float64 C-contiguous, overwritten with the rotations.
        Ek : (n,) float64 C-contiguous scratch, overwritten with the cell energies or the
            traces (numba) or left untouched (numpy).
        warm : (n, 3, 3) float64 C-contiguous or None, polar warm start, updated in place
            (:func:`fit_rotations`).
        threads : int >= 1, threads of the kernel (:func:`resolve_threads`).
        data : :class:`KernelData` or None (:meth:`kernel_data`, mesh numbering); all the
            arrays above are in its numbering.
        Et : (ne,) float64 C-contiguous scratch or None: with numba, the trace form's edge
            terms (ne = the number of edges); None: the term-by-term sum.

        Returns
        -------
        E : float, ``E(U, R*(U))`` (mesh units^2).
        """
        kern = fused(threads)
        if not kern:
            return self._local_step_numpy(U, R, warm, data)
        if data is None:
            data = self.kernel_data(False)
        U = np.ascontiguousarray(U, np.float64)
        n, ne = self.n, len(self.edges)
        for name, a, shape in (("U", U, (n, 3)), ("R", R, (n, 3, 3)), ("Ek", Ek, (n,)),
                               ("warm", R if warm is None else warm, (n, 3, 3)),
                               ("Et", _NO_EDGES if Et is None else Et, (0,) if Et is None else (ne,))):
            if not (isinstance(a, np.ndarray) and a.shape == shape and a.dtype == np.float64
                    and a.flags.c_contiguous):
                raise SShaDeError(f"{name} must be a C-contiguous float64 array of shape {shape}")
        args = (U, *data.local_arrays(), R if warm is None else warm, warm is not None, R, Ek)
        with numba_threads(threads) if threads > 1 else contextlib.nullcontext():
            if Et is None:
                kern[0](*args, 0, data.edge_w, _NO_EDGES)
                return float((Ek if data.perm is None else Ek[data.inv]).sum())
            kern[0](*args, 1, data.edge_w, Et)
            tr = (Ek if data.perm is None else Ek[data.inv]).sum()
            E = float((Et if data.einv is None else Et[data.einv]).sum() + self.rest_term - 2.0 * tr)
            if abs(E) >= TRACE_MIN_ENERGY * self.rest_term:
                return E
            kern[0](*args, 2, data.edge_w, Et)  # nearly rigid: the cells' energies at these R
        return float((Ek if data.perm is None else Ek[data.inv]).sum())

    def _local_step_numpy(self, U, R, warm, data) -> float:
        """:meth:`local_step` without numba: :meth:`_rotations_numpy` in the mesh's numbering."""
        if data is None or data.perm is None:
            Rn, E = self._rotations_numpy(U, True, warm)
            R[...] = Rn
            return E
        inv, perm = data.inv, data.perm  # numpy path in the mesh's numbering
        Wo = None if warm is None else warm[inv]
        Rn, E = self._rotations_numpy(np.asarray(U)[inv], True, Wo)
        R[...] = Rn[perm]
        if warm is not None:
            warm[...] = Wo[perm]
        return E

    def rotations(self, U: np.ndarray, *, return_energy: bool = False, warm: np.ndarray | None = None,
                  threads: int | None = None):
        """Optimal rotations for ``U`` (the local step), optionally with ``E(U)``.

        Parameters
        ----------
        U : (n, 3) float64.
        return_energy : bool, also return the energy with these rotations.
        warm : (n, 3, 3) float64 or None, warm start of the polar kernel, updated in place
            (:func:`fit_rotations`).
        threads : int or None, threads of the numba kernel (:func:`resolve_threads`).

        Returns
        -------
        R : (n, 3, 3) float64 rotations. E : float, only with ``return_energy``
            (mesh units^2; :meth:`energy`).
        """
        t = resolve_threads(threads, self.n)
        if fused(t):
            if warm is not None and (not isinstance(warm, np.ndarray) or warm.shape != (self.n, 3, 3)
                                     or warm.dtype != np.float64 or not warm.flags.c_contiguous):
                raise SShaDeError(f"warm must be a C-contiguous float64 array of shape {(self.n, 3, 3)}")
            R = np.empty((self.n, 3, 3))
            E = self.local_step(U, R, np.empty(self.n), warm, t)
            return (R, E) if return_energy else R
        return self._rotations_numpy(U, return_energy, warm)

    def _rotations_numpy(self, U, return_energy, warm):
        """Local step with scipy's ``KT @ U`` and :func:`fit_rotations` (no fused kernel)."""
        M = self.covariances(U)
        R, tr = fit_rotations(M, return_trace=True, warm=warm if polar_kernel() else None)
        if not return_energy:
            return R
        return R, self._energy(U, R, tr)

    def _energy_from_trace(self, U: np.ndarray, tr: np.ndarray) -> float:
        """Closed form on edge differences (translation-invariant; ~1e-13 relative noise)."""
        ed = U[self.edges[:, 0]] - U[self.edges[:, 1]]
        return float((self.edge_w * np.einsum("ij,ij->i", ed, ed)).sum() + self.rest_term - 2.0 * tr.sum())

    def _energy(self, U: np.ndarray, R: np.ndarray, tr: np.ndarray | None) -> float:
        """Energy ``E(U, R)``: the numba term-by-term sum when available (~1e-15 relative
        noise, needed to compare energies of iterates near the minimum), else the closed
        form (``tr[k] = tr(R_k^T M_k)`` required)."""
        kern = energy_kernel()
        if kern:
            out = np.empty(self.n)
            kern(np.ascontiguousarray(U, np.float64), self.edges, self.edge_vec, self.cell_ptr, self.pair_edge,
                 self.pair_w, np.ascontiguousarray(R), out)
            return float(out.sum())
        if tr is None:
            tr = np.einsum("kab,kab->k", R, self.covariances(U))
        return self._energy_from_trace(U, tr)

    # ----------------------------------------------------------------- global step
    def rhs(self, R: np.ndarray, *, threads: int | None = None) -> np.ndarray:
        """Right-hand side ``K(R)`` of the global step ``L U = K(R)``.

        Parameters
        ----------
        R : (n, 3, 3) float64 per-cell rotations.
        threads : int or None, threads of the numba kernel (:func:`resolve_threads`).

        Returns
        -------
        B : (n, 3) float64, ``B_s = sum_{(k,e), e=(s,d)} a_ke R_k (v_s - v_d)`` (and the
            negative for the other end point).
        """
        out = np.empty((self.n, 3))
        return self.rhs_rows(R, np.arange(self.n, dtype=np.uint32), np.zeros((self.n, 3)), out,
                             resolve_threads(threads, self.n))

    def rhs_rows(self, R: np.ndarray, rows: np.ndarray, sub: np.ndarray, out: np.ndarray,
                 threads: int = 1, data: KernelData | None = None) -> np.ndarray:
        """``out = K(R)[rows] - sub``, the global step's right-hand side on some rows.

        Numba: a kernel over the rows (parallel for ``threads > 1``) gathering the
        rotations of the neighbouring cells; else scipy's ``K @ Rs``.

        Parameters
        ----------
        R : (n, 3, 3) float64 rotations. rows : (r,) integer vertex indices (uint32 spares a
            conversion).
        sub : (r, 3) float64. out : (r, 3) float64 C-contiguous, written.
        threads : int >= 1.
        data : :class:`KernelData` or None (mesh numbering); ``R`` and ``rows`` are in its
            numbering.

        Returns
        -------
        out.
        """
        kern = fused(threads)
        if not kern:
            if data is not None and data.perm is not None:  # numpy path in the mesh's numbering
                R = np.asarray(R)[data.inv]
                rows = data.perm[rows]
            Rs = np.ascontiguousarray(np.asarray(R, np.float64).transpose(2, 0, 1)).reshape(3 * self.n, 3)
            np.subtract((self.K @ Rs)[rows], sub, out=out)
            return out
        if data is None:
            data = self.kernel_data(False)
        rows = rows if rows.dtype == np.uint32 and rows.flags.c_contiguous else as_u32(rows)
        R = np.ascontiguousarray(R, np.float64)
        sub = np.ascontiguousarray(sub, np.float64)
        r = len(rows)
        if (r and rows.max() >= self.n) or R.shape != (self.n, 3, 3) or sub.shape != (r, 3) \
                or not (isinstance(out, np.ndarray) and out.shape == (r, 3) and out.dtype == np.float64
                        and out.flags.c_contiguous):
            raise SShaDeError("rhs_rows: rows must index vertices, R be (n, 3, 3), sub and out (len(rows), 3) "
                              "float64 (out C-contiguous)")
        args = (rows, *data.kv, R, sub, out)
        if threads > 1:
            with numba_threads(threads):
                kern[1](*args)
        else:
            kern[1](*args)
        return out

    # ------------------------------------------------------------ energy/gradient
    def energy(self, U: np.ndarray, R: np.ndarray | None = None) -> float:
        """ARAP energy ``E(U) = min_R E(U, R)`` (or ``E(U, R)`` for given ``R``).

        Summed term by term (numba kernel, relative rounding noise ~1e-15) or, without
        numba, in closed form ``E = sum_e w_e (||e'_e||^2 + ||e_e||^2) - 2 sum_k
        tr(R_k^T M_k)`` (rotations preserve lengths; the edge weights over all cells sum
        to ``w_e``; noise ~1e-13 relative from cancellation).

        Parameters
        ----------
        U : (n, 3) float64 deformed positions.
        R : (n, 3, 3) float64 or None; None: the optimal rotations.

        Returns
        -------
        float, mesh units^2 (``0`` for a rigid motion of ``V``).
        """
        U = np.asarray(U, np.float64)
        if R is None:
            return self.rotations(U, return_energy=True)[1]
        return self._energy(U, np.asarray(R, np.float64), None)

    def energy_direct(self, U: np.ndarray, R: np.ndarray | None = None) -> float:
        """Same as :meth:`energy` but summed term by term,
        ``sum_k sum_e a_ke ||e'_e - R_k e_e||^2`` (for tests; O(p) memory)."""
        U = np.asarray(U, np.float64)
        if R is None:
            R = self.rotations(U)
        ed = U[self.edges[:, 0]] - U[self.edges[:, 1]]
        r = ed[self.pair_edge] - np.einsum("kab,kb->ka", R[self.pair_cell], self.edge_vec[self.pair_edge])
        return float((self.pair_w * (r * r).sum(1)).sum())

    def gradient(self, U: np.ndarray, R: np.ndarray | None = None) -> np.ndarray:
        """Gradient ``dE/dU = 2 (L U - K(R))`` with the optimal rotations ``R*(U)``.

        Parameters
        ----------
        U : (n, 3) float64. R : (n, 3, 3) or None (None: optimal rotations for ``U``;
            then this is the gradient of ``E(U) = min_R E(U, R)`` by the envelope theorem).

        Returns
        -------
        (n, 3) float64, mesh units (energy units / length).
        """
        U = np.asarray(U, np.float64)
        if R is None:
            R = self.rotations(U)
        return 2.0 * (self.L @ U - self.rhs(R))

    def local_global_step(self, U: np.ndarray, handles: np.ndarray, targets: np.ndarray,
                          solve) -> np.ndarray:
        """One local/global iteration (for tests and simple use).

        Parameters
        ----------
        U : (n, 3) float64 current positions. handles : (h,) int64; targets : (h, 3).
        solve : callable, ``X = solve(B)`` solving ``L_ff X = B`` for ``(n_f, 3)`` ``B``
            on the free vertices (``np.setdiff1d(arange(n), handles)``, sorted).

        Returns
        -------
        (n, 3) float64 next iterate (handles at their targets).
        """
        free = np.setdiff1d(np.arange(self.n), handles)
        R = self.rotations(U)
        B = self.rhs(R)
        Ut = np.array(U, np.float64)
        Ut[handles] = targets
        Ut[free] = 0.0
        B = B - self.L @ Ut
        Un = Ut.copy()
        Un[free] = solve(B[free])
        return Un


def build_operators(V: np.ndarray, F: np.ndarray, energy: str = "spokes_and_rims") -> ArapOperators:
    """Precompute the ARAP operators of the rest mesh ``(V, F)`` for ``energy``.

    Parameters
    ----------
    V : (n, 3) float64 rest positions (any length unit). F : (m, 3) int faces.
    energy : ``"spokes"`` (Sorkine & Alexa 2007) or ``"spokes_and_rims"`` (Chao et al.
        2010), with libigl's weights (:data:`ENERGIES`).

    Returns
    -------
    ArapOperators

    Raises
    ------
    SShaDeError
        Unknown energy; bad shapes, NaN/inf, indices out of range; a degenerate face (its
        cotangent weights are not finite); a vertex that is in no face.

    Examples
    --------
    Example::

        ops = build_operators(V, F, "spokes")
        ops.energy(V)  # rest pose: 0
    """
    if energy not in ENERGIES:
        raise SShaDeError(f"unknown ARAP energy {energy!r}; use one of {ENERGIES}")
    V, F = check_arrays(V, F, min_vertices=3)
    n = len(V)
    if np.bincount(F.ravel(), minlength=n).min() == 0:
        raise SShaDeError("a vertex is referenced by no face (unreferenced vertex)")
    C = igl.cotmatrix_entries(V, F)  # (m, 3): cot/2 for edges [1,2], [2,0], [0,1]
    if not np.isfinite(C).all():
        bad = int(np.flatnonzero(~np.isfinite(C).all(1))[0])
        raise SShaDeError(f"face {bad} is degenerate (non-finite cotangent weight)")
    edges, edge_vec, edge_w, fe2e = _edges(V, F, C)
    pattern = _pattern(n, edges)
    pair_cell, pair_edge, pair_w, cell_ptr = _cell_pairs(F, C, energy, len(edges), fe2e, pattern)
    L, kt, kv = _laplacian_and_rhs(V, F, C, energy, pattern, fe2e.reshape(-1, 3))
    rest_term = float((edge_w * (edge_vec ** 2).sum(1)).sum())
    mass = np.asarray(igl.massmatrix(V, F, igl.MASSMATRIX_TYPE_VORONOI).diagonal(), np.float64)
    return ArapOperators(energy_type=energy, n=n, V=V, F=F, edges=edges, edge_vec=edge_vec, edge_w=edge_w,
                         pair_cell=pair_cell, pair_edge=pair_edge, pair_w=pair_w, cell_ptr=cell_ptr, L=L, kt=kt, kv=kv,
                         rest_term=rest_term, mass=mass, diag=bbox_diag(V))


def _edges(V: np.ndarray, F: np.ndarray, C: np.ndarray) -> tuple:
    """The undirected edges of ``F`` from its face-edges (edge ``k`` of face ``f``, from
    corner ``k + 1`` to ``k + 2``, opposite corner ``k``, at ``3 f + k``): ``(edges (ne, 2)
    int64 (s < d, sorted), edge_vec (ne, 3), edge_w (ne,) (the sum of the face-edges'
    cotangent entries ``C`` (m, 3) in face order), fe2e (3m,) int64 the edge of each
    face-edge)``."""
    n = len(V)
    S, D = F[:, [1, 2, 0]].ravel(), F[:, [2, 0, 1]].ravel()
    ukey, fe2e = np.unique(np.minimum(S, D) * n + np.maximum(S, D), return_inverse=True)
    edges = np.stack([ukey // n, ukey % n], 1)
    edge_vec = V[edges[:, 0]] - V[edges[:, 1]]
    return edges, edge_vec, np.bincount(fe2e, weights=C.ravel(), minlength=len(edges)), fe2e


def _cell_pairs(F: np.ndarray, C: np.ndarray, energy: str, ne: int, fe2e: np.ndarray, pattern: tuple) -> tuple:
    """The (cell, edge) incidences of ``energy`` (the cells: docs/implementation.md,
    "Implementation notes: sshade/arap/operators.py"): ``(pair_cell, pair_edge, pair_w,
    cell_ptr)`` as the attributes of :class:`ArapOperators`, sorted by cell, then edge.

    Spokes: the cells of an edge are its end points, ``w = c / 2`` per face: the pairs of
    cell ``v`` are the off-diagonal entries of row ``v`` of ``L``'s ``pattern``
    (:func:`_pattern`), whose column order is the edges' order. Spokes-and-rims: the
    opposite corner too, ``w = c / 3``, a (cell, edge) met twice summed."""
    ptr, idx, diag, fwd, bwd = pattern
    n = len(ptr) - 1
    c = C.ravel()
    if energy == "spokes":
        offd = np.ones(len(idx), bool)
        offd[diag] = False
        pos_edge = np.empty(len(idx), np.int64)
        pos_edge[fwd] = pos_edge[bwd] = np.arange(ne)
        pair_edge = pos_edge[offd]
        cell_ptr = ptr - np.arange(n + 1)
        pair_cell = np.repeat(np.arange(n), np.diff(cell_ptr))
        return pair_cell, pair_edge, np.bincount(fe2e, weights=c / 2.0, minlength=ne)[pair_edge], cell_ptr
    cells = np.concatenate([F[:, [1, 2, 0]].ravel(), F[:, [2, 0, 1]].ravel(), F.ravel()])
    P = sp.coo_matrix((np.tile(c / 3.0, 3), (cells, np.tile(fe2e, 3))), shape=(n, ne)).tocsr()  # sums duplicates
    P.sort_indices()
    cell_ptr = P.indptr.astype(np.int64)
    return np.repeat(np.arange(n), np.diff(cell_ptr)), P.indices.astype(np.int64), P.data, cell_ptr


def _laplacian_and_rhs(V: np.ndarray, F: np.ndarray, C: np.ndarray, energy: str, pattern: tuple,
                       fe: np.ndarray) -> tuple[sp.csr_matrix, tuple, tuple]:
    """``(L, kt, kv)`` of :class:`ArapOperators`, assembled face by face on ``pattern``
    (:func:`_pattern`: the diagonal and both directions of every edge, columns sorted).
    ``fe`` (m, 3): the edge of each face-edge (opposite corner ``k``).

    ``L = -igl.cotmatrix(V, F)`` to the bit: the entries libigl's ``cotmatrix`` makes, four
    per face-edge in its order, summed in that order (Eigen's ``setFromTriplets``). For
    ``K``, a pair (cell ``q``, edge ``e = v_s - v_d``) of weight ``w`` adds ``w e`` at
    (q, s) and ``-w e`` at (q, d); the cells of a face's edge are its end points (``w = c /
    2``) and, for spokes-and-rims, the opposite corner too (``w = c / 3``). Summed within
    each face into its 3x3 block of positions (corners ``q``, ``r``), then over the faces
    in their order."""
    n, m = len(V), len(F)
    ptr, idx, diag, fwd, bwd = pattern
    nnz = len(idx)
    T = np.empty((m, 3, 3), np.int64)  # T[f, q, r]: position of (F[f, q], F[f, r])
    T[:, (0, 1, 2), (0, 1, 2)] = diag[F]
    for k in range(3):  # face-edge k joins corners a and b
        a, b = (k + 1) % 3, (k + 2) % 3
        e = fe[:, k]
        pf, pb = fwd[e], bwd[e]
        lt = F[:, a] < F[:, b]
        T[:, a, b] = np.where(lt, pf, pb)
        T[:, b, a] = np.where(lt, pb, pf)
    # libigl's triplets per face-edge k, corners a = k + 1 and b = k + 2 (mod 3): (a, b),
    # (b, a), (a, a), (b, b), at T[:, q, r] = T.reshape(m, 9)[:, 3 q + r]
    at = [p for k in range(3) for a, b in [((k + 1) % 3, (k + 2) % 3)] for p in (3 * a + b, 3 * b + a, 4 * a, 4 * b)]
    Ct = np.repeat(C, 4, axis=1) * np.tile([-1.0, -1.0, 1.0, 1.0], 3)  # -C off the diagonal
    L = sp.csr_matrix((np.bincount(T.reshape(m, 9)[:, at].ravel(), weights=Ct.ravel(), minlength=nnz), idx, ptr),
                      shape=(n, n))
    kval = _rhs_values(V, F, C, energy != "spokes", T, nnz)
    tperm = np.empty(nnz, np.int64)  # position of (j, i) for (i, j)
    tperm[diag], tperm[fwd], tperm[bwd] = diag, bwd, fwd
    return L, (ptr, idx, np.ascontiguousarray(kval.T)), (ptr, idx, np.ascontiguousarray(kval[:, tperm].T))


def _pattern(n: int, edges: np.ndarray) -> tuple:
    """The CSR pattern of ``L`` (n vertices, ``edges`` (ne, 2) with ``s < d``): ``(ptr
    (n + 1,), idx (nnz,))`` int64, columns sorted, and the positions in it of the diagonal
    (n,), of ``(s, d)`` and of ``(d, s)`` (ne,) each."""
    ne = len(edges)
    ar = np.arange(n)
    ids = np.arange(n + 2 * ne)
    P = sp.coo_matrix((ids, (np.concatenate([ar, edges[:, 0], edges[:, 1]]),
                             np.concatenate([ar, edges[:, 1], edges[:, 0]]))), shape=(n, n)).tocsr()
    P.sort_indices()
    pos = np.empty(len(ids), np.int64)
    pos[P.data] = np.arange(P.nnz)
    return (P.indptr.astype(np.int64), P.indices.astype(np.int64), pos[:n], pos[n:n + ne], pos[n + ne:])


def _rhs_values(V: np.ndarray, F: np.ndarray, C: np.ndarray, rims: bool, T: np.ndarray, nnz: int) -> np.ndarray:
    """(3, nnz) float64: the values of ``K^T`` on the pattern, one row per component, from
    each face's 3x3 block at positions ``T`` (m, 3, 3) (:func:`_laplacian_and_rhs`)."""
    m = len(F)
    VF = V[F]  # (m, 3, 3): the corners' positions
    # u[k]: edge k (corner k + 1 to k + 2) times its weight; at corner r the edges through
    # it sum to u[r + 2] - u[r + 1] (the spokes' diagonal, every cell of a rims face)
    u = [(C[:, k] / (3.0 if rims else 2.0))[:, None] * (VF[:, (k + 1) % 3] - VF[:, (k + 2) % 3]) for k in range(3)]
    W = np.stack([u[(r + 2) % 3] - u[(r + 1) % 3] for r in range(3)], 2)  # (m, 3 components, 3 corners)
    at = T.ravel()
    kval = np.empty((3, nnz))
    for c in range(3):
        if rims:  # every cell of the face: its corner's edges at every position of the corner
            B = np.broadcast_to(W[:, c, None, :], (m, 3, 3)).ravel()
        else:  # spokes: the corner's edges on the diagonal; off it only the edge (q, r), + where r is its first corner
            B = np.stack([u[k][:, c] for k in range(3)], 1)[:, _SPOKE_EDGE] * _SPOKE_SIGN
            B[:, (0, 1, 2), (0, 1, 2)] = W[:, c, :]
            B = B.ravel()
        kval[c] = np.bincount(at, weights=B, minlength=nnz)
    return kval
