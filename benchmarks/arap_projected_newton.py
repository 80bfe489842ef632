"""Projected-Newton steps for the converged ARAP problem: the exact Hessian of the reduced
energy, projected cell by cell, as Newton's matrix or as L-BFGS's initial Hessian; counted
against the solver's L-BFGS. The record: benchmarks/records/arap_projected_newton.md.

The ``ARAP`` baseline's problem (spokes energy, its unit frame, the rigid start, the
default criterion ``etol = 1e-7``, ``gtol = 1e-3``; :class:`arap_alternatives.Problem`).
The reduced energy ``f(U) = min_R E(U, R) = sum_k f_k`` splits over the cells ``k``:
``f_k = sum_e a_ke ||e'_e||^2 - 2 sigma(M_k) + const``, ``M_k = sum_e a_ke e'_e e_e^T``,
``sigma(M) = max_R tr(R^T M)``. With ``M = R S`` (polar), ``d2 sigma = a^T (tr(S) I -
S)^-1 a``, ``a = axial(R^T dM - dM^T R)`` (the rotation's derivative, e.g. Chao et al.
2010 §4; Smith, de Goes & Kim 2019 for the eigen-structure), so the cell's Hessian over
its vertices is ``H_k = 2 L_k (x) I3 - 2 G_k^T W_k G_k``, ``W_k = (tr(S) I - S)^-1``,
``G_k`` the map from the cell's vertex moves to ``a``. Each ``H_k`` is projected to its
non-negative eigenvalues (Teran et al. 2005's per-element projection) and summed.

``newton``: Newton's step on the projected Hessian (one factorisation per iteration),
Armijo backtracking from the unit step. ``lbfgs_h``: L-BFGS (memory 10) with the
projected Hessian's factor as ``H0`` (scaled by the newest pair as Nocedal & Wright eq.
7.20), refactored every ``--refresh`` iterations (0: only at the start). ``lbfgs_2l``:
the same L-BFGS with the two-level ``H0`` of :class:`TwoLevel` (a Galerkin coarse level
of the exact Hessian over a remesh's P1 space, refreshed every ``--refresh``
iterations). ``lbfgs_mg``: the same L-BFGS with one symmetric two-level cycle on ``2 L_ff``
(:class:`LaplacianVCycle`: Jacobi sweeps and that P1 space's Galerkin coarse level) in place
of its factor. ``lbfgs_l``: the same L-BFGS with ``(2 L_ff)^-1`` (the solver's ``H0``).

    python benchmarks/arap_projected_newton.py --cases twisted_bar,bent_cylinder,lifted_plane
    python benchmarks/arap_projected_newton.py --faust /work/shared/data/faust_reg --cases s0_p3
    python benchmarks/arap_projected_newton.py --root /work/main/data/defaust --cases s00_p01
    python benchmarks/arap_projected_newton.py --root data/defaust --cases s00_p01 --methods lbfgs_mg --nc 6000 --nu 2

Prints one JSON line per run (``--trace``: one per iteration). Writes no file.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from functools import partial
from pathlib import Path

import numpy as np
import scipy.sparse as sp

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from arap_alternatives import Problem, backtrack, descent, load_case, push_pair  # noqa: E402  (this script's folder, as run)

from sshade.arap import ArapOptions, solve_arap  # noqa: E402
from sshade.arap.linear import LaplacianSolver  # noqa: E402
from sshade.mesh.unit_frame import unit_frame  # noqa: E402


def rotation_terms(ops, U, floor: float = 1e-12):
    """``W_k = (tr(S_k) I - S_k)^-1`` (n, 3, 3) and each pair's ``a_ke [e_e]x R_k^T``
    (p, 3, 3) at positions ``U`` (n, 3); eigenvalues of ``tr(S) I - S`` clamped to at
    least ``floor`` times the cell's largest."""
    R = ops.rotations(U, threads=1)
    S = R.transpose(0, 2, 1) @ ops.covariances(U)
    S = 0.5 * (S + S.transpose(0, 2, 1))
    lam, Q = np.linalg.eigh(np.trace(S, axis1=1, axis2=2)[:, None, None] * np.eye(3) - S)
    lam = np.maximum(lam, floor * np.maximum(np.abs(lam).max(1, keepdims=True), 1e-30))
    W = (Q / lam[:, None, :]) @ Q.transpose(0, 2, 1)
    ev = ops.edge_vec[ops.pair_edge]
    X = np.zeros((len(ev), 3, 3))  # [e]x
    X[:, 0, 1], X[:, 0, 2], X[:, 1, 2] = -ev[:, 2], ev[:, 1], -ev[:, 0]
    X[:, 1, 0], X[:, 2, 0], X[:, 2, 1] = ev[:, 2], -ev[:, 1], ev[:, 0]
    return W, ops.pair_w[:, None, None] * (X @ R[ops.pair_cell].transpose(0, 2, 1))


