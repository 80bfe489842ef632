"""Scaling benchmark (issue "Scalable SShaDe"; paper abstract, §1, Table 1):
``python -m eval experiment=scaling``.
Floor 4 of eval/ (eval/experiments/, tests/test_layering.py); notes: docs/implementation.md.

Parameters: the meshes, handles and budgets from ``scaling.*``
(``conf/experiment/scaling.yaml``); SShaDe's from the method config ``method.SShaDe``
(the ``sshade`` section, the experiment's yaml sets ``sshade.n_low: 6000``;
:attr:`eval.run.spec.EvalSpec.sshade`); Elastic's stopping rule from ``method.Elastic`` (the ``arap``
section; :func:`elastic_params`)."""
from __future__ import annotations

import logging
import math
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, List, Optional  # OmegaConf 2.3 reads typing's generics

import numpy as np

from baselines.fullres_arap import Elastic
from eval.config_schema import section_reader
from eval.datasets.shapes import axis_handles, axis_landmarks
from eval.experiments.experiment_registry import register_experiment
from eval.experiments.scaling.mesh_set import MeshEntry, cache_name, mesh_entries
from eval.experiments.scaling.probe import probe_first_call
from eval.experiments.scaling.scaling_table import write_csv, write_markdown
from eval.metrics.measures import deformation_metrics
from eval.run.memory import PeakMemory, release_freed
from eval.run.paths import abs_path
from eval.run.runinfo import collect_runinfo, write_runinfo
from eval.run.spec import EvalSpec
from harness.checks import check_fields, checked_field
from sshade import deform
from sshade.arap import ArapOptions, arap_deform, make_criterion
from sshade.errors import SShaDeError
from sshade.mesh.io import read_mesh, write_mesh
from sshade.mesh.validate import validate_mesh
from sshade.pipeline import MAX_SEED, warm_sshade
from sshade.warmup import warm_fullres

log = logging.getLogger(__name__)

__all__ = ["ScalingConfig", "build_mesh", "size_mesh", "run_scaling", "elastic_params"]


