"""The converged full-resolution baselines on held-out meshes with eight handle regions,
against libigl's iteration on the same problem in the same process.

The meshes and the edit are those of ``benchmarks/frames.py --regions 8`` (its
``sized_mesh`` and ``eight_regions``): by default the dragon of libigl's tutorial data, LS3
Loop only ("hard", 160,002 vertices) and LS3 Loop then isotropic remeshing to 182,000
("clean"). Each method runs once warm (an untimed call on a small mesh first compiles its
kernels); libigl's ``arap_solve`` with the method's energy (spokes for ARAP, spokes and rims
for Elastic) is timed over ``--igl-iterations`` iterations from the rest pose. The ratio is
the method's wall seconds over libigl's seconds per iteration: "the converged ARAP baseline
costs at most N libigl iterations".

    python benchmarks/fullres_heldout.py [--mesh NAME=PATH[:hard] --sizes N ...] [--methods ARAP Elastic]
        [--cache DIR]
"""
import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))  # benchmarks/frames.py
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the repository

import frames as fb  # noqa: E402

from baselines import ARAP, Elastic  # noqa: E402
from harness.command import run_command  # noqa: E402

METHODS = {"ARAP": (ARAP, "spokes"), "Elastic": (Elastic, "spokes_and_rims")}
DRAGON = str(Path(__file__).resolve().parents[2] / "shared" / "data" / "classic" / "dragon.obj")
DEFAULT = [(f"dragon={DRAGON}:hard", 160000), (f"dragon={DRAGON}", 182000)]


def main(a) -> int:
    pairs = list(zip(a.mesh, a.sizes)) if a.mesh else DEFAULT
    V0, F0 = fb.read_mesh(DRAGON)
    for name in a.methods:  # compile every kernel before any timer
        METHODS[name][0]().deform(V0, F0, np.arange(20), V0[:20] + 0.01)
    print("| mesh | vertices | method | seconds | iterations | status | libigl s / iteration | "
          "libigl iterations |\n|---|---:|---|---:|---:|---|---:|---:|", flush=True)
    for spec, size in pairs:
        entry = fb.mesh_entry(spec)
        V, F, V0 = fb.sized_mesh(entry, int(size), Path(a.cache))
        h, T = fb.eight_regions(V, V0, seed=0)
        for name in a.methods:
            cls, energy = METHODS[name]
            m = cls()
            t0 = time.perf_counter()
            m.deform(V, F, h, T)
            s = time.perf_counter() - t0
            it = fb.igl_iteration_s(V, F, h, T, a.igl_iterations, energy)
            print(f"| {entry.name} ({entry.kind}) | {len(V)} | {name} | {s:.1f} | {m.info['iterations']} | "
                  f"{m.info.get('status', m.info.get('converged'))} | {it:.3f} | {s / it:.0f} |", flush=True)
    return 0


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--mesh", action="append", help="NAME=PATH[:hard], with --sizes (default: the two dragons)")
    ap.add_argument("--sizes", nargs="+", type=int, default=[])
    ap.add_argument("--methods", nargs="+", default=["ARAP"], choices=sorted(METHODS))
    ap.add_argument("--cache", default="data/frames_heldout", help="where built meshes are kept")
    ap.add_argument("--igl-iterations", type=int, default=5)
    a = ap.parse_args()
    if a.mesh and len(a.mesh) != len(a.sizes):
        ap.error("give one --sizes entry per --mesh")
    raise SystemExit(run_command(lambda: main(a)))