def free_dofs(P: Problem) -> np.ndarray:
    """(3 n,) int64: each coordinate ``3 v + c``'s index among the free coordinates, -1 at
    the handles' (vertex-major, as ``x.ravel()`` of the free positions)."""
    out = np.full(3 * P.ops.n, -1, np.int64)
    fd = (3 * P.free[:, None] + np.arange(3)).ravel()
    out[fd] = np.arange(len(fd))
    return out


class CellHessian:
    """The cells' vertex lists and the pairs' local indices of one :class:`Problem`."""

    def __init__(self, P: Problem):
        ops, n = P.ops, P.ops.n
        self.P = P
        e = ops.edges[ops.pair_edge]
        cell = ops.pair_cell
        keys = np.unique(np.concatenate([cell * n + e[:, 0], cell * n + e[:, 1]]))
        self.vcell, self.vert = keys // n, keys % n
        self.m = np.bincount(self.vcell, minlength=n)
        self.start = np.concatenate([[0], np.cumsum(self.m)[:-1]])
        self.ls = np.searchsorted(keys, cell * n + e[:, 0]) - self.start[cell]
        self.ld = np.searchsorted(keys, cell * n + e[:, 1]) - self.start[cell]
        self.free_dof = free_dofs(P)
        self.n_neg = 0
        self.project = True  # False: the exact (unprojected) Hessian, for checks

    def matrix(self, U: np.ndarray) -> sp.csc_matrix:
        """The projected Hessian over the free coordinates (3 n_f, 3 n_f), vertex-major."""
        W, Qp = rotation_terms(self.P.ops, U)
        rows, cols, vals, self.n_neg = [], [], [], 0
        for m in np.unique(self.m):
            r, c, v = self._group(m, W, Qp)
            rows.append(r), cols.append(c), vals.append(v)
        r, c, v = np.concatenate(rows), np.concatenate(cols), np.concatenate(vals)
        keep = (r >= 0) & (c >= 0)
        nf = 3 * len(self.P.free)
        return sp.csc_matrix((v[keep], (r[keep], c[keep])), shape=(nf, nf))

    def _group(self, m: int, W, Qp):
        """COO triplets of the projected Hessians of the cells with ``m`` vertices."""
        ops = self.P.ops
        cells = np.flatnonzero(self.m == m)
        loc = np.full(ops.n, -1, np.int64)
        loc[cells] = np.arange(len(cells))
        pk = loc[ops.pair_cell]
        sel = pk >= 0
        kl, ls, ld, a = pk[sel], self.ls[sel], self.ld[sel], ops.pair_w[sel]
        Lk = np.zeros((len(cells), m, m))
        for i, j, s in ((ls, ls, 1.0), (ld, ld, 1.0), (ls, ld, -1.0), (ld, ls, -1.0)):
            np.add.at(Lk, (kl, i, j), s * a)
        G = np.zeros((len(cells), m, 3, 3))
        np.add.at(G, (kl, ls), Qp[sel])
        np.add.at(G, (kl, ld), -Qp[sel])
        G = G.transpose(0, 2, 1, 3).reshape(len(cells), 3, 3 * m)
        H = 2.0 * np.kron(Lk, np.eye(3)) - 2.0 * G.transpose(0, 2, 1) @ W[cells] @ G
        lam, Q = np.linalg.eigh(H)
        self.n_neg += int((lam < -1e-12 * np.abs(lam).max(1, keepdims=True)).sum())
        if self.project:
            H = (Q * np.maximum(lam, 0.0)[:, None, :]) @ Q.transpose(0, 2, 1)
        verts = self.vert[self.start[cells][:, None] + np.arange(m)]
        dof = self.free_dof[(3 * verts[:, :, None] + np.arange(3)).reshape(len(cells), 3 * m)]
        r = np.broadcast_to(dof[:, :, None], H.shape).ravel()
        c = np.broadcast_to(dof[:, None, :], H.shape).ravel()
        return r, c, H.ravel()


