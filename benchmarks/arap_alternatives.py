"""Two other minimisers of the converged ARAP problem, counted in local steps against the
solver's L-BFGS; the record: benchmarks/records/arap_alternatives.md.

The ``ARAP`` baseline's problem (spokes energy, its unit frame, the rigid start, the
default criterion ``etol = 1e-7``, ``gtol = 1e-3``), minimised by

``newton_cg``, an inexact Newton method (Nocedal & Wright, Algorithm 7.1, with
Steihaug's stop on negative curvature):

* the outer iteration: Armijo backtracking from the unit step along the inner solution;
* the inner one: conjugate gradients on ``H d = -grad E``, preconditioned by the global
  step's matrix ``2 L_ff`` (one Cholesky factorisation, :class:`sshade.arap.linear.LaplacianSolver`),
  stopped at a relative preconditioned residual ``min(eta, sqrt(gnorm))`` or on a
  direction of non-positive curvature (then the last iterate, or that direction first);
* Hessian-vector products by a forward difference of the gradient
  (:meth:`sshade.arap.operators.ArapOperators.gradient` at the optimal rotations, the
  envelope theorem's gradient), step ``1e-7 |x| / |p|``.

``rotations``, L-BFGS over the per-cell rotations with the positions eliminated: the
reduced energy ``f(R) = min_U E(U, R) = E(U(R), R)``, ``U(R)`` the global step (one
Cholesky solve), its gradient in each rotation's tangent (``R_k <- exp([w_k]) R_k``) the
axial vector of ``2 (A - A^T)``, ``A = M_k(U(R)) R_k^T`` (the envelope theorem over ``U``);
the initial Hessian the identity scaled by the newest pair (Nocedal & Wright, eq. 7.20), or
``--block-diagonal`` each cell's ``2 (tr(A) I - sym(A))`` with its eigenvalues clamped
positive; Armijo backtracking along the geodesic. Its stopping test is the solver's, at
``U(R)`` with the optimal rotations ``R*(U(R))`` (one more local step per iteration).

Every gradient or energy evaluation costs one local step (the rotations), as one L-BFGS
iteration's does; the count reported is those local steps (and, for ``rotations``, also
one Cholesky solve each). The ``lbfgs`` line is :func:`sshade.arap.solve_arap` with
``threads=1`` on the same problem.

    python benchmarks/arap_alternatives.py --cases twisted_bar,bent_cylinder,lifted_plane
    python benchmarks/arap_alternatives.py --root /work/main/data/defaust --cases s00_p01 --max-evals 2600

Prints one JSON line per run (``--trace``: also one per outer iteration). Writes no file.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from sshade.arap import DEFAULT_CRITERION, ArapOptions, build_operators, solve_arap  # noqa: E402
from sshade.arap.criterion import gradient_norm  # noqa: E402
from sshade.arap.linear import LaplacianSolver  # noqa: E402
from sshade.arap.problems import CASES  # noqa: E402
from sshade.arap.rigid import rigid_fit  # noqa: E402
from sshade.mesh.unit_frame import unit_frame  # noqa: E402


def load_case(name: str, root: str | None):
    """``(V, F, handles, targets)`` of a synthetic case or a DeFAUST case ``sXX_pYY``."""
    if name in CASES:
        return CASES[name]()
    if root is None:
        raise SystemExit(f"error: {name!r} is not a synthetic case ({', '.join(CASES)}); DeFAUST cases need --root")
    from defaust.dataset import load
    sub, pose = int(name[1:3]), int(name[5:7])
    case = next(c for c in load(root, subjects=[sub], partial=True) if c.pose == pose)
    return case.V, case.F, case.handles, case.targets


class Problem:
    """The free vertices' energy, gradient and preconditioner of one ARAP problem (unit frame)."""

    def __init__(self, V, F, h, T):
        self.ops = build_operators(V, F, "spokes")
        self.h = np.asarray(h, np.int64)
        self.free = np.setdiff1d(np.arange(len(V)), self.h)
        Rr, t = rigid_fit(V[self.h], T)
        self.U = V @ Rr.T + t
        self.U[self.h] = T
        Lf = self.ops.L.tocsr()[self.free]
        self.L2 = (2.0 * Lf[:, self.free]).tocsr()
        self.lin = LaplacianSolver(Lf[:, self.free])
        self.c_fb = Lf[:, self.h] @ T
        self.mass, self.diag = self.ops.mass[self.free], self.ops.diag
        self.evals = 0

    def at(self, x):
        """Energy and free-row gradient at free positions ``x`` (n_f, 3): one local step."""
        U = self.U.copy()
        U[self.free] = x
        R, E = self.ops.rotations(U, return_energy=True, threads=1)
        self.evals += 1
        return E, 2.0 * (self.ops.L @ U - self.ops.rhs(R, threads=1))[self.free]

    def energy(self, x):
        U = self.U.copy()
        U[self.free] = x
        self.evals += 1
        return self.ops.energy(U)

    def precondition(self, r):
        """``(2 L_ff)^-1 r``."""
        return 0.5 * self.lin.solve(r)

    def gnorm(self, g):
        return gradient_norm(g, self.mass, self.diag)

    def converged(self, E, E_prev, g, trace_row: dict | None) -> tuple[float, bool]:
        """The solver's stopping test at energy ``E`` (previous ``E_prev``) and free-row
        gradient ``g``: ``(gnorm, met)``; ``trace_row`` printed with the energy and gnorm."""
        gn = self.gnorm(g)
        rel = (E_prev - E) / abs(E) if np.isfinite(E_prev) else np.inf
        if trace_row is not None:
            print(json.dumps({**trace_row, "evals": self.evals, "energy": E, "gnorm": gn}), flush=True)
        return gn, bool(rel < DEFAULT_CRITERION.etol and gn < DEFAULT_CRITERION.gtol)


