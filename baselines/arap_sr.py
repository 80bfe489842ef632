"""ARAP-SR: as-rigid-as-possible with smooth rotations (Levi & Gotsman 2015,
"Smooth rotation enhanced as-rigid-as-possible mesh animation", IEEE TVCG).

Energy (spokes, cotangent weights w_ij, A = total surface area):

    E = sum_i sum_{j in N(i)} w_ij || e'_ij - R_i e_ij ||^2
        + alpha * A * sum_i sum_{j in N(i)} || R_i - R_j ||_F^2

Local step: each R_i maximises tr(R_i^T M_i) with
M_i = sum_j w_ij e'_ij e_ij^T + 2 alpha A sum_j R_j (neighbours' rotations from the
previous iteration), i.e. R_i = polar(M_i) (batched SVD, det fixed to +1).
Global step: the cotangent Laplacian system of ARAP with the handles fixed, prefactored
once (SuperLU, COLAMD ordering). At alpha = 0 this is ARAP (spokes, Sorkine & Alexa 2007).
Written on libigl's cotangent matrix because no maintained Python package offers the
smoothed energy (Open3D's ``deform_as_rigid_as_possible`` has a "smoothed" ARAP variant,
but it is a 300+ MB dependency for one baseline).
"""
from __future__ import annotations

import time

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu

from sshade.arap import PROTOCOLS, ArapResult, iterate, make_criterion, rigid_fit
from sshade.errors import SShaDeError
from sshade.mesh.validate import validate_handles, validate_mesh
from sshade.warmup import WARMED, warm_once

from .arap import check_arap_args
from .arap_sr_solver import solve_arap_sr
from .coarse_start import SR_ENERGY, check_start, start_rotations

__all__ = ["arap_sr_deform", "ARAPSR"]


def _polar(M: np.ndarray) -> np.ndarray:
    """Closest rotations to a batch of 3x3 matrices (k, 3, 3)."""
    U, _, Vt = np.linalg.svd(M)
    R = U @ Vt
    neg = np.linalg.det(R) < 0
    if neg.any():
        U[neg, :, 2] *= -1
        R[neg] = U[neg] @ Vt[neg]
    return R


