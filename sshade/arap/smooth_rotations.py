"""ARAP with smooth rotations, ARAP-SR (Levi & Gotsman 2015, "Smooth rotation enhanced
as-rigid-as-possible mesh animation", IEEE TVCG): its energy and its problem.

    E(U, R) = sum_i sum_{j in N(i)} w_ij || e'_ij - R_i e_ij ||^2
              + alpha * A * sum_i c_i sum_{j in N(i)} || R_i - R_j ||_F^2

``w_ij`` libigl's cotangent weights, ``A`` the surface area, ``c_i = 1 / valence``
(``alpha_scaling="valence"``, Open3D's alpha) or 1 (``"none"``; :data:`ALPHA_SCALINGS`).
:class:`SRProblem` holds its local and global steps for both protocols:
:mod:`sshade.arap.sr_solver` (converged) and :mod:`sshade.arap.sr_paper_protocol` (§4.1).
Derivation and sources: docs/implementation.md, "Implementation notes: sshade/arap/smooth_rotations.py".
"""
from __future__ import annotations

import time

import numpy as np
import scipy.sparse as sp
from numba import njit

from ..errors import SShaDeError
from ..mesh.validate import validate_handles
from .criterion import gradient_norm
from .kernel_data import REORDER_MIN_VERTICES
from .kernels import sr_local_kernel
from .linear import LaplacianSolver
from .operators import build_operators, fit_rotations
from .options import ALPHA_SCALINGS, READS, SR_ENERGY, ArapOptions
from .sr_local import SRLocal, edge_sq_sum

__all__ = ["SRProblem", "colour_classes", "smoothness_weights", "check_sr_options"]

clock = time.perf_counter


@njit(cache=True, nogil=True)
def _class_targets(M, Rf, indptr, indices, data, cls, wR, out):  # pragma: no cover - compiled
    """``out[k] = M[i] + wR sum_{j in N(i)} a_ij R_j`` for ``i = cls[k]`` (the matrices whose
    polar factors are the class's new rotations); ``M`` (n, 9), ``Rf`` (n, 9), the weighted
    graph as CSR ``(indptr, indices, data)``, ``out`` (len(cls), 9)."""
    for k in range(len(cls)):
        i = cls[k]
        for a in range(9):
            out[k, a] = 0.0
        for p in range(indptr[i], indptr[i + 1]):
            j = indices[p]
            c = data[p]
            for a in range(9):
                out[k, a] += c * Rf[j, a]
        for a in range(9):
            out[k, a] = M[i, a] + wR * out[k, a]


@njit(cache=True, nogil=True)
def _scatter_rows(Rf, cls, Rc):  # pragma: no cover - compiled
    """``Rf[cls[k]] = Rc[k]`` for (n, 9) ``Rf`` and (len(cls), 9) ``Rc``."""
    for k in range(len(cls)):
        for a in range(9):
            Rf[cls[k], a] = Rc[k, a]


def smoothness_weights(n: int, edges: np.ndarray, alpha_scaling: str = "valence") -> np.ndarray:
    """Per-edge weights ``(c_s + c_d) / 2`` of the rotation-smoothness term (module
    docstring): ``c_i = 1 / d_i`` for ``"valence"`` (Open3D's Smoothed ARAP), 1 for
    ``"none"``.

    Parameters
    ----------
    n : int, vertex count. edges : (ne, 2) int undirected edges, each once.
    alpha_scaling : one of :data:`ALPHA_SCALINGS`.

    Returns
    -------
    (ne,) float64, dimensionless.

    Raises
    ------
    SShaDeError on an unknown ``alpha_scaling``.
    """
    if alpha_scaling not in ALPHA_SCALINGS:
        raise SShaDeError(f"ARAP-SR: alpha_scaling must be one of {ALPHA_SCALINGS}, got {alpha_scaling!r}")
    s, d = np.asarray(edges[:, 0], np.int64), np.asarray(edges[:, 1], np.int64)
    if alpha_scaling == "none":
        return np.ones(len(s))
    deg = np.bincount(np.r_[s, d], minlength=n).astype(np.float64)
    c = 1.0 / np.maximum(deg, 1.0)
    return 0.5 * (c[s] + c[d])