def factor(CH: CellHessian, x, reg: float):
    """Factor of the projected Hessian at free positions ``x`` (plus ``reg`` times 2 L_ff)."""
    U = CH.P.U.copy()
    U[CH.P.free] = x
    t = time.perf_counter()
    H = CH.matrix(U)
    if reg > 0:
        H = H + reg * sp.kron(CH.P.L2, sp.eye(3), format="csc")
    t_build = time.perf_counter() - t
    f = LaplacianSolver(H)
    return (lambda g: f.solve(g.reshape(-1, 1)).reshape(g.shape)), t_build, f.factor_s, H.nnz


class HessianFactor:
    """The projected Hessian's factor as an initial inverse Hessian, refreshed on call."""

    def __init__(self, CH: CellHessian, reg: float):
        self.CH, self.reg, self.build_s, self.factor_s, self.nnz = CH, reg, 0.0, 0.0, 0

    def refresh(self, x) -> float:
        t = time.perf_counter()
        self.solve, b, fs, self.nnz = factor(self.CH, x, self.reg)
        self.build_s, self.factor_s = self.build_s + b, self.factor_s + fs
        return time.perf_counter() - t

    def apply(self, g):
        """``H^-1 g`` with the last factor."""
        return self.solve(g)


def newton(P: Problem, *, reg: float, max_iter: int, trace: bool) -> dict:
    """Projected Newton from the rigid start to the default criterion."""
    CH = CellHessian(P)
    x = P.U[P.free].copy()
    E, g = P.at(x)
    E_prev, it, status, tb, tf, nnz = np.inf, 0, "max_iter", 0.0, 0.0, 0
    while it < max_iter:
        gn, met = P.converged(E, E_prev, g, {"iteration": it} if trace else None)
        if met:
            status = "converged"
            break
        solve, b, fs, nnz = factor(CH, x, reg)
        tb, tf = tb + b, tf + fs
        d = -solve(g)
        x = x + backtrack(P, x, E, d, float((g * d).sum())) * d
        E_prev = E
        E, g = P.at(x)
        it += 1
    return {"status": status, "iterations": it, "evals": P.evals, "energy": E, "gnorm": P.gnorm(g),
            "build_s": round(tb, 2), "factor_s": round(tf, 2), "nnz": nnz, "neg_eigs_last": CH.n_neg}


