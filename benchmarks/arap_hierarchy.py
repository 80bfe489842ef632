"""Converged full-resolution ARAP (spokes, the ``ARAP`` baseline's energy and default
criterion) from coarse-level starts, counting fine-level iterations and weighted coarse
ones (a level's iterations times its vertices over the fine mesh's); the record:
benchmarks/records/arap_hierarchy.md. Starts of the fine solve:

* ``rigid``: the rigid fit of the handles (the baseline's default start);
* ``N:R``: a solve on one remesh with ``N`` samples (``sshade.remesh.remesh``, seed 0, the
  handles required), every fine vertex given the rotation of its Voronoi region (``R0``);
  ``6000:R`` is the baseline's ``start="coarse"``;
* ``N:U``: the same low-res solve, its POSITIONS carried to the fine mesh
  (:func:`sshade.smooth_transfer.smooth_decode` over :func:`sshade.projection.project_to_fans`,
  SShaDe's own transfer) and given as ``U0``;
* ``A>B>C:R`` / ``A>B>C:U``: a chain of remeshes, each level solved to the default
  criterion from the previous level's positions carried as above (the first from its
  rigid start), the fine solve from the last level's rotations / positions.

Every solve runs in the baseline's unit frame with ``threads=1`` (iteration counts are
deterministic for a thread count); energies are reported in mesh units. The fine solves
are traced (backtracking evaluations, L-BFGS resets, curvature pairs skipped, the scaling
``gamma``, the first iteration at which each half of the criterion holds, the energy gap
and gradient norm at a few iterations). ``--deep START=N`` continues a DeFAUST result for
at most N iterations under ``DEEP_CRITERION`` (a stop early in a slow valley against
another stationary point); ``--save-dir`` / ``--snapshots`` keep results and iterates,
``--cells`` splits the energy changes between them over the vertex cells.

    python benchmarks/arap_hierarchy.py --root /work/main/data/defaust
    python benchmarks/arap_hierarchy.py --cases twisted_bar,bent_cylinder,lifted_plane

Prints one JSON line per run and per coarse level (``--out DIR`` also appends them to
DIR/runs.jsonl). ``--out``, ``--save-dir`` and ``--trace-dir`` are folders that are new,
empty or this benchmark's earlier output (continued, not replaced).
The iterations are patched only to be counted (``sshade.arap.solver.LBFGS`` and
``_Stepper.local`` wrapped): no arithmetic changes.
"""
from __future__ import annotations

import argparse
import contextlib
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the repository, as the other benchmarks

import sshade.arap.solver as arap_solver  # noqa: E402
from eval.run.outdir import claim_output_dir  # noqa: E402
from sshade.arap import DEEP_CRITERION, DEFAULT_CRITERION, ArapOptions, build_operators, solve_arap  # noqa: E402
from sshade.arap.accelerate import LBFGS  # noqa: E402
from sshade.arap.problems import CASES  # noqa: E402
from sshade.mesh.unit_frame import unit_frame  # noqa: E402
from sshade.projection import project_to_fans  # noqa: E402
from sshade.remesh import mesh_topology, remesh  # noqa: E402
from sshade.smooth_transfer import smooth_decode  # noqa: E402

ENERGY = "spokes"
#: the chain on DeFAUST (samples per level, coarse to fine); the synthetic cases take the
#: same fractions of their vertex count
DEFAUST_CHAINS = ((6000,), (25000,), (6000, 25000), (6000, 25000, 80000))
DEFAUST_N = 168853  # s00_p01's vertices: the synthetic chains are these fractions of their meshes
LEVEL_CAP = 5000  # baselines.coarse_start.COARSE_MAX_ITER

# ---------------------------------------------------------------- tracing (no arithmetic changed)
TRACE: dict = {}
#: iteration -> iterate (unit frame) of the next fine solve, filled by its callback (--snapshots)
SNAPSHOTS: dict = {}


class TracedLBFGS(LBFGS):
    """The solver's L-BFGS, recording per direction: the local steps evaluated since the
    last direction (accepted + backtracks), the history size before/after, whether a new
    curvature pair was stored, gamma, and a fresh history (reset by the loop after a
    failed line search, or inside ``direction`` for a non-descent direction)."""

    def direction(self, x, g, grad=None):
        if TRACE.get("on"):
            n_before, pos_before, had_prev = self.n_hist, self.pos, self.have_prev
        d, slope = super().direction(x, g, grad)
        if TRACE.get("on"):
            TRACE["dirs"].append({"n_local": TRACE["n_local"], "n_before": n_before, "n_after": self.n_hist,
                                  "pair": bool(had_prev and self.pos != pos_before), "had_prev": had_prev,
                                  "gamma": float(self.gamma), "slope": float(slope)})
        return d, slope