def colour_classes(n: int, edges: np.ndarray, seed: int = 0) -> list[np.ndarray]:
    """Split the vertices of a graph into independent sets (Jones & Plassmann 1993:
    in each round, the uncoloured vertices whose random priority beats every uncoloured
    neighbour's form one class).

    Parameters
    ----------
    n : int, vertex count. edges : (ne, 2) int undirected edges. seed : int, priorities.

    Returns
    -------
    list of (k_c,) int64 sorted arrays partitioning ``arange(n)``, no edge inside a class.
    """
    s, d = np.asarray(edges[:, 0], np.int64), np.asarray(edges[:, 1], np.int64)
    p = np.random.default_rng(seed).permutation(n).astype(np.int64)
    left = np.ones(n, bool)
    out = []
    while left.any():
        q = np.where(left, p, -1)
        best = np.full(n, -1, np.int64)
        np.maximum.at(best, s, q[d])
        np.maximum.at(best, d, q[s])
        pick = left & (p > best)
        out.append(np.flatnonzero(pick))
        left &= ~pick
    return out


class SRProblem:
    """ARAP-SR's operators on one mesh and handle set (built once per solve).

    Parameters
    ----------
    V : (n, 3) float64 rest positions; F : (m, 3) int faces. handles : (h,) int;
    targets : (h, 3) float64 (both None: energies only, no global step).
    alpha : float >= 0, smoothness weight (times the area).
    linear_solver : :class:`sshade.arap.LaplacianSolver` backend.
    alpha_scaling : one of :data:`ALPHA_SCALINGS` (module docstring; default Open3D's).

    Raises
    ------
    SShaDeError on a bad mesh, handles, alpha or alpha_scaling, or a component without a
    handle.
    """

    def __init__(self, V, F, handles, targets, alpha: float, linear_solver: str = "auto",
                 alpha_scaling: str = "valence"):
        if not (np.isfinite(alpha) and alpha >= 0):
            raise SShaDeError(f"ARAP-SR: alpha must be a finite number >= 0, got {alpha!r}")
        self.ops = ops = build_operators(V, F, "spokes")
        if handles is None:  # energy evaluation only (no global step)
            handles, targets = np.zeros(0, np.int64), np.zeros((0, 3))
        else:
            handles, targets = validate_handles(ops.V, handles, targets)
        self.h, self.T = handles, targets
        self.n, self.alpha, self.alpha_scaling = ops.n, float(alpha), alpha_scaling
        Vr, Fr = ops.V, ops.F
        self.area = 0.5 * float(np.linalg.norm(np.cross(Vr[Fr[:, 1]] - Vr[Fr[:, 0]], Vr[Fr[:, 2]] - Vr[Fr[:, 0]]),
                                               axis=1).sum())
        self.wR = self.alpha * self.area  # times a_ij: the weight of R_j in the local step
        self.rs = np.sqrt(self.wR) if self.wR > 0 else 1.0
        s, d = ops.edges[:, 0], ops.edges[:, 1]
        self.edge_w = smoothness_weights(self.n, ops.edges, alpha_scaling)  # a_ij = (c_s + c_d) / 2
        self.adj = sp.csr_matrix((np.r_[self.edge_w, self.edge_w], (np.r_[s, d], np.r_[d, s])),
                                 shape=(self.n, self.n))
        self.classes = colour_classes(self.n, ops.edges)
        self.adj.sort_indices()
        self._kernel_setup()
        free = np.ones(self.n, bool)
        free[self.h] = False
        self.free = np.flatnonzero(free)
        t0 = clock()
        self.solver = LaplacianSolver(ops.L[self.free][:, self.free], linear_solver) if len(self.h) else None
        self.factor_s = clock() - t0
        self._L_fb = ops.L[self.free][:, self.h]
        self.Lfb_T = self._L_fb @ self.T

    def _kernel_setup(self) -> None:
        """The fused local step (:class:`sshade.arap.sr_local.SRLocal`, in the reverse
        Cuthill-McKee numbering from :data:`REORDER_MIN_VERTICES` vertices), or None when
        numba is unusable (then the scipy / numpy path)."""
        self.fused = SRLocal(self.ops, self.adj, self.classes, self.edge_w, self.wR,
                             self.n >= REORDER_MIN_VERTICES) if sr_local_kernel() else None

    def set_targets(self, targets) -> None:
        """New ``targets`` ((h, 3) float64, one per handle) for the same handles: the
        global step's right-hand side follows them; the operators and the factorised
        ``L_ff`` are kept. Raises SShaDeError on targets of the wrong shape or not finite."""
        self.h, self.T = validate_handles(self.ops.V, self.h, targets)
        self.Lfb_T = self._L_fb @ self.T

    def smoothness(self, R: np.ndarray) -> float:
        """``sum_i c_i sum_{j in N(i)} ||R_i - R_j||_F^2`` (module docstring),
        dimensionless."""
        Rf = np.ascontiguousarray(R, np.float64).reshape(self.n, 9)
        ne = len(self.edge_w)
        s, d = (np.ascontiguousarray(self.ops.edges[:, k], np.int64) for k in (0, 1))
        return 2.0 * float(edge_sq_sum(Rf, s, d, self.edge_w, np.arange(ne, dtype=np.int64), np.empty(ne)))

    def energy(self, U: np.ndarray, R: np.ndarray) -> float:
        """``E(U, R)`` of the module docstring, mesh units^2."""
        return 2.0 * self.ops.energy(U, R) + self.wR * self.smoothness(R)

    def sweep(self, U: np.ndarray, R: np.ndarray, jacobi: bool = False) -> np.ndarray:
        """One Gauss-Seidel sweep of the local step over the colour classes (``jacobi``:
        every rotation at once from the previous ones, which may increase the energy; for
        measurements). ``R`` (n, 3, 3) float64 is updated in place and returned; ``U``
        (n, 3)."""
        return self.local_step(U, R, jacobi)[0]

    def local_step(self, U: np.ndarray, R: np.ndarray, jacobi: bool = False) -> tuple[np.ndarray, float]:
        """:meth:`sweep` and the energy ``E(U, R)`` at its rotations (:meth:`energy`, the
        same float): with numba one pass over the cells, each cell's ARAP term summed when
        its rotation is set (:class:`sshade.arap.sr_local.SRLocal`), else the scipy /
        numpy path then :meth:`energy`.

        Parameters
        ----------
        U : (n, 3) float64. R : (n, 3, 3) float64, updated in place. jacobi : bool.

        Returns
        -------
        ``(R, E)``: ``R`` itself; ``E`` float, mesh units^2.
        """
        Rk = self.to_work(R)
        Rk, E = self.work_step(U, Rk, jacobi)
        R[...] = self.from_work(Rk)
        return R, E

    # ----------------------------------------- the iterations' state: rotations "Rw"
    def to_work(self, R: np.ndarray) -> np.ndarray:
        """(n, 3, 3) rotations as a new C-contiguous array in the numbering the iterations
        keep them in (:class:`sshade.arap.sr_local.SRLocal`; the mesh's without numba)."""
        return self.fused.to_kernel(R) if self.fused is not None else np.array(R, np.float64, order="C")

    def from_work(self, Rw: np.ndarray) -> np.ndarray:
        """Inverse of :meth:`to_work`: a new (n, 3, 3) array in the mesh's numbering."""
        return self.fused.from_kernel(Rw) if self.fused is not None else np.array(Rw, np.float64)

    def work_step(self, U: np.ndarray, Rw: np.ndarray, jacobi: bool = False) -> tuple[np.ndarray, float]:
        """:meth:`local_step` on ``Rw`` ((n, 3, 3) of :meth:`to_work`, updated in place):
        ``(Rw, E)``."""
        if self.fused is not None:
            return Rw, self.fused.step(U, Rw, jacobi)
        Rw = self._sweep_numpy(U, Rw, jacobi)
        return Rw, self.energy(U, Rw)

    def work_rhs(self, Rw: np.ndarray) -> np.ndarray:
        """``K(R)`` ((n, 3) float64, the mesh's numbering) of ``Rw`` (:meth:`to_work`), as
        :meth:`sshade.arap.operators.ArapOperators.rhs` gives it."""
        return self.fused.rhs(Rw) if self.fused is not None else self.ops.rhs(Rw)

    def _sweep_numpy(self, U: np.ndarray, R: np.ndarray, jacobi: bool) -> np.ndarray:
        """:meth:`sweep` without the fused kernel (scipy products, :func:`fit_rotations`)."""
        M = self.ops.covariances(U)
        if self.wR == 0:
            R[...] = fit_rotations(M)
            return R
        Rf = np.ascontiguousarray(R).reshape(self.n, 9)
        if jacobi:
            R[...] = fit_rotations(M + self.wR * (self.adj @ Rf).reshape(-1, 3, 3))
            return R
        Mf = np.ascontiguousarray(M).reshape(self.n, 9)
        buf = np.empty((max(len(c) for c in self.classes), 9))
        ip, ix, iw = self.adj.indptr, self.adj.indices, self.adj.data
        for c in self.classes:  # compiled gather / scatter, batched polar decompositions
            X = buf[:len(c)]
            _class_targets(Mf, Rf, ip, ix, iw, c, self.wR, X)
            _scatter_rows(Rf, c, np.ascontiguousarray(fit_rotations(X.reshape(-1, 3, 3))).reshape(-1, 9))
        if not np.shares_memory(Rf, R):  # R was not C-contiguous: Rf is a copy
            R[...] = Rf.reshape(self.n, 3, 3)
        return R

    def pack(self, U: np.ndarray, R: np.ndarray) -> np.ndarray:
        """The state ``(U_free, R)`` as one vector (Anderson's unknowns); the rotations are
        scaled by ``sqrt(alpha A)`` (their weight in the energy). Shape (3 n_f + 9 n,)."""
        return np.concatenate([U.take(self.free, axis=0).ravel(), self.rs * R.ravel()])

    def unpack(self, x: np.ndarray, U: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Inverse of :meth:`pack`: ``(U', R')`` with ``U'`` a copy of ``U`` whose free rows
        come from ``x``; ``R'`` (n, 3, 3) not necessarily rotations."""
        nf = 3 * len(self.free)
        Un = np.array(U, np.float64)
        Un[self.free] = x[:nf].reshape(-1, 3)
        return Un, np.ascontiguousarray(x[nf:].reshape(self.n, 3, 3) / self.rs)

    def global_step(self, U: np.ndarray, R: np.ndarray, B: np.ndarray | None = None) -> np.ndarray:
        """``argmin_U E(U, R)`` with the handles at their targets: a new (n, 3) array.
        ``B``: ``ops.rhs(R)`` if already computed."""
        Un = np.array(U, np.float64)
        Un[self.h] = self.T
        B = self.ops.rhs(R) if B is None else B
        Un[self.free] = self.solver.solve(B.take(self.free, axis=0) - self.Lfb_T)
        return Un

    def gnorm(self, U: np.ndarray, R: np.ndarray, B: np.ndarray | None = None) -> float:
        """Scale-free norm of ``dE/dU / 2 = 2 (L U - K(R))`` on the free vertices
        (:func:`sshade.arap.gradient_norm`), dimensionless. ``B``: ``ops.rhs(R)`` if
        already computed."""
        B = self.ops.rhs(R) if B is None else B
        g = 2.0 * (self.ops.L @ U - B).take(self.free, axis=0)
        return gradient_norm(g, self.ops.mass.take(self.free), self.ops.diag)

    def reduced_energy(self, U: np.ndarray, R: np.ndarray | None = None, *, rtol: float = 1e-13,
                       max_sweeps: int = 2000) -> tuple[float, np.ndarray]:
        """``min_R E(U, R)`` for a fixed ``U`` (n, 3) by sweeps from ``R`` (default ARAP's
        optimal rotations) until the relative decrease of a sweep is below ``rtol``.
        Returns ``(E, R)``."""
        R = self.ops.rotations(U) if R is None else np.array(R, np.float64)
        E, Rw = self.energy(U, R), self.to_work(R)
        for _ in range(max_sweeps):
            En = self.work_step(U, Rw)[1]
            done = E - En <= rtol * abs(En)
            E = En
            if done:
                break
        return E, self.from_work(Rw)


def check_sr_options(options, who: str, problem: SRProblem | None) -> ArapOptions:
    """The options of the ARAP-SR solver ``who`` (a key of :data:`READS`).

    ``options``: an :class:`ArapOptions` or None (the defaults), setting no field ``who``
    does not read, of ARAP-SR's energy (or the default), agreeing with ``problem``'s
    (an :class:`SRProblem` or None) alpha, alpha_scaling and linear solver.

    Returns
    -------
    :class:`ArapOptions`, checked.

    Raises
    ------
    SShaDeError naming ``who``.
    """
    o = ArapOptions.of(options, who)
    o.refuse_unused(READS[who], who)
    if o.energy not in (SR_ENERGY, ArapOptions.energy):
        raise SShaDeError(f"{who} solves ARAP-SR's energy ({SR_ENERGY!r}), not {o.energy!r} "
                          "(solve_arap or arap_deform)")
    if problem is not None:
        backend = None if problem.solver is None else problem.solver.backend
        for name, mine, its in (("alpha", o.alpha, problem.alpha), ("alpha_scaling", o.alpha_scaling,
                                                                      problem.alpha_scaling)):
            if mine != its:
                raise SShaDeError(f"{who}: {name}={mine!r}, but the problem given was built with {its!r}")
        if o.linear_solver not in ("auto", backend):
            raise SShaDeError(f"{who}: linear_solver={o.linear_solver!r}, but the problem given factorised with "
                              f"{backend!r}")
    return o