class ExactHessian:
    """The reduced energy's exact (unprojected) Hessian ``2 L_ff (x) I3 - 2 G^T W G`` over
    the free coordinates as an operator, ``W`` and ``G`` taken at the last :meth:`refresh`."""

    def __init__(self, P: Problem, floor: float = 1e-12):
        self.P, self.free_dof, self.floor = P, free_dofs(P), floor
        self.L2k = sp.kron(P.L2, sp.eye(3), format="csr")

    def refresh(self, x) -> float:
        """Rebuild ``G`` (3 n, 3 n_f) and ``W`` (3 n, 3 n) at free positions ``x`` (n_f, 3)."""
        t = time.perf_counter()
        P, ops = self.P, self.P.ops
        U = P.U.copy()
        U[P.free] = x
        W, Qp = rotation_terms(ops, U, self.floor)
        e = ops.edges[ops.pair_edge]
        rows = (3 * ops.pair_cell[:, None, None] + np.arange(3)[None, :, None]) * np.ones((1, 1, 3), np.int64)
        parts = []
        for end, sgn in ((e[:, 0], 1.0), (e[:, 1], -1.0)):
            cols = self.free_dof[3 * end[:, None, None] + np.arange(3)[None, None, :]] * np.ones((1, 3, 1), np.int64)
            parts.append((rows.ravel(), cols.ravel(), sgn * Qp.ravel()))
        r, c, v = (np.concatenate(z) for z in zip(*parts))
        keep = c >= 0
        self.G = sp.csr_matrix((v[keep], (r[keep], c[keep])), shape=(3 * ops.n, 3 * len(P.free)))
        self.GT = self.G.T.tocsr()
        self.W = _block_diag(W)
        return time.perf_counter() - t

    def apply(self, v):
        """``H v`` for ``v`` (n_f, 3)."""
        f = v.ravel()
        return (self.L2k @ f - 2.0 * (self.GT @ (self.W @ (self.G @ f)))).reshape(v.shape)


def p1_interpolation(P: Problem, V, F, handles, nc: int, seed: int = 0):
    """The P1 interpolation (n_f, n_c) CSR from a remesh of ``(V, F)`` with ``nc`` samples
    (:func:`sshade.remesh.remesh`, the handles required) to the free vertices of ``P``:
    each free vertex's closest point on the remesh, its clipped barycentric weights."""
    import igl

    from sshade.remesh import remesh
    rm = remesh(V, F, nc, seed=seed, required=np.asarray(handles, np.int64))
    Vc, Fc = V[rm.seeds], np.asarray(rm.F, np.int64)
    _, fi, C = igl.point_mesh_squared_distance(V[P.free], Vc, Fc)
    T = Fc[fi]
    B = igl.barycentric_coordinates(C, Vc[T[:, 0]], Vc[T[:, 1]], Vc[T[:, 2]])
    B = np.clip(B, 0.0, None)
    B /= B.sum(1, keepdims=True)
    nf = len(P.free)
    return sp.csr_matrix((B.ravel(), (np.repeat(np.arange(nf), 3), T.ravel())), shape=(nf, len(Vc)))


class TwoLevel:
    """A two-level preconditioner of the reduced energy's exact Hessian: the fine level
    ``(2 L_ff)^-1`` (the global step's factor), the coarse level the Galerkin product
    ``P^T H P`` of the Hessian ``H = 2 L_ff (x) I3 - 2 G^T W G`` at the last refresh, over
    the P1 interpolation ``P`` from a remesh with ``nc`` samples (closest point,
    barycentric). Applied symmetric-multiplicatively: coarse, fine, coarse."""

    def __init__(self, P: Problem, V, F, handles, nc: int, seed: int = 0):
        self.P = P
        Pm = p1_interpolation(P, V, F, handles, nc, seed)
        self.nc = Pm.shape[1]
        self.Pk = sp.kron(Pm, sp.eye(3), format="csr")
        self.H = ExactHessian(P)
        self.PtL2P = (self.Pk.T @ self.H.L2k @ self.Pk).tocsc()
        self.shift = 0.0

    def refresh(self, x) -> float:
        """Rebuild ``H`` and the coarse factor at free positions ``x``; seconds taken."""
        t = time.perf_counter()
        self.H.refresh(x)
        GP = (self.H.G @ self.Pk).tocsr()
        Hc = (self.PtL2P - 2.0 * (GP.T @ self.H.W @ GP)).tocsc()
        Hc = 0.5 * (Hc + Hc.T)
        for mu in (0.0, 1e-3, 1e-2, 1e-1, 1.0, 10.0, 100.0, np.inf):
            A = self.PtL2P if mu == np.inf else Hc + mu * self.PtL2P
            try:
                self.fc = LaplacianSolver(A + 1e-12 * sp.eye(Hc.shape[0]))
            except Exception:
                continue
            self.shift = mu
            break
        return time.perf_counter() - t

    def hess(self, v):
        """``H v`` for ``v`` (n_f, 3)."""
        return self.H.apply(v)

    def coarse(self, r):
        rc = self.Pk.T @ r.ravel()
        return (self.Pk @ self.fc.solve(rc.reshape(-1, 1)).ravel()).reshape(r.shape)

    def apply(self, r, mode: str = "mult"):
        """The preconditioner on a residual ``r`` (n_f, 3)."""
        if mode == "add":
            return self.coarse(r) + self.P.precondition(r)
        z = self.coarse(r)
        z = z + self.P.precondition(r - self.hess(z))
        return z + self.coarse(r - self.hess(z))


