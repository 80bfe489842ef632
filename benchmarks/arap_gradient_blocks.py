"""Where the gradient of a converging ARAP solve sits, and whether relaxing that region
alone between L-BFGS runs shortens the solve (a one-off experiment; no product code).

The problem is the ``ARAP`` baseline's on a DeFAUST case (spokes energy, unit frame, rigid
start, the default criterion) solved by ``sshade.arap.ArapSolver``:

- ``concentration``: one solve to the criterion; at given iterations the gradient of the
  reduced energy (``ArapOperators.gradient``), each free vertex's share of the criterion's
  ``gnorm^2`` (``|g_i|^2 / m_i``), the shares of the top 0.1 / 1 / 10 % of vertices, and of
  the top ``h`` (the handle count) their graph distance to a handle, how many touch a
  negative cotangent weight, and their valence.
- ``blocks``: ``--every`` iterations of L-BFGS, then an exact block step: the ``--top``
  vertices of largest share dilated by ``--rings`` rings (handles excluded) are the
  unknowns, the faces within two rings of them a sub-mesh whose other vertices are held
  (every cell whose energy depends on the unknowns is whole in it), solved to ``gtol
  1e-6``; then L-BFGS again from there (its history restarts), ``--rounds`` times, then to
  the criterion. ``--restart-only``: the same restarts without the block steps (the control).

    python benchmarks/arap_gradient_blocks.py concentration [--root data/defaust] [--subject 0] [--pose 1]
    python benchmarks/arap_gradient_blocks.py blocks [--rings 3] [--top 500] [--every 100] [--rounds 4]
                                                     [--restart-only]

Record: benchmarks/records/arap_alternatives.md ("The gradient's region").
"""
import argparse
import sys
import time
from pathlib import Path

import numpy as np
from scipy.sparse.csgraph import dijkstra

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the repository, as the other benchmarks

from defaust.dataset import load  # noqa: E402
from sshade.arap import ArapOptions, solve_arap  # noqa: E402
from sshade.arap.criterion import Criterion  # noqa: E402
from sshade.arap.solver import ArapSolver  # noqa: E402
from sshade.mesh.unit_frame import unit_frame  # noqa: E402

SNAPSHOTS = (50, 100, 200, 300, 350, 400, 450, 500, 550, 600)


def _problem(a):
    """The case in the unit frame: V, F, handles, targets."""
    case = next(c for c in load(a.root, subjects=[a.subject], partial=True) if c.pose == a.pose)
    fr = unit_frame(case.V)
    return fr.to_unit(case.V), case.F, case.handles, fr.to_unit(case.targets)


def _shares(ops, U, free):
    """Each free vertex's term of gnorm^2 (unnormalised) and the gradient rows."""
    g = ops.gradient(U)[free]
    return (g ** 2).sum(1) / ops.mass[free], g


def concentration(a) -> None:
    V, F, h, T = _problem(a)
    s = ArapSolver(V, F, h, ArapOptions(energy="spokes"))
    ops, snaps = s.ops, {}
    free = np.setdiff1d(np.arange(ops.n), h)

    def cb(it, U, E, gn):
        if it in SNAPSHOTS:
            snaps[it] = (U.copy(), E, gn)
        return False

    res = s.solve(T, callback=cb)
    snaps[res.iterations] = (res.V.copy(), res.info["energy"], res.info["gnorm"])
    A = ops.L.tocsr().copy()
    A.data[:] = 1.0
    A.setdiag(0)
    A.eliminate_zeros()
    hop = dijkstra(A, indices=h, unweighted=True, min_only=True)
    neg = np.zeros(ops.n, bool)
    neg[ops.edges[ops.edge_w < 0].ravel()] = True
    val = np.diff(A.indptr)
    print(f"{res.iterations} iterations; free vertices: median hops to a handle {np.median(hop[free]):.0f}, "
          f"touching a negative weight {neg[free].mean():.3f}, median valence {np.median(val[free]):.0f}")
    for it in sorted(snaps):
        U, E, gn = snaps[it]
        c, _ = _shares(ops, U, free)
        o = np.sort(c)[::-1]
        top = free[np.argsort(c)[::-1][:len(h)]]
        share = [o[:max(1, int(f * len(o)))].sum() / o.sum() for f in (0.001, 0.01, 0.1)]
        print(f"it {it:4d} E {E:.10g} gnorm {gn:.3g}: top 0.1 / 1 / 10 % {share[0]:.2f} / {share[1]:.2f} / "
              f"{share[2]:.2f}; top {len(h)}: median hops {np.median(hop[top]):.0f}, touching a negative weight "
              f"{neg[top].mean():.2f}, median valence {np.median(val[top]):.0f}")