_local = arap_solver._Stepper.local


def _traced_local(self, x):
    TRACE["n_local"] = TRACE.get("n_local", 0) + 1
    return _local(self, x)


arap_solver.LBFGS = TracedLBFGS
arap_solver._Stepper.local = _traced_local


def summarize_trace(res) -> dict:
    """Backtracks, resets, skipped pairs, gamma, and when each half of the criterion first holds."""
    dirs = TRACE["dirs"]
    crit = DEFAULT_CRITERION
    E = np.array(res.info["energy_history"])
    G = np.array(res.info["gnorm_history"])
    rel = np.full(len(E), np.inf)
    rel[1:] = (E[:-1] - E[1:]) / np.abs(E[1:])
    # local steps between consecutive directions: 1 accepted + backtracks (+ fallbacks)
    nl = np.array([d["n_local"] for d in dirs] + [TRACE["n_local"]])
    evals = np.diff(nl)
    # a history dropped: by the loop after a failed line search (the next direction starts
    # empty though the last one ended with pairs) or inside direction() (not a descent one)
    resets = sum(1 for i in range(1, len(dirs)) if dirs[i]["n_before"] == 0 and dirs[i - 1]["n_after"] > 0)
    resets += sum(1 for d in dirs if d["n_after"] == 0 and (d["n_before"] > 0 or d["pair"]))
    skipped = sum(1 for d in dirs if d["had_prev"] and not d["pair"])
    gam = np.array([d["gamma"] for d in dirs])
    first_e = int(np.argmax(rel < crit.etol)) if (rel < crit.etol).any() else None
    first_g = int(np.argmax(G < crit.gtol)) if (G < crit.gtol).any() else None
    out = {"backtracks": int((evals - 1).clip(0).sum()), "steps_with_backtrack": int((evals > 1).sum()),
           "lbfgs_resets": int(resets), "pairs_skipped": int(skipped),
           "gamma_median": float(np.median(gam)) if len(gam) else None,
           "gamma_max": float(gam.max()) if len(gam) else None,
           "first_it_rel_below_etol": first_e, "first_it_gnorm_below_gtol": first_g}
    n = len(G)
    marks = [k for k in (0, 10, 25, 50, 100, 200, 300, 400, 500, 600, 800, 1000) if k < n] + [n - 1]
    out["gnorm_at"] = {str(k): float(G[k]) for k in marks}
    out["energy_gap_at"] = {str(k): float((E[k] - E[-1]) / abs(E[-1])) for k in marks}
    return out


# ---------------------------------------------------------------- cases
def defaust_case(root: str, subject: int, pose: int):
    from defaust.dataset import load
    case = next(c for c in load(root, subjects=[subject], partial=True) if c.pose == pose)
    return f"s{subject:02d}_p{pose:02d}", case.V, case.F, case.handles, case.targets


def synthetic_case(name: str):
    V, F, h, T = CASES[name]()
    return name, V, F, h, T


# ---------------------------------------------------------------- solves
def solve(V, F, h, T, ops, *, U0=None, R0=None, criterion=DEFAULT_CRITERION, max_iter=None, trace=False,
          per_iter=None):
    """One converged solve (threads=1); ``trace``: the summary of :func:`summarize_trace`;
    ``per_iter``: a path, the per-iteration record (energy, gnorm, local steps evaluated,
    gamma, largest and RMS vertex move; unit frame) saved there as .npz."""
    TRACE.clear()
    TRACE.update(on=trace or per_iter is not None, dirs=[], n_local=0)
    opt = ArapOptions(energy=ENERGY, threads=1, criterion=criterion, max_iter=max_iter)
    moves, prev = [], {}

    def callback(k, U, E, gn):
        if k in SNAPSHOTS:
            SNAPSHOTS[k] = U.copy()
        if "U" in prev:
            d = np.sqrt(((U - prev["U"]) ** 2).sum(1))
            moves.append((d.max(), np.sqrt((d * d).mean())))
        prev["U"] = U.copy()
        return False

    res = solve_arap(V, F, h, T, opt, U0=U0, R0=R0, operators=ops,
                     callback=callback if per_iter or SNAPSHOTS else None)
    summ = summarize_trace(res) if trace else {}
    if per_iter:
        nl = np.array([d["n_local"] for d in TRACE["dirs"]] + [TRACE["n_local"]])
        np.savez(per_iter, energy=np.array(res.info["energy_history"]), gnorm=np.array(res.info["gnorm_history"]),
                 evals=np.diff(nl), gamma=np.array([d["gamma"] for d in TRACE["dirs"]]),
                 n_hist=np.array([d["n_after"] for d in TRACE["dirs"]]), moves=np.array(moves))
    TRACE["on"] = False
    return res, summ


