"""The bounding box of a mesh, per coordinate column (sshade.mesh.bounds) against NumPy's
axis-0 reduction, and the checks that take it, at a DeFAUST case's size.

    python benchmarks/bounds.py [--root data/defaust] [--repeats 50]

Prints one Markdown row per timing: the median over ``--repeats`` calls, in ms, the two
ways of the box interleaved. Record: benchmarks/records/bounds.md.
"""
import argparse
import statistics
import time

import numpy as np

from defaust.dataset import load
from sshade.mesh.bounds import bounding_box
from sshade.mesh.unit_frame import unit_frame
from sshade.mesh.validate import validate_deformed, validate_targets


def _ms(fn, repeats: int) -> float:
    fn()
    ts = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        ts.append(time.perf_counter() - t0)
    return 1000 * statistics.median(ts)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--root", default="data/defaust")
    ap.add_argument("--repeats", type=int, default=50)
    a = ap.parse_args()
    c = load(a.root, subjects=[0])[0]
    V = np.ascontiguousarray(c.V, np.float64)
    rows = {"box, per column (sshade.mesh.bounds)": [], "box, V.min(axis=0) / V.max(axis=0)": []}
    for _ in range(5):  # interleaved
        rows["box, per column (sshade.mesh.bounds)"].append(_ms(lambda: bounding_box(V), a.repeats))
        rows["box, V.min(axis=0) / V.max(axis=0)"].append(_ms(lambda: (V.min(axis=0), V.max(axis=0)), a.repeats))
    print(f"{len(V)} vertices, numpy {np.__version__}\n\n| timing | median ms |\n|---|---:|")
    for k, v in rows.items():
        print(f"| {k} | {statistics.median(v):.3f} |")
    for name, fn in (("validate_targets (handles' targets)", lambda: validate_targets(V, len(c.handles), c.targets)),
                     ("validate_deformed (a method's output)", lambda: validate_deformed(V + 0.0, len(V), V=V)),
                     ("unit_frame", lambda: unit_frame(V))):
        print(f"| {name} | {_ms(fn, a.repeats):.3f} |")


if __name__ == "__main__":
    main()
