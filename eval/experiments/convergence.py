"""Time to accuracy of the ARAP solvers: ``python -m eval experiment=convergence``.
Floor 4 of eval/ (eval/experiments/, tests/test_layering.py); notes: docs/implementation.md.

For each case (a subdivided plane with its boundary fixed and a central disc lifted,
:func:`sshade.arap.problems.lifted_plane`; the first case of the configured dataset, by
default a DeFAUST case at 150k-200k vertices), the distance to the deep-converged
full-resolution spokes-and-rims minimiser (:func:`eval.metrics.reference.reference_solution`,
cached) is traced against wall time for:"""
from __future__ import annotations

import dataclasses
import logging
import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, List  # OmegaConf 2.3 reads typing's generics

import numpy as np
from omegaconf import MISSING

from eval import datasets
from eval.config_schema import section_reader
from eval.experiments.experiment_registry import register_experiment
from eval.metrics.reference import reference_solution, status_words
from eval.present.figures import safe_figure
from eval.present.measures import label as measure_label
from eval.run.paths import abs_path
from eval.run.runinfo import collect_runinfo, finish_run, write_runinfo
from eval.run.spec import DatasetSpec, EvalSpec, ReferenceOptions
from harness.checks import check_fields, checked_field
from sshade import deform
from sshade.arap import ArapOptions, rigid_fit, solve_arap
from sshade.arap.problems import lifted_plane
from sshade.errors import SShaDeError
from sshade.files import atomic_write
from sshade.pipeline import effective_params

__all__ = ["ConvergenceConfig", "run_convergence", "libigl_curve", "solver_curve", "time_to", "CURVE_OPTIONS"]

log = logging.getLogger("eval")
#: the iteration cap of :func:`solver_curve`'s solves (the time budget usually stops them first)
CURVE_MAX_ITER = 5000
#: :func:`solver_curve`'s solver options when none are given: L-BFGS on the spokes-and-rims
#: energy, 300 s, at most :data:`CURVE_MAX_ITER` iterations (change a field with
#: :func:`dataclasses.replace`)
CURVE_OPTIONS = ArapOptions(accelerate="lbfgs", time_budget_s=300.0, max_iter=CURVE_MAX_ITER)


def _dist(U, ref_U, diag) -> tuple[float, float]:
    d = np.linalg.norm(U - ref_U, axis=1) / diag * 100.0
    return float(d.mean()), float(d.max())


def libigl_curve(V, F, handles, targets, ref_U, *, energy: str = "spokes_and_rims", time_budget_s: float = 300.0,
                 stop_pct: float = 1e-3, max_iter: int = 100000) -> list[dict]:
    """libigl's local/global (``igl.arap_solve``, one iteration per call) from the rigid
    fit of the handles, traced against a reference.

    Parameters
    ----------
    V : (n, 3) float64, F : (m, 3) int64, handles : (h,) int64, targets : (h, 3) float64.
    ref_U : (n, 3) float64, the reference minimiser.
    energy : ``"spokes"`` or ``"spokes_and_rims"``.
    time_budget_s : stop once the timed iterations have taken this long (seconds).
    stop_pct : stop once the mean distance is below this (% of the diagonal).
    max_iter : iteration cap.

    Returns
    -------
    list of dicts ``iteration``, ``time_s`` (precomputation + iterations, distance
    evaluations excluded), ``ref_mean_pct``, ``ref_max_pct``; the first row is the start.
    """
    import igl

    V = np.ascontiguousarray(V, np.float64)
    F = np.ascontiguousarray(F, np.int64)
    b = np.ascontiguousarray(handles, np.int32)
    bc = np.ascontiguousarray(targets, np.float64)
    diag = float(np.linalg.norm(V.max(0) - V.min(0)))
    t0 = time.perf_counter()
    R, t = rigid_fit(V[handles], bc)
    U = V @ R.T + t
    U[b] = bc
    data = igl.ARAPData()
    data.energy = igl.ARAP_ENERGY_TYPE_SPOKES if energy == "spokes" else igl.ARAP_ENERGY_TYPE_SPOKES_AND_RIMS
    data.max_iter = 1
    igl.arap_precomputation(V, F, 3, b, data)
    elapsed = time.perf_counter() - t0
    m, x = _dist(U, ref_U, diag)
    rows = [{"iteration": 0, "time_s": elapsed, "ref_mean_pct": m, "ref_max_pct": x}]
    for it in range(1, max_iter + 1):
        t1 = time.perf_counter()
        U = igl.arap_solve(bc, data, U)
        elapsed += time.perf_counter() - t1
        m, x = _dist(U, ref_U, diag)
        rows.append({"iteration": it, "time_s": elapsed, "ref_mean_pct": m, "ref_max_pct": x})
        if m < stop_pct or elapsed > time_budget_s:
            break
    return rows