class Level:
    """One remesh of the fine mesh: its low-res problem, operators and the projection of
    every fine vertex onto it (for carrying positions)."""

    def __init__(self, V, F, h, n_low, topo):
        t = time.perf_counter()
        self.rm = rm = remesh(V, F, int(n_low), seed=0, required=h, topology=topo)
        self.V, self.F, self.h = V[rm.seeds], rm.F, rm.label[h]
        self.n = len(rm.seeds)
        self.ops = build_operators(self.V, self.F, ENERGY)
        self.P = project_to_fans(V, rm.label, self.V, self.F)
        self.setup_s = time.perf_counter() - t

    def carry(self, Vfine, U):
        """Fine positions (n, 3) from this level's deformed positions ``U`` (k, 3)."""
        return smooth_decode(Vfine, self.P.tri, self.P.bary, self.V, U, self.F)

    def rotations(self, U):
        """Fine rotations (n, 3, 3): each fine vertex its region's."""
        return np.ascontiguousarray(self.ops.rotations(U)[self.rm.label])


def run_case(name, V0, F, h, T0, chains, deep, emit, rigid=True, trace_dir=None, kinds="RU", save_dir=None):
    """Every start on one case: ``rigid`` (when ``rigid``), then for each chain (a tuple of
    sample counts, coarse to fine) ``<chain>:R`` and ``<chain>:U``."""
    frame = unit_frame(V0)
    V, T = frame.to_unit(V0), frame.to_unit(T0)
    n = len(V)
    diag = float(np.linalg.norm(V0.max(0) - V0.min(0)))
    t = time.perf_counter()
    ops = build_operators(V, F, ENERGY)
    topo = mesh_topology(V, F)
    emit({"case": name, "n": n, "handles": int(len(h)), "chains": [list(c) for c in chains],
          "setup_s": round(time.perf_counter() - t, 1)})
    levels, solved = {}, {}  # n_low -> Level; chain prefix -> (row, U)

    def level(nl):
        if nl not in levels:
            levels[nl] = Level(V, F, h, nl, topo)
        return levels[nl]

    def solve_chain(chain):
        """The last level of ``chain`` solved from the previous level's carried positions
        (the first from the rigid fit); rows emitted once per prefix."""
        if chain in solved:
            return solved[chain]
        L = level(chain[-1])
        U0 = None
        if len(chain) > 1:
            _, Up = solve_chain(chain[:-1])
            U0 = level(chain[-2]).carry(V, Up)[L.rm.seeds]
        res, _ = solve(L.V, L.F, L.h, T, L.ops, U0=U0, max_iter=LEVEL_CAP)
        row = {"case": name, "chain": ">".join(map(str, chain)), "n_low": int(chain[-1]), "n": L.n,
               "start": "rigid" if U0 is None else "carried", "iterations": res.iterations,
               "status": res.info["status"], "energy": frame.energy(res.info["energy"]), "gnorm": res.info["gnorm"],
               "weight": L.n / n, "weighted_iterations": res.iterations * L.n / n,
               "setup_s": round(L.setup_s, 1), "s_per_iter": round(res.solve_s / max(res.iterations, 1), 4)}
        emit(row)
        solved[chain] = (row, res.V)
        return solved[chain]

    runs = (["rigid"] if rigid else []) + [f"{'>'.join(map(str, c))}:{k}" for c in chains for k in kinds]
    results = {}
    for s in runs:
        kw, coarse_w = {}, 0.0
        if s != "rigid":
            cs, kind = s.split(":")
            chain = tuple(int(x) for x in cs.split(">"))
            _, Uc = solve_chain(chain)
            coarse_w = sum(solved[chain[:i + 1]][0]["weighted_iterations"] for i in range(len(chain)))
            L = level(chain[-1])
            if kind == "U":
                kw["U0"] = L.carry(V, Uc)
            else:
                kw["R0"] = L.rotations(Uc)
        res, summ = solve(V, F, h, T, ops, trace=True,
                          per_iter=f"{trace_dir}/{name}_{s.replace(':', '_').replace('>', '-')}.npz"
                          if trace_dir else None, **kw)
        results[s] = res.V
        if save_dir:
            tag = s.replace(':', '_').replace('>', '-')
            np.save(f"{save_dir}/{name}_{tag}.npy", frame.from_unit(res.V))
            for k, Uk in SNAPSHOTS.items():
                if Uk is not None:
                    np.save(f"{save_dir}/{name}_{tag}_it{k}.npy", frame.from_unit(Uk))
        SNAPSHOTS.update(dict.fromkeys(SNAPSHOTS))
        row = {"case": name, "start": s, "fine_iterations": res.iterations, "status": res.info["status"],
               "energy": frame.energy(res.info["energy"]), "gnorm": res.info["gnorm"],
               "rel_decrease": res.info["rel_decrease"], "coarse_weighted": round(coarse_w, 1),
               "total_weighted": round(res.iterations + coarse_w, 1),
               "s_per_iter": round(res.solve_s / max(res.iterations, 1), 4), **summ}
        if "rigid" in results and s != "rigid":
            d = np.linalg.norm(res.V - results["rigid"], axis=1) * frame.scale
            row["vs_rigid_mean_pct"] = float(100 * d.mean() / diag)
            row["vs_rigid_max_pct"] = float(100 * d.max() / diag)
        emit(row)
    for s in deep:
        if s in results:
            res, _ = solve(V, F, h, T, ops, U0=results[s], criterion=DEEP_CRITERION, max_iter=deep[s])
            emit({"case": name, "deep_from": s, "iterations": res.iterations, "status": res.info["status"],
                  "energy": frame.energy(res.info["energy"]), "gnorm": res.info["gnorm"],
                  "energy_history_every_100": [frame.energy(e) for e in res.info["energy_history"][::100]]})