def arap_sr_deform(V: np.ndarray, F: np.ndarray, handles: np.ndarray, targets: np.ndarray, *,
                   alpha: float = 0.01, tol: float = 1e-4, max_iter: int = 1000,
                   V0: np.ndarray | None = None, time_budget_s: float | None = None) -> ArapResult:
    """ARAP with smooth rotations under the paper's §4.1 move rule (``arap.protocol=paper``;
    the converged protocol is :func:`baselines.arap_sr_solver.solve_arap_sr`).

    Parameters
    ----------
    V : (n, 3) float64; F : (m, 3) int64 (validated). handles : (h,) int64;
    targets : (h, 3) float64.
    alpha : float >= 0, rotation-smoothness weight (multiplied by the surface area A so
        it is scale-free); 0 gives plain ARAP (spokes).
    tol, max_iter : stop when the largest vertex move in one iteration is below
        ``tol * bbox_diag``, at most ``max_iter`` iterations.
    V0 : (n, 3) initial guess, default the rigid fit of the handles.
    time_budget_s : optional cap on iteration time (benchmarks).

    Returns
    -------
    :class:`sshade.arap.ArapResult`.

    Examples
    --------
    Example::

        res = arap_sr_deform(V, F, handles, targets, alpha=0.01)
    """
    import igl
    V = np.ascontiguousarray(V, np.float64)
    F = np.ascontiguousarray(F, np.int64)
    n = len(V)
    diag = float(np.linalg.norm(V.max(0) - V.min(0)))
    R0, t0_ = rigid_fit(V[handles], targets)
    if float(np.abs(V[handles] @ R0.T + t0_ - targets).max()) <= 1e-12 * diag:
        return ArapResult(V=V @ R0.T + t0_, iterations=0, converged=True, last_move=0.0, precompute_s=0.0,
                          solve_s=0.0, info={"rigid": True})
    t0 = time.perf_counter()
    L = -igl.cotmatrix(V, F).tocsr()  # positive semi-definite, L_ij = -w_ij off-diagonal
    W = (-L).tocoo()
    off = W.row != W.col
    I, J, w = W.row[off], W.col[off], W.data[off]  # directed spokes i -> j with weight w_ij
    A = 0.5 * np.linalg.norm(np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]), axis=1).sum()
    e = V[J] - V[I]  # rest spokes e_ij
    free = np.ones(n, bool)
    free[handles] = False
    fi = np.flatnonzero(free)
    Lff = L[fi][:, fi].tocsc()
    Lfb = L[fi][:, handles]
    lu = splu(Lff, permc_spec="COLAMD")
    # incidence for sums over spokes of vertex i: S (n x nnz) with S[i, k] = 1 for spoke k = (I[k], J[k])
    S = sp.csr_matrix((np.ones(len(I)), (I, np.arange(len(I)))), shape=(n, len(I)))
    Adj = sp.csr_matrix((np.ones(len(I)), (I, J)), shape=(n, n))
    t1 = time.perf_counter()
    U = (V @ R0.T + t0_) if V0 is None else np.array(V0, np.float64)
    U[handles] = targets
    R = np.broadcast_to(R0, (n, 3, 3)).copy()

    def step(U):
        nonlocal R
        # local step
        ed = U[J] - U[I]
        cov = (w[:, None, None] * ed[:, :, None] * e[:, None, :]).reshape(-1, 9)  # w e' e^T
        M = (S @ cov).reshape(n, 3, 3)
        if alpha > 0:
            M += 2.0 * alpha * A * (Adj @ R.reshape(n, 9)).reshape(n, 3, 3)
        R = _polar(M)
        # global step: L x = b, b_i = sum_j w_ij / 2 (R_i + R_j) e_ij (as in Sorkine & Alexa eq. 9,
        # with e_ij = v_j - v_i)
        rot_e = 0.5 * np.einsum("kab,kb->ka", R[I] + R[J], e)
        b = -(S @ (w[:, None] * rot_e))  # sign: L = -cot (PSD) and e_ij = v_j - v_i
        Un = U.copy()
        Un[fi] = lu.solve(b[fi] - Lfb @ targets)
        Un[handles] = targets
        return Un

    U, it, converged, move = iterate(step, U, thresh=tol * diag, max_iter=max_iter, time_budget_s=time_budget_s)
    t2 = time.perf_counter()
    return ArapResult(V=U, iterations=it, converged=converged, last_move=move, precompute_s=t1 - t0,
                      solve_s=t2 - t1, info={"alpha": alpha})