class LaplacianVCycle:
    """An approximate ``(2 L_ff)^-1``: one symmetric two-level cycle on ``A = 2 L_ff`` (``nu``
    damped-Jacobi sweeps, the Galerkin coarse correction ``P (P^T A P)^-1 P^T`` over the
    P1 space of a remesh with ``nc`` samples, ``nu`` sweeps back), the global step's matrix
    without its factor (Xian, Tong & Liu 2019 solve it by a Galerkin multigrid). Damping
    ``omega = 1 / lambda_max(D^-1 A)`` (power iteration), so the cycle is SPD and a valid
    L-BFGS ``H0``; ``cycles`` cycles per application."""

    def __init__(self, P: Problem, V, F, handles, nc: int, nu: int = 2, cycles: int = 1, seed: int = 0):
        self.A = P.L2
        Pm = p1_interpolation(P, V, F, handles, nc, seed).tocsc()
        used = np.flatnonzero(np.asarray(abs(Pm).sum(0)).ravel() > 1e-12)  # a coarse handle may reach no free vertex
        self.Pm = Pm[:, used].tocsr()
        self.nc, self.nu, self.cycles = len(used), nu, cycles
        Ac = (self.Pm.T @ self.A @ self.Pm).tocsc()
        self.fc = LaplacianSolver(Ac + 1e-10 * Ac.diagonal().mean() * sp.eye(Ac.shape[0]))
        dinv = 1.0 / self.A.diagonal()
        v = np.random.default_rng(seed).standard_normal(self.A.shape[0])
        for _ in range(50):
            v = dinv * (self.A @ v)
            lam = np.linalg.norm(v)
            v /= lam
        self.omega_dinv = (1.0 / (1.05 * lam)) * dinv[:, None]

    def apply(self, r):
        """The cycle(s) on a residual ``r`` (n_f, 3); zero start."""
        A, z = self.A, np.zeros_like(r)
        for _ in range(self.cycles):
            for _ in range(self.nu):
                z = z + self.omega_dinv * (r - A @ z)
            z = z + self.Pm @ self.fc.solve(self.Pm.T @ (r - A @ z))
            for _ in range(self.nu):
                z = z + self.omega_dinv * (r - A @ z)
        return z


def _block_diag(W):
    """Block-diagonal CSR of the (k, 3, 3) blocks ``W``."""
    k = len(W)
    r = (3 * np.arange(k)[:, None, None] + np.arange(3)[None, :, None]) * np.ones((1, 1, 3), np.int64)
    c = (3 * np.arange(k)[:, None, None] + np.arange(3)[None, None, :]) * np.ones((1, 3, 1), np.int64)
    return sp.csr_matrix((W.ravel(), (r.ravel(), c.ravel())), shape=(3 * k, 3 * k))