def solver_curve(V, F, handles, targets, ref_U, options: ArapOptions | None = None, *, U0=None,
                 t_offset: float = 0.0) -> tuple[list[dict], object]:
    """:func:`sshade.arap.solve_arap` traced against a reference (arguments as
    :func:`libigl_curve`; ``options`` :func:`~sshade.arap.solve_arap`'s, None:
    :data:`CURVE_OPTIONS`; ``U0`` a start, ``t_offset`` seconds added to every time, e.g.
    the time SShaDe took to produce ``U0``). Returns ``(rows, result)``; the last row is
    the returned result."""
    diag = float(np.linalg.norm(V.max(0) - V.min(0)))
    if U0 is None:
        R, t = rigid_fit(V[handles], targets)
        start = V @ R.T + t
        start[handles] = targets
    else:
        start = np.asarray(U0, np.float64)
    m0, x0 = _dist(start, ref_U, diag)
    rows: list[dict] = [{"iteration": 0, "time_s": t_offset, "ref_mean_pct": m0, "ref_max_pct": x0}]
    spent = {"cb": 0.0}
    t0 = time.perf_counter()

    def cb(k, U, E, gn):
        t1 = time.perf_counter()
        m, x = _dist(U, ref_U, diag)
        rows.append({"iteration": int(k), "time_s": t_offset + (t1 - t0) - spent["cb"], "ref_mean_pct": m,
                     "ref_max_pct": x, "energy": float(E), "gnorm": float(gn)})
        spent["cb"] += time.perf_counter() - t1
        return False

    res = solve_arap(V, F, handles, targets, CURVE_OPTIONS if options is None else options, U0=U0, callback=cb)
    total = t_offset + (time.perf_counter() - t0) - spent["cb"]
    m, x = _dist(res.V, ref_U, diag)
    rows.append({"iteration": int(res.iterations), "time_s": total, "ref_mean_pct": m, "ref_max_pct": x,
                 "energy": float(res.info.get("energy", math.nan)), "gnorm": float(res.info.get("gnorm", math.nan))})
    return rows, res


def time_to(rows: list[dict], pct: float) -> float:
    """First ``time_s`` at which ``ref_mean_pct`` is below ``pct`` (NaN if never)."""
    for r in rows:
        if r["ref_mean_pct"] < pct:
            return float(r["time_s"])
    return float("nan")


@dataclass
class PlaneConfig:
    """``convergence.plane``: the lifted plane's ``lift`` (a fraction of its side) and
    ``n_target`` (vertices)."""

    lift: float = checked_field(float, default=0.2)
    n_target: int = checked_field(int, min=4, default=40000)


@dataclass
class ConvergenceSShaDeConfig:
    """``convergence.sshade``: the sampling counts ``k`` to run (an integer or a list; None:
    1 and ``sshade.n_samplings``) and ``refine_k`` (SShaDe + refine starts from that run)."""

    k: Any = checked_field(list[int], min=1, max=10_000, allow_none=True, default=None)
    refine_k: int = checked_field(int, min=1, default=MISSING)


@dataclass
class ConvergenceConfig:
    """The ``convergence`` section (conf/experiment/convergence.yaml), typed and checked: the
    ``cases`` (``plane``, ``dataset``), the ``plane``, the ``dataset_case``, the ``energy``,
    each iterative solver's ``time_budget_s`` (seconds as written), libigl's ``stop_pct``,
    the table's ``target_pct``, whether libigl runs (``libigl``) and SShaDe's counts
    (``sshade``). Made by :func:`eval.config_schema.typed_section` at the door, whose
    ``OmegaConf.to_object`` runs :meth:`__post_init__`: SShaDeError naming the key for a
    number out of range, ``sshade.k`` not integers in [1, 10000] or an unknown case;
    ``cases`` and ``sshade.k`` become tuples."""

    cases: List[str] = field(default_factory=list)
    plane: PlaneConfig = field(default_factory=PlaneConfig)
    dataset_case: int = checked_field(int, min=0, default=0)
    energy: str = "spokes_and_rims"
    time_budget_s: Any = checked_field(float, min=0, default=300)
    stop_pct: float = checked_field(float, min=0, default=0.001)
    target_pct: float = checked_field(float, min=0, default=0.05)
    libigl: bool = True
    sshade: ConvergenceSShaDeConfig = field(default_factory=ConvergenceSShaDeConfig)

    def __post_init__(self):
        check_fields(self, "convergence")  # plane and sshade too
        for name in self.cases:
            if name not in ("plane", "dataset"):
                raise SShaDeError(f"convergence.cases: unknown case {name!r}; use plane and/or dataset")
        self.cases = tuple(self.cases)
        ks = self.sshade.k
        self.sshade.k = None if ks is None else tuple(ks)