class ARAPSR:
    """ARAP-SR baseline behind the :class:`sshade.method.Deformer` interface.

    Parameters
    ----------
    alpha : float >= 0, rotation smoothness (times the surface area).
    protocol : ``"converged"`` (default, ``info["protocol"] = "converged-sr"``:
        :func:`baselines.arap_sr_solver.solve_arap_sr`, Gauss-Seidel local step and
        Anderson acceleration, stopped by the energy-and-gradient criterion ``etol`` /
        ``gtol``) or ``"paper"`` (:func:`arap_sr_deform`,
        the §4.1 move rule ``tol``; ``info["protocol"] = "move-rule"``).
    tol : float > 0, ``"paper"``: move tolerance (fraction of the bounding-box diagonal).
    max_iter : int or None, iteration cap (None: 10000 converged, 1000 paper).
    etol, gtol : floats or None, the ``"converged"`` criterion (None: the defaults of
        :data:`sshade.arap.DEFAULT_CRITERION`).
    start : ``"converged"`` protocol's start: ``"rigid"`` (the rigid fit of the handles),
        ``"coarse"`` (:func:`baselines.coarse_start.coarse_start`: the rotations of the
        same energy solved on a ``coarse_n_low``-vertex remesh), ``"auto"`` (default:
        coarse when the mesh has at least ``COARSE_MIN_RATIO * coarse_n_low`` vertices,
        falling back to rigid if the remesh or the low-res solve raises SShaDeError).
        Either start is stopped by the same full-resolution criterion (issue 21).
    coarse_n_low : int >= 4, the remesh's sample count for the coarse start.

    Raises
    ------
    SShaDeError on a bad value.
    """

    name = "ARAP-SR"

    def __init__(self, *, alpha: float = 0.01, tol: float = 1e-4, max_iter: int | None = None,
                 protocol: str = "converged", etol: float | None = None, gtol: float | None = None,
                 start: str = "auto", coarse_n_low: int = 6000):
        if protocol not in PROTOCOLS:
            raise SShaDeError(f"{self.name}: unknown protocol {protocol!r}; use one of {PROTOCOLS}")
        self.start, self.coarse_n_low = check_start(self.name, start, coarse_n_low)
        args = check_arap_args(self.name, tol, max_iter, etol, gtol, alpha=alpha)  # SShaDeError on a bad value
        self.alpha, self.tol, self.protocol = args["alpha"], args["tol"], protocol
        self.max_iter = ({"converged": 10000, "paper": 1000}[protocol] if args["max_iter"] is None
                         else args["max_iter"])
        self.criterion = make_criterion(etol, gtol)
        self.info: dict = {}
        #: (n, 3, 3) float64 or None: the rotations of the last converged-protocol result
        #: (its reduced energy and a reference's continued solve start there; not in ``info``,
        #: which is stored as JSON)
        self.rotations: np.ndarray | None = None

    def deform(self, V, F, handles, targets) -> np.ndarray:
        """Deform ``(V, F)`` so ``V[handles]`` reach ``targets``; (n, 3) float64.
        Raises ``SShaDeError`` on invalid mesh or handles."""
        self.rotations = None
        V, F = validate_mesh(V, F)
        handles, targets = validate_handles(V, handles, targets)
        if self.protocol == "paper":
            res = arap_sr_deform(V, F, handles, targets, alpha=self.alpha, tol=self.tol, max_iter=self.max_iter)
        else:
            res = self._converged(V, F, handles, targets)
        self.rotations = res.info.get("R") if self.protocol == "converged" else None
        proto = "move-rule" if self.protocol == "paper" else "converged-sr"
        self.info = {"iterations": res.iterations, "converged": res.converged, "protocol": proto,
                     "precompute_s": res.precompute_s, "solve_s": res.solve_s, "alpha": self.alpha,
                     "s_per_iter": res.solve_s / max(res.iterations, 1)}
        for k in ("status", "energy", "gnorm", "rel_decrease", "n_fallback", "coarse_n", "coarse_iterations",
                  "coarse_s"):
            if k in res.info:
                self.info[k] = res.info[k]
        return res.V

    def _converged(self, V, F, handles, targets):
        """The converged protocol from the start of ``self.start``
        (:func:`baselines.coarse_start.start_rotations`); a coarse start's seconds count in
        ``precompute_s`` and its numbers go to ``info``."""
        R0, cinfo = start_rotations(self.start, V, F, handles, targets, energy=SR_ENERGY, alpha=self.alpha,
                                    coarse_n_low=self.coarse_n_low, criterion=self.criterion)
        res = solve_arap_sr(V, F, handles, targets, alpha=self.alpha, criterion=self.criterion,
                            max_iter=self.max_iter, R0=R0)
        if cinfo:
            res.precompute_s += cinfo["remesh_s"] + cinfo["coarse_s"]
            res.info.update(cinfo)
        return res

    def warmup(self, n_vertices: int | None = None) -> float:
        """First-call costs (libigl, the linear solver, the polar and energy kernels, mesh
        validation, the remesh of a coarse start) paid once on a tiny mesh outside any timed call
        (:func:`sshade.warmup.warm_once`); ``n_vertices`` is ignored. Returns the seconds
        spent."""
        coarse = self.protocol == "converged" and self.start != "rigid"  # + the remesh's kernels
        return warm_once(WARMED, ("arap_sr", self.protocol, coarse),
                         lambda V, F, h, T: ARAPSR(alpha=self.alpha, max_iter=5, protocol=self.protocol,
                                                   start="coarse" if coarse else "rigid",
                                                   coarse_n_low=40).deform(V, F, h, T))