def newton_cg(P: Problem, *, eta: float, max_cg: int, max_evals: int, trace: bool) -> dict:
    """Inexact Newton from the rigid start to the default criterion (or ``max_evals``)."""
    x = P.U[P.free].copy()
    E, g = P.at(x)
    E_prev, outer, neg, status = np.inf, 0, 0, "max_evals"
    while P.evals < max_evals:
        gn, met = P.converged(E, E_prev, g, {"outer": outer} if trace else None)
        if met:
            status = "converged"
            break
        d, hit_neg = _inner(P, x, g, eta=min(eta, np.sqrt(gn)), max_cg=max_cg)
        neg += hit_neg
        x = x + backtrack(P, x, E, d, float((g * d).sum())) * d
        E_prev = E
        E, g = P.at(x)
        outer += 1
    return {"status": status, "outer": outer, "negative_curvature_stops": neg, "evals": P.evals,
            "energy": E, "gnorm": P.gnorm(g)}


def _inner(P: Problem, x, g, *, eta: float, max_cg: int):
    """Preconditioned CG on ``H d = -g``; ``(d, stopped on non-positive curvature)``."""
    d = np.zeros_like(x)
    r = -g
    z = P.precondition(r)
    p = z.copy()
    rz0 = rz = float((r * z).sum())
    nx = np.sqrt((x * x).sum())
    for _ in range(max_cg):
        eps = 1e-7 * nx / np.sqrt((p * p).sum())
        Hp = (P.at(x + eps * p)[1] - g) / eps
        pHp = float((p * Hp).sum())
        if pHp <= 0:
            return (p if not d.any() else d), True
        a = rz / pHp
        d += a * p
        r -= a * Hp
        z = P.precondition(r)
        rz_new = float((r * z).sum())
        if np.sqrt(rz_new / rz0) <= eta:
            break
        p = z + (rz_new / rz) * p
        rz = rz_new
    return d, False