def _cases(opts: ConvergenceConfig, ds: DatasetSpec | None) -> list[tuple[str, tuple]]:
    """(name, (V, F, handles, targets)) of the configured cases."""
    out = []
    for name in opts.cases:
        if name == "plane":
            plane = opts.plane
            out.append((f"plane_{int(plane.n_target // 1000)}k", lifted_plane(plane.lift, n_target=plane.n_target)))
        else:
            root = datasets.dataset_root(ds)
            i = opts.dataset_case
            c = datasets.load_cases(ds.name, root, ds.options, limit=i + 1)[i]
            out.append((f"{ds.name}_{c.name}", (c.V, c.F, c.handles, c.targets)))
    return out


def sampling_counts(opts: ConvergenceConfig, sp: dict) -> list[int]:
    """The sampling counts SShaDe runs with: ``convergence.sshade.k``, or when it is null
    ``[1, n_samplings]`` (``n_samplings`` of ``sp``, the run's SShaDe parameters)."""
    ks = opts.sshade.k
    return [int(k) for k in (ks if ks is not None else dict.fromkeys([1, int(sp["n_samplings"])]))]


def run_convergence(spec: EvalSpec) -> dict:
    """The experiment (module docstring) of ``spec.experiment.options``
    (:class:`ConvergenceConfig`, ``conf/experiment/convergence.yaml``).

    Returns dict ``out_dir``, ``table`` (DataFrame), ``curves`` (DataFrame), ``paths``.

    Raises
    ------
    SShaDeError on a bad SShaDe parameter or dataset, before any solver runs.
    """
    import pandas as pd

    opts = spec.experiment.options
    out_dir = abs_path(spec.output.out_dir)
    sp = spec.sshade
    cases = _cases(opts, spec.dataset)
    info = collect_runinfo(spec.record(), seeds={"sshade": int(sp["seed"])},
                           extra={"status": "running", "sshade_params": effective_params(sp)})
    write_runinfo(out_dir / "run.json", info)
    t_start = time.perf_counter()
    curves, table = [], []
    for cname, (V, F, h, T) in cases:
        c_curves, c_table = _case_curves(opts, spec.reference, cname, np.asarray(V, np.float64),
                                         np.asarray(F, np.int64), h, T, sp)
        curves += c_curves
        table += c_table
    cdf = pd.DataFrame(curves)
    tdf = pd.DataFrame(table)
    paths = {}
    for name, df in (("curves.csv", cdf), ("table.csv", tdf)):
        with atomic_write(out_dir / name, "w", newline="") as fh:
            df.to_csv(fh, index=False, float_format="%.6g")
        paths[name] = out_dir / name
    p = safe_figure("convergence", convergence_figure, cdf, tdf, out_dir / "convergence.png",
                    target_pct=opts.target_pct)
    if p is not None:
        paths["figure"] = p
    md = _markdown(tdf, opts.target_pct, opts.time_budget_s)
    finish_run(out_dir, md, paths, info, n_cases=len(cases), n_errors=0, wall_s=time.perf_counter() - t_start)
    return {"out_dir": out_dir, "table": tdf, "curves": cdf, "paths": paths}


def _case_curves(opts: ConvergenceConfig, reference: ReferenceOptions, cname: str, V, F, h, T,
                 sp: dict) -> tuple[list[dict], list[dict]]:
    """One case: its reference (``reference``: its cache and limits), then every solver's
    curve; returns the curve rows and the table rows (one per solver)."""
    budget, target, energy = opts.time_budget_s, opts.target_pct, opts.energy
    curves, table = [], []
    ref = reference_solution(V, F, h, T, energy=energy, cache_dir=reference.cache, max_iter=reference.max_iter,
                             time_budget_s=reference.time_budget_s)
    log.info("%s: %d vertices; reference %s (%s, %s iterations)", cname, len(V),
             "cached" if ref.info.get("cached") else f"computed in {ref.info.get('seconds')} s",
             status_words(ref.info.get("status")), ref.info.get("iterations"))

    def add(solver, rows, *, iterations, stopped):
        for r in rows:
            curves.append({"case": cname, "solver": solver, **r})
        last = rows[-1]
        table.append({"case": cname, "n_vertices": len(V), "solver": solver, "iterations": iterations,
                      "time_s": last["time_s"], "time_to_target_s": time_to(rows, target),
                      "ref_mean_pct": last["ref_mean_pct"], "ref_max_pct": last["ref_max_pct"],
                      "stopped": stopped})
        log.info("%s %-22s %6s it. %8.2f s  mean %.4f%%  max %.3f%%  (%s)", cname, solver, iterations,
                 last["time_s"], last["ref_mean_pct"], last["ref_max_pct"], stopped)

    if opts.libigl:
        rows = libigl_curve(V, F, h, T, ref.U, energy=energy, time_budget_s=budget, stop_pct=opts.stop_pct)
        last = rows[-1]
        add("libigl local/global", rows, iterations=last["iteration"],
            stopped=("reached stop_pct" if last["ref_mean_pct"] < opts.stop_pct else
                     f"time budget {budget:g} s"))
    options = dataclasses.replace(CURVE_OPTIONS, energy=energy, time_budget_s=budget)
    for acc, label in (("lbfgs", "L-BFGS (ours)"), ("anderson", "Anderson (ours)")):
        rows, res = solver_curve(V, F, h, T, ref.U, dataclasses.replace(options, accelerate=acc))
        add(label, rows, iterations=res.iterations, stopped=str(res.info.get("status")))
    for k in sampling_counts(opts, sp):
        t0 = time.perf_counter()
        Vs, si = deform(V, F, h, T, return_info=True, **{**sp, "n_samplings": int(k)})
        dt = time.perf_counter() - t0 - si["compile_s"]  # numba's first-call compilation is not SShaDe's time
        m, x = _dist(Vs, ref.U, float(np.linalg.norm(V.max(0) - V.min(0))))
        add(f"SShaDe k={int(k)}", [{"iteration": int(si["iterations"]), "time_s": dt, "ref_mean_pct": m,
                                    "ref_max_pct": x}],
            iterations=int(si["iterations"]), stopped="low-res " + ("converged" if si["converged"] else "capped"))
        if int(k) == opts.sshade.refine_k:
            rows, res = solver_curve(V, F, h, T, ref.U, options, U0=Vs, t_offset=dt)
            add("SShaDe + refine", rows, iterations=res.iterations, stopped=str(res.info.get("status")))
    return curves, table