def lbfgs_pc(P: Problem, h0, *, refresh_fn=None, refresh: int = 0, max_iter: int, m: int, trace: bool,
             scale: bool = True) -> dict:
    """L-BFGS (memory ``m``) with initial inverse Hessian ``h0``; ``refresh_fn(x)`` every
    ``refresh`` iterations (and at the start) when given."""
    x = P.U[P.free].copy()
    E, g = P.at(x)
    S, Y, E_prev, it, status, tr, nr = [], [], np.inf, 0, "max_iter", 0.0, 0
    while it < max_iter:
        gn, met = P.converged(E, E_prev, g, {"iteration": it} if trace else None)
        if met:
            status = "converged"
            break
        if refresh_fn is not None and (it == 0 or (refresh and it % refresh == 0)):
            tr, nr = tr + refresh_fn(x), nr + 1
        d, slope, S, Y = descent(S, Y, g, h0, scale)
        alpha = 1.0
        while True:
            E_try, g_try = P.at(x + alpha * d)
            if E_try <= E + 1e-4 * alpha * slope or alpha < 1e-10:
                break
            alpha *= 0.5
        S, Y = push_pair(S, Y, alpha * d, g_try - g, m)
        x, E_prev, E, g = x + alpha * d, E, E_try, g_try
        it += 1
    return {"status": status, "iterations": it, "evals": P.evals, "energy": E, "gnorm": P.gnorm(g),
            "refreshes": nr, "refresh_s": round(tr, 2)}


def faust_case(root: str, name: str):
    from eval.datasets.faust import FaustOptions, faust_cases
    sub, pose = int(name[1:name.index("_")]), int(name[name.index("_p") + 2:])
    c = faust_cases(root, FaustOptions(root=root, subjects=[sub], poses=[pose]))[0]
    return c.V, c.F, c.handles, c.targets


def unit_case(name: str, faust: str | None, root: str | None):
    """``(V, F, handles, targets)`` of a FAUST (``faust``), DeFAUST (``root``) or
    synthetic case, in the mesh's unit frame."""
    V0, F, h, T0 = faust_case(faust, name) if faust else load_case(name, root)
    frame = unit_frame(V0)
    return frame.to_unit(V0), F, h, frame.to_unit(T0)


def solver_row(V, F, h, T) -> dict:
    """The solver's L-BFGS (``solve_arap``, spokes, one thread) on the case: its row's fields."""
    r = solve_arap(V, F, h, T, ArapOptions(energy="spokes", threads=1))
    return {"status": r.info["status"], "iterations": r.iterations, "evals": r.info["n_local"],
            "energy": r.info["energy"], "gnorm": r.info["gnorm"]}


def case_arguments(ap: argparse.ArgumentParser) -> None:
    """Add ``--cases``, ``--root`` and ``--faust`` (what :func:`run_cases` reads) to ``ap``."""
    ap.add_argument("--cases", default="twisted_bar,bent_cylinder,lifted_plane",
                    help="comma-separated synthetic cases, DeFAUST sXX_pYY (--root) or FAUST sN_pM (--faust)")
    ap.add_argument("--root", help="a DeFAUST build, for sXX_pYY cases")
    ap.add_argument("--faust", help="a folder of FAUST registrations, for sN_pM cases")


