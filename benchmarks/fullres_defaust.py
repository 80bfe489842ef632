"""Converged full-resolution baselines on one DeFAUST case, this checkout against others:
``baselines.ARAP()`` and ``baselines.Elastic()`` as the evaluator builds them (rigid
start, L-BFGS, the default criterion) on s00_p01 at high resolution (168,853 vertices),
each run in a fresh process after an untimed warm-up run in that process, the checkouts
interleaved.

    python benchmarks/fullres_defaust.py [--root data/defaust] [--subject 0] [--pose 1]
                                         [--methods ARAP Elastic] [--repeats 3]
                                         [--code OTHER_CHECKOUT ...]

``--code``: other checkouts to run beside this one (e.g. ``git worktree add /tmp/parent
HEAD~1``); each process imports ``sshade`` and ``baselines`` from its checkout. Prints one
Markdown row per checkout and method: iterations (deterministic), the stop, the final
energy, the set-up and iteration seconds (median and range over ``--repeats``) and the
iterations' seconds per iteration. Run it on a quiet machine. Record:
benchmarks/records/fullres_defaust.md.
"""
import argparse
import json
import os
import statistics
import subprocess
import sys
from pathlib import Path

_PROBE = r"""
import json, sys, time
import numpy as np
import baselines
from defaust.dataset import load
root, subject, pose, name = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), sys.argv[4]
case = next(c for c in load(root, subjects=[subject]) if c.pose == pose)
m = getattr(baselines, name)()
m.deform(case.V, case.F, case.handles, case.targets)  # warm-up: kernels, caches
t = time.perf_counter()
m.deform(case.V, case.F, case.handles, case.targets)
wall = time.perf_counter() - t
i = m.info
print(json.dumps({"iterations": i["iterations"], "status": i["status"], "energy": i.get("energy"),
                  "precompute_s": i["precompute_s"], "solve_s": i["solve_s"], "wall_s": wall}))
"""


def run(code: Path, root: Path, subject: int, pose: int, method: str) -> dict:
    """One fresh process on checkout ``code``: its JSON line as a dict."""
    out = subprocess.run([sys.executable, "-c", _PROBE, str(root), str(subject), str(pose), method],
                         cwd=code, env={**os.environ, "PYTHONPATH": str(code)},
                         capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--root", default="data/defaust")
    ap.add_argument("--subject", type=int, default=0)
    ap.add_argument("--pose", type=int, default=1)
    ap.add_argument("--methods", nargs="+", default=["ARAP", "Elastic"])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--code", nargs="*", default=[], help="other checkouts to run beside this one")
    a = ap.parse_args()
    here = Path(__file__).resolve().parents[1]
    codes = [here, *(Path(c).resolve() for c in a.code)]
    root = Path(a.root).resolve()
    runs: dict = {(c, m): [] for c in codes for m in a.methods}
    for _ in range(a.repeats):
        for m in a.methods:
            for c in codes:
                runs[c, m].append(run(c, root, a.subject, a.pose, m))
    print(f"s{a.subject:02d}_p{a.pose:02d}, {a.repeats} interleaved runs each\n")
    print("| checkout | method | iterations | stop | energy | set-up s | iterations s | ms / iteration |")
    print("|---|---|---:|---|---:|---:|---:|---:|")
    for (c, m), rs in runs.items():
        pre = [r["precompute_s"] for r in rs]
        sol = [r["solve_s"] for r in rs]
        it = rs[0]["iterations"]
        print(f"| {c} | {m} | {it} | {rs[0]['status']} | {rs[0]['energy']:.10g} | {statistics.median(pre):.2f} "
              f"({min(pre):.2f}-{max(pre):.2f}) | {statistics.median(sol):.2f} ({min(sol):.2f}-{max(sol):.2f}) | "
              f"{1e3 * statistics.median(sol) / max(it, 1):.1f} |")


if __name__ == "__main__":
    main()
