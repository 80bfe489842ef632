"""The fused local step's energy term by term against the trace form: what each costs and
how far apart they are. The record: benchmarks/records/arap_trace_energy.md.

The solver's local step (``ArapOperators.local_step``, one numba kernel per block of cells)
does the covariances, the polar decompositions and the energy: each cell's summed pair by
pair, ``E_k = sum_p a_p ||e'_p - R_k e_p||^2``, or (with its ``Et``) the trace form
``E = sum_e w_e ||e'_e||^2 + sum_e w_e ||e_e||^2 - 2 sum_k tr(R_k^T M_k)``, one pass over
the edges instead of the pairs, ``tr`` a by-product of the polar code; its terms cancel
where the cells are nearly rigid, so below ``TRACE_MIN_ENERGY`` it sums the pairs.

Per case of ``sshade.arap.problems`` (and with ``--root`` the DeFAUST case s00_p01, spokes,
the ``ARAP`` baseline's energy) and per state ``U_t = V + t (U* - V)`` (``U*`` the converged
Elastic result) and a rigid motion of the rest pose with a tiny noise:
- the median time of the local step each way (warm start from the state before; the trace
  form's includes its fallback to the pair sum where it takes it);
- the relative difference of the two energies, the trace form's taken whole (from the polar
  kernel's ``tr``, never replaced), against the criterion's ``etol`` (1e-7).

    python benchmarks/arap_trace_energy.py [--cases bent_cylinder,twisted_bar,lifted_plane]
        [--energy spokes_and_rims|spokes] [--reps 50] [--root data/defaust]

Prints one JSON line per case and state; writes no file.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the repository, as the other benchmarks

from baselines import Elastic  # noqa: E402
from sshade.arap import kernels as K  # noqa: E402
from sshade.arap.operators import build_operators  # noqa: E402
from sshade.arap.problems import CASES  # noqa: E402


def _median_ms(f, reps: int) -> float:
    f()
    ts = []
    for _ in range(reps):
        t0 = time.perf_counter()
        f()
        ts.append(time.perf_counter() - t0)
    return float(np.median(ts) * 1e3)


def _fused_step(ops, U, W, W0, R, Ek):
    """The solver's fused local step from the warm start ``W0``, as a call without arguments."""
    def f():
        W[:] = W0
        ops.local_step(U, R, Ek, W)
    return f


def _trace_step(ops, U, W, W0, R, Ek, Et):
    """The local step with the trace form (``Et`` given: ``ArapOperators.local_step``'s own
    choice, the pair sum below ``TRACE_MIN_ENERGY`` included) from ``W0``, likewise."""
    def f():
        W[:] = W0
        ops.local_step(U, R, Ek, W, 1, None, Et)
    return f


def _states(V, U_conv, seed: int = 0):
    """The states compared: name -> (n, 3) positions."""
    diag = float(np.linalg.norm(V.max(0) - V.min(0)))
    rng = np.random.default_rng(seed)
    c, s = np.cos(0.3), np.sin(0.3)
    Rz = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    out = {f"t={t:g}": V + t * (U_conv - V) for t in (1e-4, 1e-2, 1.0)}
    out["rigid+1e-6 noise"] = V @ Rz.T + 0.1 * diag + 1e-6 * diag * rng.standard_normal(V.shape)
    return out


def run_case(name: str, V, F, h, T, energy: str, reps: int) -> list[dict]:
    """One JSON-ready row per state of one case."""
    U_conv = Elastic().deform(V, F, h, T) if energy == "spokes_and_rims" else None
    if U_conv is None:
        from baselines import ARAP
        U_conv = ARAP().deform(V, F, h, T)
    ops = build_operators(V, F, energy)
    n = ops.n
    edges = np.ascontiguousarray(ops.edges, np.int64)
    rows = []
    for sname, U in _states(V, U_conv).items():
        U = np.ascontiguousarray(U)
        R, Ek, W0 = np.empty((n, 3, 3)), np.empty(n), np.empty((n, 3, 3))
        W0[:] = np.eye(3)
        ops.local_step(U, R, Ek, W0)  # W0: the warm start at this state
        W, tr = W0.copy(), np.empty(n)
        e_term = ops.local_step(U, R, Ek, W)
        W[:] = W0
        K._polar_batch_nb(np.ascontiguousarray(ops.covariances(U)), R, tr, W, True)
        e_trace = ops._energy_from_trace(U, tr)  # the numpy path's trace form, whole
        scale = ops.rest_term

        fused_ms = _median_ms(_fused_step(ops, U, W, W0, R, Ek), reps)
        trace_ms = _median_ms(_trace_step(ops, U, W, W0, R, Ek, np.empty(len(edges))), reps)
        rows.append({"case": name, "n": n, "energy": energy, "state": sname, "E_term": e_term, "E_trace": e_trace,
                     "rel_diff": abs(e_trace - e_term) / max(abs(e_term), 1e-300), "E_over_rest": e_term / scale,
                     "fused_ms": round(fused_ms, 4), "trace_ms": round(trace_ms, 4)})
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", default="bent_cylinder,twisted_bar,lifted_plane")
    ap.add_argument("--energy", default="spokes_and_rims", choices=["spokes_and_rims", "spokes"])
    ap.add_argument("--reps", type=int, default=50)
    ap.add_argument("--root", default=None, help="a DeFAUST build: also its case s00_p01 (spokes)")
    a = ap.parse_args(argv)
    if a.root:
        from arap_hierarchy import defaust_case  # this script's folder, as run
        name, V, F, h, T = defaust_case(a.root, 0, 1)
        for row in run_case(name, V, F, h, T, "spokes", max(3, a.reps // 10)):
            print(json.dumps(row), flush=True)
    for name in a.cases.split(","):
        for row in run_case(name, *CASES[name](), a.energy, a.reps):
            print(json.dumps(row), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
