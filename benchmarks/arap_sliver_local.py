"""Converged full-resolution ARAP (spokes, the ``ARAP`` baseline's energy and default
criterion) with exact local solves on the sliver cells between L-BFGS passes: where the
gradient norm of the slow stretch and the tail sits, and whether block-coordinate
minimisation there shortens them. A one-off experiment (no product code changed); the
record: benchmarks/records/arap_sliver_local.md.

* ``--diagnose``: the baseline's solve (rigid start, ``threads=1``), and at the iterations
  of ``--snapshots`` the split of ``gnorm**2`` (a sum over free vertices of
  ``||g_i||**2 / (4 m_i)``, :func:`sshade.arap.criterion.gradient_norm`) over its largest
  vertices and over the sliver set ``S``.
* otherwise: the same solve, stopped every ``--every`` iterations from ``--from`` to
  ``--until``; each stop solves ``S`` exactly with everything else fixed, then the
  L-BFGS continues with its curvature pairs kept (``ArapSolver.solve(carry_history=True)``).

``S``: the vertices at an edge of negative cotangent weight (libigl's weights on obtuse
triangles), grown by ``--rings`` rings. The local problem is the submesh of the faces at
``S`` and its neighbours, the neighbours and the rest of the submesh as handles at their
current positions: every cell whose energy depends on ``S`` is then complete in it, so its
energy is the fine energy up to a constant (checked at the first local solve). The cost is
counted as fine iterations plus the local iterations weighted by (submesh vertices / fine
vertices).

    python benchmarks/arap_sliver_local.py --root /work/main/data/defaust --diagnose
    python benchmarks/arap_sliver_local.py --root /work/main/data/defaust --every 25

Prints one JSON line per run and per local solve; writes no file.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
import scipy.sparse as sp

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the repository, as the other benchmarks

from arap_hierarchy import defaust_case  # noqa: E402  (this script's folder, as run)

from sshade.arap import DEFAULT_CRITERION, ArapOptions, ArapSolver, build_operators  # noqa: E402
from sshade.arap.criterion import Criterion  # noqa: E402
from sshade.mesh.unit_frame import unit_frame  # noqa: E402

ENERGY = "spokes"
BASELINE_ENERGY = -0.02981296188  # s00_p01, rigid start, threads=1 (arap_hierarchy.md), mesh units


def sliver_set(ops, F: np.ndarray, h: np.ndarray, rings: int) -> np.ndarray:
    """Free vertices at an edge of negative weight in ``ops.L`` grown by ``rings`` rings
    (sorted int64)."""
    C = sp.triu(ops.L, 1).tocoo()  # L's off-diagonal is -w: a positive entry is a negative weight
    neg = C.data > 0
    mark = np.zeros(ops.n, bool)
    mark[C.row[neg]] = mark[C.col[neg]] = True
    return grown(ops, mark, h, rings)


def grown(ops, mark: np.ndarray, h: np.ndarray, rings: int) -> np.ndarray:
    """The vertices marked in ``mark`` ((n,) bool) grown by ``rings`` rings of ``ops.L``'s
    pattern, the handles ``h`` left out (sorted int64)."""
    A = (ops.L != 0).astype(np.int8).tocsr()
    for _ in range(rings):
        mark = (A @ mark.astype(np.int8)) > 0
    mark[h] = False
    return np.flatnonzero(mark)


class LocalProblem:
    """The exact block problem of the free set ``S``: the submesh of every face at a
    vertex of ``S`` or of its neighbours, the other submesh vertices its handles."""

    def __init__(self, V, F, ops, S, criterion: Criterion):
        n = len(V)
        inS = np.zeros(n, bool)
        inS[S] = True
        A = (ops.L != 0).tocsr()
        near = (A @ inS.astype(np.int8)) > 0  # S and its neighbours
        faces = F[near[F].any(1)]
        self.verts = np.unique(faces)
        loc = np.full(n, -1, np.int64)
        loc[self.verts] = np.arange(len(self.verts))
        self.Fs = loc[faces]
        self.Vs = V[self.verts]
        self.hs = np.flatnonzero(~inS[self.verts])  # local indices of the fixed vertices
        self.n, self.criterion = len(self.verts), criterion
        opt = ArapOptions(energy=ENERGY, threads=1, criterion=criterion, max_iter=5000)
        t = time.perf_counter()
        self.solver = ArapSolver(self.Vs, self.Fs, self.hs, opt)
        self.setup_s = time.perf_counter() - t

    def solve(self, U: np.ndarray):
        """``U`` (n, 3) with the rows of ``S`` replaced by the block minimiser (a new
        array) and the local result."""
        Us = U[self.verts]
        res = self.solver.solve(Us[self.hs], U0=Us)
        out = U.copy()
        out[self.verts] = res.V
        return out, res


def top_set(ops, U, free, h, k: int, rings: int) -> np.ndarray:
    """The free vertices of the ``k`` largest terms of ``gnorm**2`` at ``U`` grown by
    ``rings`` rings (sorted int64)."""
    g = ops.gradient(U)[free]
    c = (g * g).sum(1) / ops.mass[free]
    mark = np.zeros(ops.n, bool)
    mark[free[np.argsort(c)[::-1][:k]]] = True
    return grown(ops, mark, h, rings)


def gnorm_split(ops, U, free, S, mass):
    """Shares of ``gnorm**2`` at ``U``: top 10 / 100 / 1000 free vertices, the set ``S``."""
    g = ops.gradient(U)[free]
    c = (g * g).sum(1) / (4.0 * mass[free])
    tot = c.sum()
    srt = np.sort(c)[::-1]
    inS = np.isin(free, S)
    gn = float(ops.diag * np.sqrt(tot / mass[free].sum()))
    return {"gnorm": gn, "top10": float(srt[:10].sum() / tot), "top100": float(srt[:100].sum() / tot),
            "top1000": float(srt[:1000].sum() / tot), "S": float(c[inS].sum() / tot)}


def main():
    ap = argparse.ArgumentParser(prog="python benchmarks/arap_sliver_local.py", description=__doc__.splitlines()[0])
    ap.add_argument("--root", required=True, help="DeFAUST build")
    ap.add_argument("--defaust", default="0:1", help="subject:pose (default 0:1)")
    ap.add_argument("--rings", type=int, default=1, help="rings grown around the negative-weight vertices")
    ap.add_argument("--top", type=int, default=0, help="instead of the negative-weight set: at each stop, the "
                                                      "free vertices of the TOP largest gnorm terms, grown by --rings")
    ap.add_argument("--diagnose", action="store_true", help="only the gnorm split along the baseline's solve")
    ap.add_argument("--snapshots", default="1,50,100,200,300,400,500,600", help="iterations of --diagnose")
    ap.add_argument("--every", type=int, default=25, help="fine iterations between local solves")
    ap.add_argument("--from", dest="start", type=int, default=25, help="the first local solve at this iteration")
    ap.add_argument("--until", type=int, default=10**9, help="no local solve after this iteration")
    ap.add_argument("--local-gtol", type=float, default=1e-4, help="the local solves' gtol (etol 1e-9)")
    ap.add_argument("--max-iter", type=int, default=3000, help="cap on the fine iterations")
    a = ap.parse_args()
    sub, pose = (int(x) for x in a.defaust.split(":"))
    name, V0, F, h, T0 = defaust_case(a.root, sub, pose)
    frame = unit_frame(V0)
    V, T = frame.to_unit(V0), frame.to_unit(T0)
    n = len(V)
    ops = build_operators(V, F, ENERGY)
    S = sliver_set(ops, F, h, a.rings)
    free = np.setdiff1d(np.arange(n), h)

    def emit(row):
        print(json.dumps({"case": name, **row}), flush=True)

    emit({"n": n, "handles": len(h), "S": len(S), "rings": a.rings})
    opt = ArapOptions(energy=ENERGY, threads=1, criterion=DEFAULT_CRITERION, max_iter=a.max_iter)
    solver = ArapSolver(V, F, h, opt, operators=ops)
    t0 = time.perf_counter()
    if a.diagnose:
        snaps = {int(k) for k in a.snapshots.split(",") if k}

        def cb(k, U, E, gn):
            if k in snaps:
                emit({"iteration": k, "energy": frame.energy(E), "solver_gnorm": gn,
                      **gnorm_split(ops, U, free, S, ops.mass)})
            return False

        res = solver.solve(T, callback=cb)
        emit({"run": "diagnose", "iterations": res.iterations, "status": res.info["status"],
              "energy": frame.energy(res.info["energy"]), "gnorm": res.info["gnorm"],
              "s": round(time.perf_counter() - t0, 1), **gnorm_split(ops, res.V, free, S, ops.mass)})
        return
    local = LocalProblem(V, F, ops, S, Criterion(etol=1e-9, gtol=a.local_gtol))
    emit({"local_n": local.n, "local_free": len(S), "local_setup_s": round(local.setup_s, 2)})
    fine_it, local_w, stops, U0, checked = 0, 0.0, 0, None, False
    while True:
        nxt = a.start if fine_it < a.start else fine_it + a.every  # the next stop (fine iterations)
        stop_at = None if nxt > a.until else max(nxt - fine_it, 1)  # in this pass's iterations

        def cb(k, U, E, gn, stop_at=stop_at):
            return stop_at is not None and k >= stop_at

        res = solver.solve(T, U0=U0, callback=cb, carry_history=stops > 0)
        fine_it += res.iterations
        if res.info["status"] != "callback" or fine_it >= a.max_iter:
            break
        E_before = res.info["energy"]
        if a.top:
            local = LocalProblem(V, F, ops, top_set(ops, res.V, free, h, a.top, a.rings), local.criterion)
        U1, lres = local.solve(res.V)
        E_after = ops.energy(U1)
        local_w += lres.iterations * local.n / n
        stops += 1
        row = {"stop": stops, "at": fine_it, "local_n": local.n, "local_iterations": lres.iterations,
               "local_status": lres.info["status"],
               "energy_before": frame.energy(E_before), "energy_after": frame.energy(E_after),
               "gnorm_before": res.info["gnorm"], **{f"after_{k}": v for k, v in
                                                    gnorm_split(ops, U1, free, S, ops.mass).items()}}
        if not checked:  # the block energy is the fine energy up to a constant
            Us0 = res.V[local.verts]
            dE_loc = local.solver.ops.energy(lres.V) - local.solver.ops.energy(Us0)
            row["energy_change_fine_vs_local"] = [E_after - E_before, dE_loc]
            checked = True
        emit(row)
        U0 = U1
    emit({"run": f"local every {a.every} from {a.start} until {a.until}", "fine_iterations": fine_it,
          "local_solves": stops, "local_weighted": round(local_w, 1), "total_weighted": round(fine_it + local_w, 1),
          "status": res.info["status"], "energy": frame.energy(res.info["energy"]),
          "baseline_energy": BASELINE_ENERGY, "gnorm": res.info["gnorm"], "s": round(time.perf_counter() - t0, 1)})


if __name__ == "__main__":
    main()
