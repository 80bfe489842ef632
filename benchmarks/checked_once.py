"""What checking a method's mesh once saves: ``sshade.guard.run_method`` on a DeFAUST case
(s00_p01, high resolution) with the method's own ``validate_mesh`` trusting the guard's
checked arrays (:mod:`sshade.mesh.checked`, the default) and with that trust switched off
(each call checks again, as before), interleaved.

    python benchmarks/checked_once.py [--root data/defaust] [--repeats 5]

Methods: SShaDe (its defaults) and one call of ``validate_mesh`` alone at that size.
Prints one Markdown row per way: the median and range of ``seconds`` (the guard's timed
region). Record: benchmarks/records/checked_once.md.
"""
import argparse
import statistics
import time

import sshade.mesh.validate as val
from defaust.dataset import load
from sshade import SShaDe
from sshade.guard import run_method


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--root", default="data/defaust")
    ap.add_argument("--repeats", type=int, default=5)
    a = ap.parse_args()
    case = load(a.root, subjects=[0])[0]
    t0 = time.perf_counter()
    val.validate_mesh(case.V, case.F)
    print(f"one validate_mesh at {len(case.V)} vertices: {time.perf_counter() - t0:.3f} s")
    real = val.trusted_mesh
    times: dict[str, list[float]] = {"checked once": [], "checked again": []}
    run_method(SShaDe(), case.V, case.F, case.handles, case.targets)  # warm
    for _ in range(a.repeats):
        for way in times:
            val.trusted_mesh = real if way == "checked once" else (lambda *x, **k: None)
            times[way].append(run_method(SShaDe(), case.V, case.F, case.handles, case.targets).seconds)
    val.trusted_mesh = real
    print("| way | median s | range s |\n|---|---:|---:|")
    for way, ts in times.items():
        print(f"| {way} | {statistics.median(ts):.3f} | {min(ts):.3f}-{max(ts):.3f} |")


if __name__ == "__main__":
    main()
