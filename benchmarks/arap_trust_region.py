"""Trust-region Newton-CG for the converged ARAP problem on the reduced energy's exact,
unprojected Hessian (matrix-free), counted against the solver's L-BFGS. The record:
benchmarks/records/arap_trust_region.md.

The ``ARAP`` baseline's problem (:class:`arap_alternatives.Problem`: spokes energy, its
unit frame, the rigid start, the default criterion ``etol = 1e-7``, ``gtol = 1e-3``). Each
outer iteration takes the Hessian ``H = 2 L_ff (x) I3 - 2 G^T W G`` at the current point
(:class:`arap_projected_newton.ExactHessian`, no eigenvalue projection, so the slivers'
negative curvature is kept) and minimises the quadratic model inside a trust region by
Steihaug-Toint conjugate gradients (Nocedal & Wright, Algorithm 7.2; Conn, Gould & Toint
2000, Algorithm 7.5.1), preconditioned by the global step's ``2 L_ff`` (one Cholesky
factor, :class:`sshade.arap.linear.LaplacianSolver`), the region measured in that
matrix's norm (the recurrences of Gould, Lucidi, Roma & Toint 1999). Negative curvature is
followed to the region's boundary instead of stopping the inner solve. The inner solve
stops at a relative preconditioned residual ``min(eta, sqrt(gnorm))``. The step is taken
when the actual decrease is at least ``1e-4`` of the model's; the radius is quartered
below a ratio of 1/4 and doubled above 3/4 on the boundary (Nocedal & Wright, Algorithm 4.1).

One outer iteration costs one local step (the energy and gradient at the trial point) and
one more to rebuild ``W`` and ``G`` after an accepted step; one inner iteration costs one
Laplacian solve (three right-hand sides) and one Hessian product (three sparse products).
An L-BFGS iteration costs one local step, one Laplacian solve and the two-loop recursion.

    python benchmarks/arap_trust_region.py --cases twisted_bar,bent_cylinder,lifted_plane
    python benchmarks/arap_trust_region.py --faust /work/shared/data/faust_reg --cases s0_p3
    python benchmarks/arap_trust_region.py --root /work/main/data/defaust --cases s00_p01

Prints one JSON line per run (``--trace``: also one per outer iteration). Writes no file.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from arap_alternatives import Problem  # noqa: E402  (this script's folder, as run)
from arap_projected_newton import ExactHessian, case_arguments, run_cases  # noqa: E402


def _to_boundary(sMs: float, sMp: float, pMp: float, radius: float) -> float:
    """The positive ``tau`` with ``||s + tau p||_M = radius``."""
    disc = max(sMp * sMp + pMp * (radius * radius - sMs), 0.0)
    return (-sMp + np.sqrt(disc)) / pMp


def steihaug(g, hess, precondition, radius: float, eta: float, max_cg: int):
    """Steihaug-Toint CG on the model ``g.s + s.H s / 2`` in the ``M``-norm ball of
    ``radius``: ``(s, model decrease (<= 0), inner iterations, why it stopped)``.

    ``g`` (n_f, 3); ``hess(p)`` is ``H p``; ``precondition(r)`` is ``M^-1 r``."""
    s = np.zeros_like(g)
    r = g.copy()
    z = precondition(r)
    p = -z
    rz = float((r * z).sum())
    rz0, sMs, sMp, pMp, m = rz, 0.0, 0.0, rz, 0.0
    for j in range(max_cg):
        Hp = hess(p)
        kappa = float((p * Hp).sum())
        rp = float((r * p).sum())
        if kappa <= 0:
            tau = _to_boundary(sMs, sMp, pMp, radius)
            return s + tau * p, m + tau * rp + 0.5 * tau * tau * kappa, j + 1, "negative_curvature"
        alpha = rz / kappa
        sMs_new = sMs + 2 * alpha * sMp + alpha * alpha * pMp
        if sMs_new >= radius * radius:
            tau = _to_boundary(sMs, sMp, pMp, radius)
            return s + tau * p, m + tau * rp + 0.5 * tau * tau * kappa, j + 1, "boundary"
        s = s + alpha * p
        m += alpha * rp + 0.5 * alpha * alpha * kappa
        r = r + alpha * Hp
        z = precondition(r)
        rz_new = float((r * z).sum())
        if np.sqrt(max(rz_new, 0.0) / rz0) <= eta:
            return s, m, j + 1, "residual"
        beta = rz_new / rz
        sMs, sMp = sMs_new, beta * (sMp + alpha * pMp)
        pMp = rz_new + beta * beta * pMp
        p = -z + beta * p
        rz = rz_new
    return s, m, max_cg, "max_cg"


def trust_region(P: Problem, *, eta: float, max_cg: int, max_outer: int, trace: bool, floor: float = 1e-12,
                 grow: float = 2.0) -> dict:
    """Trust-region Newton-CG from the rigid start to the solver's criterion."""
    H = ExactHessian(P, floor)
    x = P.U[P.free].copy()
    E, g = P.at(x)
    H.refresh(x)
    P.evals += 1
    radius = np.sqrt(float((g * P.precondition(g)).sum()))
    E_prev, outer, inner, status, stops, rejected = np.inf, 0, 0, "max_outer", {}, 0
    while outer < max_outer:
        gn, met = P.converged(E, E_prev, g, {"outer": outer, "inner": inner, "radius": radius} if trace else None)
        if met:
            status = "converged"
            break
        s, dm, k, why = steihaug(g, H.apply, P.precondition, radius, min(eta, np.sqrt(gn)), max_cg)
        inner, stops[why], outer = inner + k, stops.get(why, 0) + 1, outer + 1
        E_try, g_try = P.at(x + s)
        rho = (E_try - E) / dm if dm < 0 else -1.0
        if rho < 0.25:
            radius *= 0.25
        elif rho > 0.75 and why in ("boundary", "negative_curvature"):
            radius *= grow
        if rho > 1e-4:
            x, E_prev, E, g = x + s, E, E_try, g_try
            H.refresh(x)
            P.evals += 1
        else:
            rejected += 1
    return {"status": status, "outer": outer, "inner": inner, "rejected": rejected, "stops": stops,
            "evals": P.evals, "energy": E, "gnorm": P.gnorm(g)}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    case_arguments(ap)
    ap.add_argument("--methods", default="trust_region,lbfgs", help="comma-separated: trust_region, lbfgs (the solver)")
    ap.add_argument("--eta", type=float, default=0.5, help="largest relative residual of the inner solve")
    ap.add_argument("--max-cg", type=int, default=200, help="inner iterations per outer one at most")
    ap.add_argument("--max-outer", type=int, default=500, help="outer iterations at most")
    ap.add_argument("--floor", type=float, default=1e-12,
                    help="clamp each cell's tr(S) I - S eigenvalues to at least this times its largest")
    ap.add_argument("--grow", type=float, default=2.0, help="the radius's factor after a good boundary step")
    ap.add_argument("--trace", action="store_true", help="one JSON line per outer iteration")
    a = ap.parse_args(argv)
    def run_one(meth, V, F, h, T, row):
        if meth != "trust_region":
            raise SystemExit(f"error: --methods: unknown method {meth!r}")
        row.update(eta=a.eta, max_cg=a.max_cg, floor=a.floor, grow=a.grow)
        return trust_region(Problem(V, F, h, T), eta=a.eta, max_cg=a.max_cg, max_outer=a.max_outer,
                            trace=a.trace, floor=a.floor, grow=a.grow)

    run_cases(a, run_one)
    return 0


if __name__ == "__main__":
    sys.exit(main())