def build_mesh(V: np.ndarray, F: np.ndarray, n_target: int, *, remesh: bool = True,
               iterations: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """A mesh of about ``n_target`` vertices from ``(V, F)`` (pymeshlab).

    LS3 Loop subdivision (``threshold=PercentageValue(0)``, else short edges are
    skipped) until the mesh has at least ``n_target`` vertices, then isotropic explicit
    remeshing with the edge length that gives ``n_target`` vertices on the same area
    (equilateral triangles: n ~ 2 A / (sqrt(3) L^2)). With ``remesh=False`` the
    subdivided mesh is returned as is.

    Parameters
    ----------
    V : (n, 3) float64; F : (m, 3) int64. n_target : int.

    Returns
    -------
    V2 : (n2, 3) float64; F2 : (m2, 3) int64.
    """
    import pymeshlab as ml
    ms = ml.MeshSet()
    ms.add_mesh(ml.Mesh(V, F))
    while ms.current_mesh().vertex_number() < n_target:
        ms.meshing_surface_subdivision_ls3_loop(iterations=1, threshold=ml.PercentageValue(0))
    if remesh:
        m = ms.current_mesh()
        Vc, Fc = m.vertex_matrix(), m.face_matrix()
        area = 0.5 * np.linalg.norm(np.cross(Vc[Fc[:, 1]] - Vc[Fc[:, 0]], Vc[Fc[:, 2]] - Vc[Fc[:, 0]]), axis=1).sum()
        L = math.sqrt(2 * area / (math.sqrt(3) * n_target))
        ms.meshing_isotropic_explicit_remeshing(iterations=iterations, targetlen=ml.PureValue(L))
    m = ms.current_mesh()
    return np.ascontiguousarray(m.vertex_matrix(), np.float64), np.ascontiguousarray(m.face_matrix(), np.int64)


def elastic_params(spec: EvalSpec) -> dict:
    """Full-resolution Elastic's protocol and stopping rule in this experiment:
    ``protocol``, ``tol``, ``max_iter``, ``etol``, ``gtol`` of the method config
    ``method.Elastic`` (the ``arap`` section)."""
    d = spec.definition(Elastic.name)
    return {k: d.get(k) for k in ("protocol", "tol", "max_iter", "etol", "gtol")}


@dataclass
class ScalingConfig:
    """The ``scaling`` section (conf/experiment/scaling.yaml), typed and checked: the
    ``meshes`` (a list of ``{name, path, remesh}``, or null for ``base_mesh`` with
    ``remesh``) and ``sizes``, the handle draw (``seed``, ``n_per_group``,
    ``region_radius``, ``rotate_deg``, ``translate``), SShaDe's timed calls (``repeat``,
    ``first_call``, ``first_call_timeout_s``), Elastic's (``elastic``, ``elastic_budget_s``,
    ``elastic_max_vertices``: None for every size) and the mesh ``cache`` (null: the
    default). Made by :func:`eval.config_schema.typed_section` at the door, whose
    ``OmegaConf.to_object`` runs :meth:`__post_init__`: SShaDeError naming the key for a
    number out of range, a size below 4 or a bad mesh entry
    (:func:`eval.experiments.scaling.mesh_set.mesh_entries`), before any mesh is built;
    ``meshes`` become :class:`MeshEntry` objects, ``sizes`` a tuple, the times floats."""

    meshes: Any = None
    base_mesh: Optional[str] = None
    remesh: bool = True
    sizes: List[int] = checked_field(list[int], min=4, allow_none=True, default_factory=list)
    seed: int = checked_field(int, min=0, default=0)
    n_per_group: int = checked_field(int, min=1, default=30)
    region_radius: float = checked_field(float, min=0, default=0.06)
    rotate_deg: float = checked_field(float, default=20.0)
    translate: float = checked_field(float, default=0.05)
    repeat: int = checked_field(int, min=1, default=3)
    first_call: bool = True
    first_call_timeout_s: Any = checked_field(float, min=0, default=600)
    elastic: bool = True
    elastic_budget_s: Any = checked_field(float, min=0, default=600)
    elastic_max_vertices: Optional[int] = checked_field(int, min=1, allow_none=True, default=None)
    cache: Optional[str] = "data/scaling"

    def __post_init__(self):
        check_fields(self, "scaling")
        self.meshes = tuple(mesh_entries(vars(self)))
        self.sizes = tuple(self.sizes or ())
        self.cache = str(self.cache or ScalingConfig.cache)


def run_scaling(spec: EvalSpec) -> dict:
    """Run the scaling experiment of ``spec.experiment.options`` (:class:`ScalingConfig`,
    see conf/experiment/scaling.yaml).

    Returns dict ``out_dir``, ``table`` (DataFrame, one row per (mesh, size)).

    Raises
    ------
    SShaDeError on a base mesh file that is not there or a bad SShaDe parameter, before
    any mesh is built.
    """
    import pandas as pd

    sc = spec.experiment.options
    out_dir = abs_path(spec.output.out_dir)
    for e in sc.meshes:
        if not abs_path(e.path).is_file():
            raise SShaDeError(f"scaling: base mesh of {e.name!r} not found: {abs_path(e.path)} "
                              "(scaling.meshes[].path, or scaling.base_mesh=PATH with scaling.meshes=null)")
    sp = spec.sshade
    ep = elastic_params(spec)
    cache = abs_path(sc.cache)  # built meshes, reused by later runs
    info = collect_runinfo(spec.record(), seeds={"scaling": sc.seed, "sshade": int(sp["seed"])},
                           extra={"status": "running"})
    write_runinfo(out_dir / "run.json", info)
    rows = []
    for e in sc.meshes:
        base = _read_base(e)
        for size in sc.sizes:
            rows.append(_size_row(sc, e, base, int(size), cache, sp, ep))
            print(f"[scaling] {rows[-1]}", file=sys.stderr, flush=True)
            write_csv(out_dir / "table.csv", pd.DataFrame(rows))
    df = pd.DataFrame(rows)
    md = write_markdown(out_dir / "table.md", df)
    info.update(status="done", n_rows=len(rows), meshes=[e.name for e in sc.meshes])
    write_runinfo(out_dir / "run.json", info)
    print(md)
    return {"out_dir": out_dir, "table": df}


def _read_base(entry: MeshEntry):
    """``(path, V0, F0, axis landmarks)`` of an entry's base mesh."""
    path = abs_path(entry.path)
    V0, F0 = read_mesh(path)
    return path, V0, F0, axis_landmarks(V0)


def _size_row(sc: ScalingConfig, entry: MeshEntry, base, size: int, cache, sp: dict, ep: dict) -> dict:
    """One row of the table: the mesh of ``entry`` at ``size``, SShaDe warm (compilation
    apart), its first call in a fresh process (``scaling.first_call``) and full-res
    Elastic (``scaling.elastic``, up to ``scaling.elastic_max_vertices``)."""
    mp, V, F, build_s = size_mesh(entry, base[1], base[2], size, cache)
    h, T = _size_handles(sc, base, V)
    row = {"mesh": entry.name, "remesh": entry.remesh, "target": size, "vertices": len(V), "faces": len(F),
           "handles": len(h), "build_s": build_s}
    print(f"[scaling] {entry.name}, {len(V)} vertices: SShaDe ...", file=sys.stderr, flush=True)
    row["sshade_compile_s"] = warm_sshade(sp)  # outside the timings and the memory peak
    repeat = sc.repeat
    late_compile_s, srow = _sshade_row(V, F, h, T, sp, repeat)
    row["sshade_compile_s"] += late_compile_s
    row.update(srow)
    if sc.first_call:
        print(f"[scaling] {entry.name}, {len(V)} vertices: first call in a fresh process ...",
              file=sys.stderr, flush=True)
        row.update(_first_call_row(mp, h, T, sp.as_dict(), repeat, sc.first_call_timeout_s))
    emax = sc.elastic_max_vertices
    if sc.elastic and (emax is None or len(V) <= emax):
        row.update(_elastic_row(V, F, h, T, ep, sc.elastic_budget_s, row["sshade_total_s"]))
    return row


def _first_call_row(mp, h, T, sp: dict, repeat: int, timeout_s: float) -> dict:
    """The first-call probe (:func:`probe_first_call`) run ``repeat`` times, each in a
    fresh process: the median probe's columns, with ``first_call_min_s`` and
    ``first_call_max_s`` (failed probes, NaN, left out; all NaN when every one fails)."""
    probes = [probe_first_call(mp, h, T, sp, timeout_s=timeout_s) for _ in range(repeat)]
    ok = [p for p in probes if math.isfinite(p["first_call_s"])]
    if not ok:
        return dict(probes[0], first_call_min_s=math.nan, first_call_max_s=math.nan)
    mid, lo, hi = _median_of(ok, lambda p: p["first_call_s"])
    return dict(mid, first_call_min_s=lo, first_call_max_s=hi)


def _median_of(items: list, key) -> tuple:
    """(the median item by ``key``, the lower one for an even count; the smallest key;
    the largest key) of a non-empty list."""
    items = sorted(items, key=key)
    return items[(len(items) - 1) // 2], key(items[0]), key(items[-1])


def size_mesh(entry: MeshEntry, V0: np.ndarray, F0: np.ndarray, size: int, cache) -> tuple:
    """The mesh of about ``size`` vertices built from an entry's base mesh ``(V0, F0)``
    (:func:`build_mesh`; (n, 3) float64, (m, 3) int64), cached in the folder ``cache``
    (created when missing) as :func:`eval.experiments.scaling.mesh_set.cache_name` and read
    from there by later calls.

    Returns
    -------
    ``(its file, V (p, 3) float64, F (q, 3) int64, seconds to build or read)``.

    Raises
    ------
    SShaDeError when the built mesh fails validation.
    """
    mp = Path(cache) / cache_name(entry, size)
    t0 = time.perf_counter()
    if mp.is_file():
        V, F = read_mesh(mp)
    else:
        V, F = build_mesh(V0, F0, size, remesh=entry.remesh)
        V, F = validate_mesh(V, F, name=f"{entry.name} at {size}")
        mp.parent.mkdir(parents=True, exist_ok=True)
        write_mesh(mp, V, F)
    return mp, V, F, time.perf_counter() - t0


def _size_handles(sc: ScalingConfig, base, V):
    """The handles and targets at one size (module docstring's rule, ``scaling.seed``)."""
    lm, center, axes = base[3]
    h, T, _, _ = axis_handles(V, lm, center, axes, n_per_group=sc.n_per_group, region_radius=sc.region_radius,
                              rotate_deg=sc.rotate_deg, translate=sc.translate, seed=sc.seed)
    return h, T


def _sshade_row(V, F, h, T, sp: dict, repeat: int = 1) -> tuple[float, dict]:
    """SShaDe's ``repeat`` timed runs with the checked parameters ``sp``: the seconds of
    compilation they still reported (0 after the warm-up) and the columns of the table
    row (times in seconds, compilation excluded) of the median run (the lower one for
    an even count), with the fastest and slowest totals (``sshade_total_min_s``,
    ``sshade_total_max_s``): one timing on a shared machine can be far off. The untimed
    run of the next master seed gives ``seed_spread_pct`` and, under the memory probe,
    ``peak_mem_mb``: the probe reads every process's page tables 50 times a second,
    which slows the call it watches, so it never watches the timed one. ``peak_mem_mb`` is the process tree's peak, this
    process's live data included (the mesh, the benchmark's state), ``call_mem_mb`` that
    peak less the tree's PSS when the call starts."""

    runs, compile_s = [], 0.0
    for _ in range(repeat):
        t0 = time.perf_counter()
        Vd, si = deform(V, F, h, T, return_info=True, **sp)  # the same result every time (seeded)
        runs.append((time.perf_counter() - t0 - si["compile_s"], si))  # compilation: 0 after the warm-up
        compile_s += si["compile_s"]
    (total, si), t_min, t_max = _median_of(runs, lambda r: r[0])
    k = int(sp["n_samplings"])
    row = {"n_low": si["n_low"], "k": k, "workers": si["workers"], "repeat": repeat,
           "sshade_total_s": total, "sshade_total_min_s": t_min, "sshade_total_max_s": t_max,
           "setup_s": si["setup_s"],
           "remesh_s": si["remesh_s"] + si["project_s"], "lowres_arap_s": si["arap_s"],
           "transfer_s": si["transfer_s"], "lowres_iters_first": si["samplings"][0]["iterations"],
           "lowres_iters_mean_warm": float(np.mean([s["iterations"] for s in si["samplings"][1:]]))
           if k > 1 else math.nan,
           "repair_rounds": int(sum(s["rounds"] for s in si["samplings"])),
           "repair_rounds_max": int(max(s["rounds"] for s in si["samplings"])),
           "repair_seeds": int(sum(s["n_repair"] for s in si["samplings"]))}
    m = deformation_metrics(V, Vd, F, h, T)
    row.update({f"sshade_{k_}": v for k_, v in m.items()})
    seed = int(sp["seed"])
    release_freed()  # what earlier rows left in this process's heap is not this call's
    with PeakMemory() as pm:
        Vd2 = deform(V, F, h, T, **dict(sp, seed=seed + 1 if seed < MAX_SEED else seed - 1))
    row["peak_mem_mb"], row["call_mem_mb"] = pm.peak_mb, pm.peak_mb - pm.start_mb
    diag = float(np.linalg.norm(V.max(axis=0) - V.min(axis=0)))
    row["seed_spread_pct"] = 100.0 * float(np.linalg.norm(Vd - Vd2, axis=1).mean()) / diag
    return compile_s, row


def _elastic_row(V, F, h, T, ep: dict, budget_s: float, sshade_total_s: float) -> dict:
    """Full-resolution Elastic (spokes and rims) under ``ep`` (:func:`elastic_params`)
    and the time budget: its columns of the table row and the speed-up over SShaDe."""

    print(f"[scaling] {len(V)} vertices: full-res Elastic (budget {budget_s:g}s) ...", file=sys.stderr, flush=True)
    protocol = str(ep["protocol"])
    row = {"elastic_compile_s": warm_fullres("spokes_and_rims", protocol, len(V))}
    paper = {"tol": float(ep["tol"])} if protocol == "paper" else {}
    options = ArapOptions(energy="spokes_and_rims", protocol=protocol, time_budget_s=budget_s,
                          max_iter=None if ep["max_iter"] is None else int(ep["max_iter"]),
                          criterion=make_criterion(ep["etol"], ep["gtol"]), **paper)
    res = arap_deform(V, F, h, T, options)
    per_it = res.solve_s / max(res.iterations, 1)
    row.update({"elastic_precompute_s": res.precompute_s, "elastic_s_per_iter": per_it,
                "elastic_iters": res.iterations, "elastic_converged": res.converged,
                "elastic_status": res.info.get("status"), "protocol": res.info.get("protocol"),
                "elastic_total_s": res.precompute_s + res.solve_s if res.converged else math.nan,
                "elastic_total_lower_bound_s": res.precompute_s + res.solve_s})
    row["speedup"] = (row["elastic_total_s"] if res.converged else row["elastic_total_lower_bound_s"]) / sshade_total_s
    row["speedup_is_lower_bound"] = not res.converged
    if res.converged:
        me = deformation_metrics(V, res.V, F, h, T)
        row.update({f"elastic_{k_}": v for k_, v in me.items()})
    return row


register_experiment("scaling", run_scaling,
                    options=section_reader("scaling", ScalingConfig, absent="use experiment=scaling"))