def _expmap(w):
    """Rotation matrices (k, 3, 3) of axis-angle vectors ``w`` (k, 3) (Rodrigues)."""
    th = np.linalg.norm(w, axis=1)
    K = np.zeros((len(w), 3, 3))
    K[:, 0, 1], K[:, 0, 2], K[:, 1, 2] = -w[:, 2], w[:, 1], -w[:, 0]
    K[:, 1, 0], K[:, 2, 0], K[:, 2, 1] = w[:, 2], -w[:, 1], w[:, 0]
    small = th < 1e-8
    t = np.where(small, 1.0, th)
    s = np.where(small, 1.0, np.sin(t) / t)
    c = np.where(small, 0.5, (1.0 - np.cos(t)) / (t * t))
    return np.eye(3) + s[:, None, None] * K + c[:, None, None] * (K @ K)


def _reduced(P: Problem, R):
    """``f(R)``, its tangent gradient (n, 3), ``U(R)`` and ``A = M(U(R)) R^T`` (one solve)."""
    U = P.U.copy()
    U[P.free] = P.lin.solve(P.ops.rhs(R, threads=1)[P.free] - P.c_fb)
    A = P.ops.covariances(U) @ R.transpose(0, 2, 1)
    P.evals += 1
    g = 2.0 * np.stack([A[:, 1, 2] - A[:, 2, 1], A[:, 2, 0] - A[:, 0, 2], A[:, 0, 1] - A[:, 1, 0]], 1)
    return P.ops.energy(U, R), g, U, A


def _h0(A, block: bool):
    """The initial inverse Hessian as a function of a tangent vector field (n, 3)."""
    if not block:
        return lambda v: v
    As = 0.5 * (A + A.transpose(0, 2, 1))
    H = 2.0 * (np.trace(A, axis1=1, axis2=2)[:, None, None] * np.eye(3) - As)
    lam, Q = np.linalg.eigh(H)
    lam = np.maximum(lam, 1e-3 * np.abs(lam).max(1, keepdims=True) + 1e-30)
    Hinv = (Q / lam[:, None, :]) @ Q.transpose(0, 2, 1)
    return lambda v: np.einsum("kab,kb->ka", Hinv, v)


def backtrack(P: Problem, x, E: float, d, slope: float) -> float:
    """Armijo backtracking from the unit step along ``d`` (slope ``g . d``): the step taken."""
    alpha = 1.0
    while True:
        if P.energy(x + alpha * d) <= E + 1e-4 * alpha * slope or alpha < 1e-10:
            return alpha
        alpha *= 0.5


def two_loop(S, Y, g, h0, scale: bool = True):
    """L-BFGS direction ``-H g`` (Nocedal & Wright, Algorithm 7.4, ``gamma h0``; ``gamma``
    from the newest pair, eq. 7.20, or 1 without ``scale``)."""
    q, al = g.copy(), []
    for s, y in reversed(list(zip(S, Y))):
        a = float((s * q).sum()) / float((s * y).sum())
        al.append(a)
        q -= a * y
    gamma = float((S[-1] * Y[-1]).sum()) / float((Y[-1] * h0(Y[-1])).sum()) if S and scale else 1.0
    r = gamma * h0(q)
    for (s, y), a in zip(zip(S, Y), reversed(al)):
        r += (a - float((y * r).sum()) / float((s * y).sum())) * s
    return -r


def descent(S, Y, g, h0, scale: bool = True):
    """``(d, g . d, S, Y)``: the L-BFGS direction, or ``-h0(g)`` with the history dropped
    when that is no descent direction."""
    d = two_loop(S, Y, g, h0, scale)
    slope = float((g * d).sum())
    if not slope < 0:
        S, Y = [], []
        d = -h0(g)
        slope = float((g * d).sum())
    return d, slope, S, Y


