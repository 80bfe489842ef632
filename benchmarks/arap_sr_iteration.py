"""The cost of one ARAP-SR iteration at full resolution (sshade/arap/smooth_rotations.py,
sshade/arap/sr_local.py), under both protocols, on DeFAUST cases: the paper protocol's
(Jacobi local step and global step) and the converged protocol's (global step, a
Gauss-Seidel sweep, an Anderson candidate and its sweep), each a fixed number of
iterations after an untimed run on the same problem; the energy and a digest of the
vertices reached say whether two checkouts compute the same iterates. A hard mesh too:
``--mesh NAME=PATH[:hard] --size N`` builds it as the scaling experiment does (``:hard``:
LS3 Loop only; cached in ``--cache`` under the scaling experiment's file names) with that
experiment's edit (eval.datasets.shapes.axis_handles: two regions fixed, one turned 20
degrees, one moved 5 % of the diagonal), in the unit frame as the evaluator runs ARAP-SR.

    python benchmarks/arap_sr_iteration.py DEFAUST_DIR [--cases s00_p01 ...] [--iters 20] [--tag T]
    python benchmarks/arap_sr_iteration.py --mesh centaur=../shared/data/tosca/centaur0.off:hard
        [--size 200000] [--cache data/scaling] [--iters 20] [--tag T]

Compare two commits by running it from each checkout in turn, interleaved (the first
column names the checkout). One row per case and protocol: ms per iteration, iterations,
energy, the first 12 hex digits of the SHA-256 of the vertices. Measured:
benchmarks/records/arap_sr_iteration.md.
"""
import argparse
import hashlib
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the repository, as the other benchmarks


def _defaust_cases(a):
    """(name, V, F, handles, targets) of the chosen DeFAUST cases."""
    from defaust.dataset import load
    cases = {c.name: c for c in load(a.defaust)}
    for name in a.cases:
        c = cases[name]
        yield name, c.V, c.F, c.handles, c.targets


def _hard_case(a):
    """(name, V, F, handles, targets) of ``--mesh`` at ``--size``, the scaling experiment's edit."""
    from frames import mesh_entry, sized_mesh  # this script's folder, as run

    from eval.datasets.shapes import axis_handles, axis_landmarks
    entry = mesh_entry(a.mesh)
    V, F, V0 = sized_mesh(entry, a.size, Path(a.cache))
    h, T, _, _ = axis_handles(V, *axis_landmarks(V0))
    yield f"{entry.name} ({entry.kind})", V, F, h, T


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("defaust", nargs="?")
    ap.add_argument("--cases", nargs="+", default=["s00_p01"])
    ap.add_argument("--mesh", help="NAME=PATH[:hard], instead of DeFAUST cases")
    ap.add_argument("--size", type=int, default=200_000)
    ap.add_argument("--cache", default="data/scaling")
    ap.add_argument("--iters", type=int, default=20)
    ap.add_argument("--tag", default="")
    a = ap.parse_args(argv)
    if (a.defaust is None) == (a.mesh is None):
        ap.error("give either DEFAUST_DIR or --mesh")
    from sshade.arap import ArapOptions, SRProblem, arap_sr_deform, solve_arap_sr
    from sshade.mesh.unit_frame import unit_frame

    for name, V0, F, h, T0 in (_hard_case(a) if a.mesh else _defaust_cases(a)):
        fr = unit_frame(V0)
        V, T = fr.to_unit(V0), fr.to_unit(T0)
        pb = SRProblem(V, F, h, T, 0.01)
        for proto, solve in (("paper", arap_sr_deform), ("converged", solve_arap_sr)):
            solve(V, F, h, T, ArapOptions(alpha=0.01, max_iter=2), problem=pb)  # untimed
            r = solve(V, F, h, T, ArapOptions(alpha=0.01, max_iter=a.iters), problem=pb)
            digest = hashlib.sha256(np.ascontiguousarray(r.V).tobytes()).hexdigest()[:12]
            print(f"| {a.tag} | {name} | {len(V)} | {proto} | {1e3 * r.solve_s / max(r.iterations, 1):.1f} | "
                  f"{r.iterations} | {r.info['energy']!r} | {digest} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
