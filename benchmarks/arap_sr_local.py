"""ARAP-SR's local step and acceleration compared on small cases of sshade.arap.problems
(sshade/arap/smooth_rotations.py): Jacobi local step (all rotations at once from the previous
ones), Gauss-Seidel over a vertex colouring, Gauss-Seidel with Anderson on the joint
(U, R) residual (the default) and with the history reset after every rejected candidate
(an older scheme), each to the default criterion.

    python benchmarks/arap_sr_local.py [alpha]     # prints one row per case and scheme

Columns: iterations (global solves), local sweeps, status, final energy, the largest
energy increase between accepted states (> 0: the energy went up), rejected Anderson
candidates, seconds. Measured rows: benchmarks/records/arap_sr_local_step.md.
"""
import argparse
import time

import numpy as np

from sshade.arap import ArapOptions, SRProblem, solve_arap_sr
from sshade.arap.problems import bent_cylinder, lifted_plane, twisted_bar

CASES = {"twisted_bar": lambda: twisted_bar(90.0, h=0.12), "bent_cylinder": lambda: bent_cylinder(h=0.16),
         "lifted_plane": lambda: lifted_plane(n_target=2500)}
SCHEMES = {"jacobi": ("none", True, False), "gauss-seidel": ("none", False, False),
           "gs+anderson": ("anderson", False, False), "gs+anderson, reset": ("anderson", False, True)}


def main(alpha: float = 0.01) -> None:
    print("| case | n | scheme | iters | sweeps | status | energy | max increase | rejected | s |")
    print("|---|---:|---|---:|---:|---|---:|---:|---:|---:|")
    for name, make in CASES.items():
        V, F, h, T = make()
        pb = SRProblem(V, F, h, T, alpha)
        for scheme, (acc, jac, reset) in SCHEMES.items():
            t = time.perf_counter()
            options = ArapOptions(alpha=alpha, accelerate=acc, jacobi=jac, max_iter=5000, reset_on_reject=reset)
            r = solve_arap_sr(V, F, h, T, options, problem=pb)
            dt = time.perf_counter() - t
            inc = float(np.diff(r.info["energy_history"]).max())
            print(f"| {name} | {len(V)} | {scheme} | {r.iterations} | {r.info['n_sweeps']} | {r.info['status']} | "
                  f"{r.info['energy']:.10g} | {inc:.2g} | {r.info['n_fallback']} | {dt:.2f} |", flush=True)


if __name__ == "__main__":
    ap = argparse.ArgumentParser(prog="python benchmarks/arap_sr_local.py", description=__doc__.splitlines()[0])
    ap.add_argument("alpha", type=float, nargs="?", default=0.01, help="ARAP-SR smoothness weight (default 0.01)")
    main(ap.parse_args().alpha)