def cell_analysis(root: str, subject: int, pose: int, save_dir: str, emit) -> None:
    """Where the energy goes between the saved rigid-start iterates (``--snapshots``,
    ``--save-dir``) and against the saved ``6000:U`` result: the change of the per-cell
    (per-vertex) spokes energies split into the cells whose energy is negative at the
    rigid start's result (cells at sliver triangles: libigl's cotangent weights are
    negative on obtuse angles), the other cells touching a negative edge weight, and the
    rest; and the largest vertex moves of each stretch (% of the diagonal)."""
    import igl
    import scipy.sparse as sp
    name, V, F, _, _ = defaust_case(root, subject, pose)
    n, diag = len(V), float(np.linalg.norm(V.max(0) - V.min(0)))
    ops = build_operators(V, F, ENERGY)

    def cells(U):
        R, Ek = np.empty((n, 3, 3)), np.empty(n)
        ops.local_step(np.ascontiguousarray(U), R, Ek, None, 1, None)
        return Ek

    base = Path(save_dir) / name
    snaps = {int(p.stem.rsplit("_it", 1)[1]): np.load(p) for p in Path(save_dir).glob(f"{name}_rigid_it*.npy")}
    snaps = dict(sorted(snaps.items()))
    snaps["final"] = np.load(f"{base}_rigid.npy")
    other = {}
    if Path(f"{base}_6000_U.npy").exists():
        other["6000:U"] = np.load(f"{base}_6000_U.npy")
    Ek = {k: cells(U) for k, U in {**snaps, **other}.items()}
    C = sp.triu(igl.cotmatrix(V, F), 1).tocoo()
    neg_w = C.data < 0
    touch = np.zeros(n, bool)
    touch[C.row[neg_w]] = touch[C.col[neg_w]] = True
    negc = Ek["final"] < 0
    ang = igl.internal_angles(V, F).max(1)
    vmax = np.zeros(n)
    np.maximum.at(vmax, F.ravel(), np.repeat(ang, 3))
    emit({"case": name, "cells": "mesh", "negative_edge_weights": int(neg_w.sum()), "edges": int(len(neg_w)),
          "vertices_at_negative_weight": int(touch.sum()), "negative_cells_final": int(negc.sum()),
          "negative_part_final": float(Ek["final"][negc].sum()), "positive_part_final": float(Ek["final"][~negc].sum()),
          "median_max_incident_angle_deg_negative_cells": float(np.degrees(np.median(vmax[negc]))),
          "median_max_incident_angle_deg_all": float(np.degrees(np.median(vmax)))})
    keys = list(snaps)
    pairs = list(zip(keys[:-1], keys[1:])) + [(k, "final") for k in other]
    for a, b in pairs:
        d = Ek[b] - Ek[a]
        Ua, Ub = {**snaps, **other}[a], snaps[b]
        mv = np.linalg.norm(Ub - Ua, axis=1)
        emit({"case": name, "cells": f"{a}->{b}", "energy_change": float(d.sum()),
              "negative_cells": float(d[negc].sum()), "other_cells_at_negative_weights": float(d[touch & ~negc].sum()),
              "rest": float(d[~touch].sum()), "move_mean_pct": float(100 * mv.mean() / diag),
              "move_max_pct": float(100 * mv.max() / diag)})