def _block_step(ops, V, F, U, is_h, A, rings, top):
    """The exact block step of the region around the ``top`` largest shares."""
    n = ops.n
    g = ops.gradient(U)
    c = (g ** 2).sum(1) / ops.mass
    c[is_h] = 0.0

    def dilate(mask, k):
        for _ in range(k):
            mask = mask | (A @ mask.astype(np.float64) > 0)
        return mask

    D = np.zeros(n, bool)
    D[np.argsort(c)[::-1][:top]] = True
    D = dilate(D, rings) & ~is_h
    Fs = F[dilate(D, 2)[F].all(1) & dilate(D, 1)[F].any(1)]
    vs = np.unique(Fs)
    loc = np.full(n, -1, np.int64)
    loc[vs] = np.arange(len(vs))
    held = np.flatnonzero(~D[vs])
    r = solve_arap(V[vs], loc[Fs], held, U[vs[held]],
                   ArapOptions(energy="spokes", criterion=Criterion(etol=1e-12, gtol=1e-6), max_iter=2000), U0=U[vs])
    Un = U.copy()
    Un[vs] = r.V
    return Un, int(D.sum()), len(vs), r.iterations, r.info["status"]


def blocks(a) -> None:
    V, F, h, T = _problem(a)
    s = ArapSolver(V, F, h, ArapOptions(energy="spokes"))
    ops = s.ops
    A = ops.L.tocsr().copy()
    A.data[:] = 1.0
    A.setdiag(0)
    A.eliminate_zeros()
    is_h = np.zeros(ops.n, bool)
    is_h[h] = True
    free = np.flatnonzero(~is_h)
    total, U0, t0 = 0, None, time.perf_counter()
    for rnd in range(a.rounds + 1):
        last = rnd == a.rounds
        res = s.solve(T, U0=U0, options=ArapOptions(energy="spokes", max_iter=None if last else a.every))
        total += res.iterations
        E, gn = res.info["energy"], res.info["gnorm"]
        if last or res.info["status"] == "converged":
            print(f"round {rnd}: {res.iterations} it ({res.info['status']}), in all {total}, E {E:.12g}, "
                  f"gnorm {gn:.3g}, {time.perf_counter() - t0:.0f} s")
            return
        if a.restart_only:  # the control: the same restarts, no block step
            print(f"round {rnd}: {res.iterations} it, E {E:.12g} gnorm {gn:.3g}; restart")
            U0 = res.V
            continue
        Ub, nd, nv, bi, bst = _block_step(ops, V, F, res.V, is_h, A, a.rings, a.top)
        c, _ = _shares(ops, Ub, free)
        gnb = ops.diag * np.sqrt((c / 4).sum() / ops.mass[free].sum())
        print(f"round {rnd}: {res.iterations} it, E {E:.12g} gnorm {gn:.3g}; block of {nd} vertices "
              f"(sub-mesh {nv}), {bi} it ({bst}): E {ops.energy(Ub):.12g} gnorm {gnb:.3g}")
        U0 = Ub


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("what", choices=("concentration", "blocks"))
    ap.add_argument("--root", default="data/defaust")
    ap.add_argument("--subject", type=int, default=0)
    ap.add_argument("--pose", type=int, default=1)
    ap.add_argument("--rings", type=int, default=3)
    ap.add_argument("--top", type=int, default=500)
    ap.add_argument("--every", type=int, default=100)
    ap.add_argument("--rounds", type=int, default=4)
    ap.add_argument("--restart-only", action="store_true", help="the same L-BFGS restarts without the block steps")
    a = ap.parse_args()
    (concentration if a.what == "concentration" else blocks)(a)


if __name__ == "__main__":
    main()