def _markdown(tdf, target: float, budget: float) -> str:
    lines = ["### convergence: distance to the deep-converged spokes-and-rims minimiser against wall time", "",
             f"Distances in % of the bounding-box diagonal; 'to {target:g}%': first time the mean distance is "
             f"below {target:g}% (-- never within the {budget:g} s budget). Times include precomputation, "
             "exclude the distance evaluations.", "",
             f"| Case | Vertices | Solver | Iterations | {measure_label('time_s')} | To {target:g}% (s) "
             "| Mean (%) | Max (%) | Stopped |",
             "|---|---:|---|---:|---:|---:|---:|---:|---|"]
    for _, r in tdf.iterrows():
        tt = "--" if not math.isfinite(r["time_to_target_s"]) else f"{r['time_to_target_s']:.2f}"
        lines.append(f"| {r['case']} | {int(r['n_vertices'])} | {r['solver']} | {int(r['iterations'])} | "
                     f"{r['time_s']:.2f} | {tt} | {r['ref_mean_pct']:.4f} | {r['ref_max_pct']:.3f} | {r['stopped']} |")
    return "\n".join(lines) + "\n"


def convergence_figure(curves, table, path, *, target_pct: float = 0.05) -> Path:
    """One log-log panel per case: mean distance to the reference (% of the diagonal)
    against wall time (s), a line per iterative solver, a marker per SShaDe run, the
    target as a dashed line. Written atomically as a PNG; returns the path."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cases = list(dict.fromkeys(curves["case"]))
    fig, axes = plt.subplots(1, len(cases), figsize=(6.0 * len(cases), 4.4), squeeze=False)
    styles = {"libigl local/global": ("tab:gray", "-"), "Anderson (ours)": ("tab:blue", ":"),
              "L-BFGS (ours)": ("tab:blue", "-"),
              "SShaDe + refine": ("tab:red", "-")}
    for ax, c in zip(axes[0], cases):
        g = curves[curves["case"] == c]
        for solver, s in g.groupby("solver", sort=False):
            y = np.maximum(s["ref_mean_pct"].to_numpy(), 1e-8)
            if solver in styles:
                col, ls = styles[solver]
                ax.plot(s["time_s"], y, ls, color=col, label=solver, lw=1.6)
            else:
                ax.plot(s["time_s"], y, "o", ms=8, label=solver,
                        color="tab:orange" if solver.endswith("=1") else "tab:green")
        ax.axhline(target_pct, color="k", ls="--", lw=0.8, label=f"{target_pct:g}% of diagonal")
        ax.set_xscale("log")
        ax.set_yscale("log")
        n = int(table[table["case"] == c]["n_vertices"].iloc[0])
        ax.set_title(f"{c} ({n:,} vertices)")
        ax.set_xlabel("wall time (s)")
        ax.set_ylabel("mean distance to minimiser (% of diagonal)")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
    fig.tight_layout()
    path = Path(path)
    with atomic_write(path, "wb") as fh:
        fig.savefig(fh, format="png", dpi=110)
    plt.close(fig)
    return path


register_experiment("convergence", run_convergence,
                    options=section_reader("convergence", ConvergenceConfig, absent="use experiment=convergence"))