def main():
    ap = argparse.ArgumentParser(prog="python benchmarks/arap_hierarchy.py", description=__doc__.splitlines()[0])
    ap.add_argument("--root", default=None, help="DeFAUST build (its case --defaust is run when given)")
    ap.add_argument("--defaust", default="0:1", help="subject:pose of the DeFAUST case (default 0:1)")
    ap.add_argument("--cases", default="", help="comma-separated sshade.arap.problems.CASES names")
    ap.add_argument("--chains", default=";".join(",".join(map(str, c)) for c in DEFAUST_CHAINS),
                    help="semicolon-separated chains of DeFAUST sample counts, coarse to fine; the synthetic "
                         "cases take the same fractions of their vertex count")
    ap.add_argument("--no-rigid", action="store_true", help="skip the rigid start")
    ap.add_argument("--deep", default="", help="START=N,...: continue those DeFAUST results under "
                                               "DEEP_CRITERION for at most N iterations")
    ap.add_argument("--out", default=None, help="also append the JSON lines to DIR/runs.jsonl")
    ap.add_argument("--kinds", default="RU", help="carried to the fine level: R (rotations), U (positions)")
    ap.add_argument("--save-dir", default=None, help="save each fine result (mesh units, .npy) here")
    ap.add_argument("--snapshots", default="", help="comma-separated iterations whose iterates --save-dir "
                                                    "also keeps (every fine solve)")
    ap.add_argument("--cells", action="store_true", help="only the per-cell analysis of the results saved in "
                                                         "--save-dir (cell_analysis)")
    ap.add_argument("--trace-dir", default=None, help="save each fine solve's per-iteration record here (.npz)")
    a = ap.parse_args()
    chains = [tuple(int(x) for x in c.split(",")) for c in a.chains.split(";") if c]
    SNAPSHOTS.update(dict.fromkeys(int(k) for k in a.snapshots.split(",") if k))
    deep = {k: int(v) for k, v in (kv.rsplit("=", 1) for kv in a.deep.split(",") if kv)}

    with contextlib.ExitStack() as stack:
        for opt in ("out", "trace_dir") + (() if a.cells else ("save_dir",)):  # --cells reads --save-dir
            if getattr(a, opt):
                claim = stack.enter_context(claim_output_dir(getattr(a, opt), "arap_hierarchy", keep=True, option="",
                                                             name="--" + opt.replace("_", "-")))
                setattr(a, opt, str(claim.path))
        _run(a, chains, deep)


def _run(a, chains, deep) -> None:
    def emit(row):
        line = json.dumps(row)
        print(line, flush=True)
        if a.out:
            with open(Path(a.out) / "runs.jsonl", "a") as f:
                f.write(line + "\n")

    if a.cells:
        sub, pose = (int(x) for x in a.defaust.split(":"))
        cell_analysis(a.root, sub, pose, a.save_dir, emit)
        return
    if a.root:
        sub, pose = (int(x) for x in a.defaust.split(":"))
        name, V, F, h, T = defaust_case(a.root, sub, pose)
        run_case(name, V, F, h, T, chains, deep, emit, rigid=not a.no_rigid, trace_dir=a.trace_dir, kinds=a.kinds,
                 save_dir=a.save_dir)
    for cname in [c for c in a.cases.split(",") if c]:
        name, V, F, h, T = synthetic_case(cname)
        sc = [tuple(max(40, int(round(nl / DEFAUST_N * len(V)))) for nl in c) for c in chains]
        run_case(name, V, F, h, T, sc, {}, emit, rigid=not a.no_rigid, trace_dir=a.trace_dir, kinds=a.kinds,
                 save_dir=a.save_dir)


if __name__ == "__main__":
    main()