def push_pair(S, Y, s, y, m: int):
    """The history with the pair ``(s, y)`` added (kept ``m`` newest) when its curvature is positive."""
    if float((s * y).sum()) > 1e-12 * np.sqrt(float((s * s).sum()) * float((y * y).sum())):
        return (S + [s])[-m:], (Y + [y])[-m:]
    return S, Y


def rotations(P: Problem, *, m: int, block: bool, max_evals: int, trace: bool) -> dict:
    """L-BFGS over the rotations from the rigid start's local step to the solver's criterion."""
    R = P.ops.rotations(P.U, threads=1)
    f, g, U, A = _reduced(P, R)
    S, Y, E_prev, it, status = [], [], np.inf, 0, "max_evals"
    while P.evals < max_evals:
        E, gu = P.at(U[P.free])
        gn, met = P.converged(E, E_prev, gu, {"iteration": it} if trace else None)
        if met:
            status = "converged"
            break
        E_prev, h0 = E, _h0(A, block)
        d, slope, S, Y = descent(S, Y, g, h0)
        alpha = 1.0
        while True:
            R_new = _expmap(alpha * d) @ R
            f_new, g_new, U_new, A_new = _reduced(P, R_new)
            if f_new <= f + 1e-4 * alpha * slope or alpha < 1e-10:
                break
            alpha *= 0.5
        S, Y = push_pair(S, Y, alpha * d, g_new - g, m)
        R, f, g, U, A = R_new, f_new, g_new, U_new, A_new
        it += 1
    return {"status": status, "iterations": it, "evals": P.evals, "energy": E, "gnorm": gn}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cases", default="twisted_bar,bent_cylinder,lifted_plane",
                    help="comma-separated synthetic cases (sshade.arap.problems.CASES) or DeFAUST sXX_pYY")
    ap.add_argument("--root", help="a DeFAUST build, for sXX_pYY cases")
    ap.add_argument("--eta", type=float, default=0.5, help="largest relative residual of the inner solve")
    ap.add_argument("--max-cg", type=int, default=100, help="inner iterations per Newton step at most")
    ap.add_argument("--max-evals", type=int, default=5000, help="local steps of the Newton run at most")
    ap.add_argument("--methods", default="newton_cg,rotations,lbfgs",
                    help="comma-separated: newton_cg, rotations, lbfgs (the solver)")
    ap.add_argument("--block-diagonal", action="store_true", help="rotations: the per-cell initial Hessian")
    ap.add_argument("--trace", action="store_true", help="one line per outer iteration")
    a = ap.parse_args(argv)
    for name in a.cases.split(","):
        V0, F, h, T0 = load_case(name, a.root)
        frame = unit_frame(V0)
        V, T = frame.to_unit(V0), frame.to_unit(T0)
        methods = a.methods.split(",")
        for meth in ("newton_cg", "rotations"):
            if meth not in methods:
                continue
            t = time.perf_counter()
            row = {"case": name, "n": len(V), "method": meth}
            if meth == "newton_cg":
                row.update(eta=a.eta, max_cg=a.max_cg)
                row.update(newton_cg(Problem(V, F, h, T), eta=a.eta, max_cg=a.max_cg, max_evals=a.max_evals,
                                     trace=a.trace))
            else:
                row.update(block_diagonal=a.block_diagonal)
                row.update(rotations(Problem(V, F, h, T), m=10, block=a.block_diagonal, max_evals=a.max_evals,
                                     trace=a.trace))
            row["s"] = round(time.perf_counter() - t, 1)
            print(json.dumps(row), flush=True)
        if "lbfgs" in methods:
            t = time.perf_counter()
            r = solve_arap(V, F, h, T, ArapOptions(energy="spokes", threads=1))
            print(json.dumps({"case": name, "n": len(V), "method": "lbfgs", "status": r.info["status"],
                              "iterations": r.iterations, "evals": r.info["n_local"], "energy": r.info["energy"],
                              "gnorm": r.info["gnorm"], "s": round(time.perf_counter() - t, 1)}), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