def run_cases(a, run_one) -> None:
    """Each of ``a.cases`` (``a.faust``, ``a.root``) and ``a.methods``: ``run_one(meth, V, F,
    h, T, row)`` fills the row, or the solver's L-BFGS for ``lbfgs``; one JSON line each."""
    for name in a.cases.split(","):
        V, F, h, T = unit_case(name, a.faust, a.root)
        for meth in a.methods.split(","):
            t = time.perf_counter()
            row = {"case": name, "n": len(V), "method": meth}
            row.update(solver_row(V, F, h, T) if meth == "lbfgs" else run_one(meth, V, F, h, T, row))
            row["s"] = round(time.perf_counter() - t, 2)
            print(json.dumps(row), flush=True)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    case_arguments(ap)
    ap.add_argument("--methods", default="newton,lbfgs_h,lbfgs",
                    help="comma-separated: newton, lbfgs_h, lbfgs_2l, lbfgs_mg, lbfgs_l (this script's L-BFGS), "
                         "lbfgs (the solver)")
    ap.add_argument("--refresh", type=int, default=0, help="lbfgs_h: refactor every N iterations (0: never)")
    ap.add_argument("--reg", type=float, default=0.0, help="add reg * 2 L_ff to the projected Hessian")
    ap.add_argument("--max-iter", type=int, default=3000, help="iterations per run at most")
    ap.add_argument("--nc", type=int, default=1000, help="lbfgs_2l: coarse samples")
    ap.add_argument("--nu", type=int, default=2, help="lbfgs_mg: Jacobi sweeps before and after the coarse level")
    ap.add_argument("--cycles", type=int, default=1, help="lbfgs_mg: two-level cycles per H0 application")
    ap.add_argument("--mode", default="mult", help="lbfgs_2l: mult (coarse-fine-coarse) or add")
    ap.add_argument("--no-scale", action="store_true", help="lbfgs_2l / lbfgs_l: no gamma scaling of H0")
    ap.add_argument("--trace", action="store_true", help="one JSON line per iteration")
    a = ap.parse_args(argv)
    def run_one(meth, V, F, h, T, row):
        if meth == "newton":
            row.update(reg=a.reg, **newton(Problem(V, F, h, T), reg=a.reg, max_iter=a.max_iter, trace=a.trace))
        elif meth == "lbfgs_h":
            P = Problem(V, F, h, T)
            H0 = HessianFactor(CellHessian(P), a.reg)
            row.update(reg=a.reg, refresh=a.refresh,
                       **lbfgs_pc(P, H0.apply, refresh_fn=H0.refresh, refresh=a.refresh,
                                  max_iter=a.max_iter, m=10, trace=a.trace))
            row.update(build_s=round(H0.build_s, 2), factor_s=round(H0.factor_s, 2), nnz=H0.nnz,
                       neg_eigs_last=H0.CH.n_neg)
        elif meth == "lbfgs_l":
            P = Problem(V, F, h, T)
            row.update(scale=not a.no_scale, **lbfgs_pc(P, P.precondition, max_iter=a.max_iter, m=10,
                                                        trace=a.trace, scale=not a.no_scale))
        elif meth == "lbfgs_mg":
            P = Problem(V, F, h, T)
            t0 = time.perf_counter()
            MG = LaplacianVCycle(P, V, F, h, a.nc, nu=a.nu, cycles=a.cycles)
            row.update(nc=MG.nc, nu=a.nu, cycles=a.cycles, scale=not a.no_scale,
                       setup_s=round(time.perf_counter() - t0, 2))
            row.update(lbfgs_pc(P, MG.apply, max_iter=a.max_iter, m=10, trace=a.trace, scale=not a.no_scale))
        elif meth == "lbfgs_2l":
            P = Problem(V, F, h, T)
            t0 = time.perf_counter()
            TL = TwoLevel(P, V, F, h, a.nc)
            row.update(nc=TL.nc, mode=a.mode, refresh=a.refresh, scale=not a.no_scale,
                       setup_s=round(time.perf_counter() - t0, 2))
            row.update(lbfgs_pc(P, partial(TL.apply, mode=a.mode), refresh_fn=TL.refresh, refresh=a.refresh,
                                max_iter=a.max_iter, m=10, trace=a.trace, scale=not a.no_scale))
            row["shift_last"] = TL.shift
        else:
            raise SystemExit(f"error: --methods: unknown method {meth!r}")
        return row

    run_cases(a, run_one)
    return 0


if __name__ == "__main__":
    sys.exit(main())
