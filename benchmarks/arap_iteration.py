"""Per-iteration cost of SShaDe's converged ARAP solver (:func:`sshade.arap.solve_arap`,
spokes-and-rims) and of libigl's ``igl.arap_solve`` on a ~200k-vertex mesh.

    python benchmarks/arap_iteration.py [--mesh data/benchmarks/armadillo_200k.npz]
                                        [--iters 30] [--repeat 3] [--threads 1 2 auto]
                                        [--energy spokes_and_rims] [--no-igl]

Mesh: an ``.npz`` with arrays ``V``, ``F`` (default: the 200k armadillo that
``benchmarks/remesh_speed.py`` caches). Handles: the scaling benchmark's fixed edit
(:func:`eval.datasets.shapes.axis_landmarks` / :func:`~eval.datasets.shapes.axis_handles`).

Ours: for every ``--threads`` value (an int, or ``auto``: ``threads=None``, the solver
picks 1 or ``NUMBA_NUM_THREADS`` by timing its iterations), ``solve_arap`` (L-BFGS, Anderson,
then plain local/global) run for ``--iters`` iterations with the criterion switched off,
after a warm-up solve (numba cache load, operators). Printed per iteration: the stages
from ``info["stage_s"]`` (local = covariances + rotations + energy, fused; rhs = ``K(R)``;
solve = CHOLMOD; gradient = the stopping test's gradient norm; anderson = Anderson's history
update and mixing, or L-BFGS's direction: gradient, the compact form's two passes), the rest of the loop ("other")
and the total (``solve_s / iterations``);
``locals/it`` is the number of local steps per iteration (the accelerated loop evaluates a
second candidate after a rejected Anderson step) and ``parallel`` the fraction of
iterations run with more than one thread. Each figure is the best of ``--repeat`` runs.

libigl: ``ARAPData`` with ``ARAP_ENERGY_TYPE_SPOKES_AND_RIMS``, ``max_iter = 1``,
``arap_precomputation`` once, then ``--iters`` calls of ``arap_solve``; best and median
seconds per call.

Timings are wall-clock: run on a quiet machine (the load average is printed before and
after; on a 2-core machine with one other job running, parallel kernels are SLOWER than
one thread: see :class:`sshade.arap.threads.ThreadPicker`). The thread count of the numba
kernels is ``--threads`` (capped at ``NUMBA_NUM_THREADS``); the iterates do not depend on
it.
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

STAGES = ("local", "rhs", "solve", "gradient", "anderson")


def load_case(path: Path):
    """``(V, F, handles, targets)`` of the fixed edit on the mesh at ``path``."""
    from eval.datasets.shapes import axis_handles, axis_landmarks
    d = np.load(path)
    V, F = np.ascontiguousarray(d["V"], np.float64), np.ascontiguousarray(d["F"], np.int64)
    lm, c, ax = axis_landmarks(V)
    h, T, _, _ = axis_handles(V, lm, c, ax)
    return V, F, np.asarray(h, np.int64), np.asarray(T, np.float64)


def bench_ours(V, F, h, T, ops, *, iters: int, repeat: int, threads: int, accelerate: str) -> dict:
    """Best-of-``repeat`` seconds per iteration of each stage, other and total."""
    from sshade.arap import ArapOptions, Criterion, solve_arap
    best = {}
    options = ArapOptions(energy=ops.energy_type, max_iter=iters, criterion=Criterion(0.0, 0.0), accelerate=accelerate,
                          threads=threads)
    for _ in range(repeat):
        r = solve_arap(V, F, h, T, options, operators=ops)
        it = max(r.iterations, 1)
        row = {k: r.info["stage_s"][k] / it for k in STAGES}
        row["total"] = r.solve_s / it
        row["other"] = row["total"] - sum(row[k] for k in STAGES)
        row["locals/it"] = r.info["n_local"] / it
        row["factor"] = r.info["factor_s"]
        row["precompute"] = r.precompute_s
        row["threads"] = r.info["threads"]
        row["reordered"] = r.info["reordered"]
        row["parallel"] = r.info.get("parallel_fraction", float(r.info["threads"] > 1))
        for k, v in row.items():
            best[k] = v if k not in best or k in ("threads", "reordered", "locals/it", "parallel") else min(best[k], v)
    return best


def bench_igl(V, F, h, T, *, iters: int, energy: str) -> tuple[float, float, float]:
    """(precomputation s, best s per arap_solve, median s per arap_solve)."""
    import igl

    from sshade.arap import rigid_fit
    data = igl.ARAPData()
    data.energy = {"spokes": igl.ARAP_ENERGY_TYPE_SPOKES,
                   "spokes_and_rims": igl.ARAP_ENERGY_TYPE_SPOKES_AND_RIMS}[energy]
    data.max_iter = 1
    t0 = time.perf_counter()
    igl.arap_precomputation(V, F, 3, h.astype(np.int32), data)
    pre = time.perf_counter() - t0
    Rr, tr = rigid_fit(V[h], T)
    U = V @ Rr.T + tr
    U[h] = T
    ts = []
    for _ in range(iters):
        t0 = time.perf_counter()
        U = igl.arap_solve(T, data, U)
        ts.append(time.perf_counter() - t0)
    return pre, float(min(ts)), float(np.median(ts))


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--mesh", type=Path, default=ROOT / "data" / "benchmarks" / "armadillo_200k.npz")
    ap.add_argument("--iters", type=int, default=30)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--threads", nargs="+", default=None,
                    help="thread counts to measure, ints or 'auto' (default: 1, NUMBA_NUM_THREADS, auto)")
    ap.add_argument("--energy", default="spokes_and_rims", choices=("spokes", "spokes_and_rims"))
    ap.add_argument("--no-igl", action="store_true", help="skip libigl")
    args = ap.parse_args(argv)

    from sshade.arap import ArapOptions, build_operators, max_threads, solve_arap
    V, F, h, T = load_case(args.mesh)
    print(f"mesh {args.mesh.name}: {len(V)} vertices, {len(F)} faces, {len(h)} handles; energy {args.energy}; "
          f"{args.iters} iterations, best of {args.repeat}; load average {os.getloadavg()[0]:.2f}")
    t0 = time.perf_counter()
    ops = build_operators(V, F, args.energy)
    print(f"build_operators {time.perf_counter() - t0:.2f} s")
    threads = [None if t == "auto" else int(t) for t in (args.threads or sorted({1, max_threads()}) + ["auto"])]
    for t in threads:  # warm-up: numba cache, kernel data, parallel pool
        solve_arap(V, F, h, T, ArapOptions(energy=args.energy, max_iter=2, threads=t), operators=ops)

    cols = STAGES + ("other", "total")
    print("\nours, milliseconds per iteration (stage_s / iterations; total = solve_s / iterations)")
    print(f"{'variant':<26}" + "".join(f"{c:>10}" for c in cols) + f"{'locals/it':>11}{'parallel':>10}")
    for accelerate in ("lbfgs", "anderson", "none"):
        for t in threads:
            b = bench_ours(V, F, h, T, ops, iters=args.iters, repeat=args.repeat, threads=t, accelerate=accelerate)
            name = f"{'plain' if accelerate == 'none' else accelerate} threads={'auto' if t is None else b['threads']}"
            print(f"{name:<26}" + "".join(f"{1e3 * b[c]:>10.1f}" for c in cols) + f"{b['locals/it']:>11.2f}"
                  f"{b['parallel']:>10.2f}")
    print(f"(precompute incl. factorisation {b['precompute']:.2f} s, factorisation {b['factor']:.2f} s, "
          f"renumbered: {b['reordered']})")
    if not args.no_igl:
        pre, best, med = bench_igl(V, F, h, T, iters=args.iters, energy=args.energy)
        print(f"\nlibigl arap_solve (max_iter=1): {1e3 * best:.1f} ms per iteration best, {1e3 * med:.1f} median "
              f"(arap_precomputation {pre:.2f} s)")
    print(f"\nload average at the end {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
