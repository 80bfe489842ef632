"""ARAP and Elastic (converged protocol) from the rigid fit of the handles against the
coarse start (baselines/coarse_start.py) on DeFAUST cases: iterations, seconds
(interleaved: rigid then coarse per case and method), energy, and optionally the distance
of each result to a deep solve continued from it (eval.metrics.reference) and between the two.

    python benchmarks/arap_coarse_start.py DEFAUST_DIR s00_p01 s01_p02 [--deep] [--out DIR]

Prints one JSON line per run (and per deep continuation with --deep).
"""
import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the repository, as the other benchmarks

from baselines import ARAP, Elastic  # noqa: E402
from eval import datasets  # noqa: E402
from eval.metrics.reference import reference_solution  # noqa: E402
from eval.metrics.reference_scores import reference_metrics  # noqa: E402
from sshade.arap import bbox_diag  # noqa: E402

METHODS = {"ARAP": (ARAP, "spokes"), "Elastic": (Elastic, "spokes_and_rims")}


def main(root, names, deep, out, methods):
    cases = {c.name: c for c in datasets.load_cases("defaust", root) if c.name in names}
    results = {}
    for name in names:
        c = cases[name]
        diag = bbox_diag(c.V)
        for mname in methods:
            cls, energy = METHODS[mname]
            for start in ("rigid", "coarse"):
                m = cls(start=start)
                m.warmup(len(c.V))
                t = time.perf_counter()
                U = m.deform(c.V, c.F, c.handles, c.targets)
                wall = time.perf_counter() - t
                results[name, mname, start] = U
                row = {"case": name, "method": mname, "start": start, "wall_s": round(wall, 2), **{
                    k: m.info.get(k) for k in ("iterations", "status", "converged", "energy", "gnorm", "rel_decrease",
                                               "precompute_s", "solve_s", "coarse_n", "coarse_iterations", "coarse_s")}}
                print(json.dumps(row), flush=True)
                if out:
                    np.save(Path(out) / f"{name}_{mname}_{start}.npy", U)
            d = np.linalg.norm(results[name, mname, "rigid"] - results[name, mname, "coarse"], axis=1)
            print(json.dumps({"case": name, "method": mname, "rigid_vs_coarse_mean_pct": 100 * d.mean() / diag,
                              "rigid_vs_coarse_max_pct": 100 * d.max() / diag}), flush=True)
    if not deep:
        return
    for name in names:
        c = cases[name]
        for mname in methods:
            energy = METHODS[mname][1]
            for start in ("rigid", "coarse"):
                U = results[name, mname, start]
                with tempfile.TemporaryDirectory() as tmp:
                    t = time.perf_counter()
                    ref = reference_solution(c.V, c.F, c.handles, c.targets, energy=energy, cache_dir=tmp, U0=U)
                    met = reference_metrics(c.V, U, c.F, ref)
                dt = round(time.perf_counter() - t, 1)
                print(json.dumps({"case": name, "method": mname, "start": start, "deep_s": dt,
                                  "ref_iterations": ref.info["iterations"], "ref_status": ref.info["status"],
                                  "ref_energy": ref.energy, **{k: met.get(k) for k in
                                                               ("ref_mean_pct", "ref_max_pct", "energy_gap")}}),
                      flush=True)


if __name__ == "__main__":
    ap = argparse.ArgumentParser(prog="python benchmarks/arap_coarse_start.py", description=__doc__.splitlines()[0])
    ap.add_argument("root")
    ap.add_argument("cases", nargs="+")
    ap.add_argument("--deep", action="store_true", help="continue a deep solve from every result")
    ap.add_argument("--out", default=None, help="folder for the results (.npy)")
    ap.add_argument("--methods", default="ARAP,Elastic")
    a = ap.parse_args()
    main(a.root, a.cases, a.deep, a.out, a.methods.split(","))
