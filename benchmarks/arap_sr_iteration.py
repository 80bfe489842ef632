"""The cost of one ARAP-SR iteration at full resolution (sshade/arap/smooth_rotations.py,
sshade/arap/sr_local.py), under both protocols, on DeFAUST cases: the paper protocol's
(Jacobi local step and global step) and the converged protocol's (global step, a
Gauss-Seidel sweep, an Anderson candidate and its sweep), each a fixed number of
iterations after an untimed run on the same problem; the energy and a digest of the
vertices reached say whether two checkouts compute the same iterates.

    python benchmarks/arap_sr_iteration.py DEFAUST_DIR [--cases s00_p01 ...] [--iters 20] [--tag T]

Compare two commits by running it from each checkout in turn, interleaved (the first
column names the checkout). One row per case and protocol: ms per iteration, iterations,
energy, the first 12 hex digits of the SHA-256 of the vertices. Measured:
benchmarks/records/arap_sr_iteration.md.
"""
import argparse
import hashlib
import sys

import numpy as np


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("defaust")
    ap.add_argument("--cases", nargs="+", default=["s00_p01"])
    ap.add_argument("--iters", type=int, default=20)
    ap.add_argument("--tag", default="")
    a = ap.parse_args(argv)
    from defaust.dataset import load
    from sshade.arap import ArapOptions, SRProblem, arap_sr_deform, solve_arap_sr
    from sshade.mesh.unit_frame import unit_frame

    cases = {c.name: c for c in load(a.defaust)}
    for name in a.cases:
        c = cases[name]
        fr = unit_frame(c.V)
        V, T = fr.to_unit(c.V), fr.to_unit(c.targets)
        pb = SRProblem(V, c.F, c.handles, T, 0.01)
        for proto, solve in (("paper", arap_sr_deform), ("converged", solve_arap_sr)):
            solve(V, c.F, c.handles, T, ArapOptions(alpha=0.01, max_iter=2), problem=pb)  # untimed
            r = solve(V, c.F, c.handles, T, ArapOptions(alpha=0.01, max_iter=a.iters), problem=pb)
            digest = hashlib.sha256(np.ascontiguousarray(r.V).tobytes()).hexdigest()[:12]
            print(f"| {a.tag} | {name} | {len(V)} | {proto} | {1e3 * r.solve_s / max(r.iterations, 1):.1f} | "
                  f"{r.iterations} | {r.info['energy']!r} | {digest} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
