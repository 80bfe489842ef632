"""Scaling benchmark (issue "Scalable SShaDe"; paper abstract, §1, Table 1):
``python -m eval experiment=scaling``.

Builds test meshes of about 25k, 50k, 100k, 200k and 450k vertices from one real mesh
(LS3 Loop subdivision, then isotropic remeshing to the target size, both pymeshlab; or
isotropic remeshing alone for sizes below the base mesh), deforms each with SShaDe and
with full-resolution Elastic (spokes and rims) under the same handles, and writes
``table.csv`` / ``table.md`` into ``out_dir`` with, per size: vertices, n_low, k,
seconds for remesh / low-res ARAP / transfer / total (numba's compilation excluded: it
runs before, on a tiny mesh, and is reported as ``sshade_compile_s`` /
``elastic_compile_s``; :mod:`sshade.warmup`), peak memory of the process tree
(PSS, MB), SShaDe's errors, Elastic's precompute time, time per iteration and time to
convergence (when it converges within ``elastic_budget_s``), and the speed-up.

Parameters: the meshes, handles and budgets from ``scaling.*``
(``conf/experiment/scaling.yaml``); SShaDe's from the method config ``method.SShaDe``
(the ``sshade`` section, the experiment's yaml sets ``sshade.n_low: 6000``;
:func:`sshade_params`); Elastic's stopping rule from ``method.Elastic`` (the ``arap``
section; :func:`elastic_params`).

Handle rule (fixed, so runs are comparable): the base mesh's principal axes a1, a2, a3
(PCA of the vertices); four landmark points = the base vertices of smallest and largest
coordinate along a1 and along a2. At each size, group g takes 30 random vertices (seeded
by ``[seed, g]``) within ``region_radius * bbox_diag`` of its landmark point. Groups at
the smallest a1 and a2 are static; the group at the largest a1 is rotated by
``rotate_deg`` about a3 through the centroid; the group at the largest a2 is translated
by ``translate * bbox_diag`` along a3.
"""
from __future__ import annotations

import logging
import math
import sys
import time

import numpy as np

from sshade import deform
from sshade.arap import arap_deform, make_criterion
from sshade.deform import check_params, warm_sshade
from sshade.errors import SShaDeError
from sshade.mesh.io import atomic_write, read_mesh, write_mesh
from sshade.mesh.validate import validate_mesh
from sshade.warmup import warm_fullres

from ..datasets.shapes import axis_handles, axis_landmarks
from ..memory import PeakMemory
from ..methods import method_spec
from ..metrics import deformation_metrics
from ..paths import abs_path
from ..runinfo import collect_runinfo, write_runinfo
from .common import sshade_spec
from .registry import register_experiment

log = logging.getLogger(__name__)

__all__ = ["build_mesh", "run_scaling", "sshade_params", "elastic_params"]


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


def sshade_params(cfg) -> dict:
    """Keyword parameters of :func:`sshade.deform` in this experiment: the method config
    ``method.SShaDe`` (:func:`eval.experiments.common.sshade_spec`)."""
    return sshade_spec(cfg)


def elastic_params(cfg) -> dict:
    """Full-resolution Elastic's protocol and stopping rule in this experiment:
    ``protocol``, ``tol``, ``max_iter``, ``etol``, ``gtol`` of the method config
    ``method.Elastic`` (the ``arap`` section)."""
    spec = method_spec(cfg, "Elastic")
    return {k: spec.get(k) for k in ("protocol", "tol", "max_iter", "etol", "gtol")}


def run_scaling(cfg) -> dict:
    """Run the scaling experiment described by ``cfg.scaling`` (see conf/experiment/scaling.yaml).

    Returns dict ``out_dir``, ``table`` (DataFrame, one row per size).

    Raises
    ------
    SShaDeError on a missing ``scaling.base_mesh`` or a bad SShaDe parameter, before any
    mesh is built.
    """
    import pandas as pd
    from omegaconf import OmegaConf



    sc = cfg.scaling
    out_dir = abs_path(cfg.out_dir)
    base_path = abs_path(sc.base_mesh)
    if not base_path.is_file():
        raise SShaDeError(f"scaling.base_mesh not found: {base_path} (set scaling.base_mesh=PATH)")
    sp = check_params(**sshade_params(cfg))
    ep = elastic_params(cfg)
    V0, F0 = read_mesh(base_path)
    base = (base_path, V0, F0, axis_landmarks(V0))
    cache = abs_path(sc.get("cache", None) or "data/scaling")  # built meshes, reused by later runs
    config = OmegaConf.to_container(cfg, resolve=True)
    info = collect_runinfo(config, seeds={"scaling": int(sc.seed), "sshade": int(sp["seed"])},
                           extra={"status": "running"})
    write_runinfo(out_dir / "run.json", info)
    rows = []
    for size in list(sc.sizes):
        V, F, build_s = _size_mesh(sc, base, int(size), cache)
        h, T = _size_handles(sc, base, V)
        row = {"target": int(size), "vertices": len(V), "faces": len(F), "handles": len(h), "build_s": build_s}
        print(f"[scaling] {len(V)} vertices: SShaDe ...", file=sys.stderr, flush=True)
        row["sshade_compile_s"] = warm_sshade(sp)  # outside the timings and the memory peak
        late_compile_s, srow = _sshade_row(V, F, h, T, sp)
        row["sshade_compile_s"] += late_compile_s
        row.update(srow)
        if bool(sc.elastic) and (sc.elastic_max_vertices is None or len(V) <= int(sc.elastic_max_vertices)):
            row.update(_elastic_row(V, F, h, T, ep, float(sc.elastic_budget_s), row["sshade_total_s"]))
        rows.append(row)
        print(f"[scaling] {row}", file=sys.stderr, flush=True)
        df = pd.DataFrame(rows)
        with atomic_write(out_dir / "table.csv", "w", newline="") as fh:
            df.to_csv(fh, index=False, float_format="%.6g")
    df = pd.DataFrame(rows)
    md = _markdown(df)
    with atomic_write(out_dir / "table.md", "w") as fh:
        fh.write(md)
    info.update(status="done", n_sizes=len(rows))
    write_runinfo(out_dir / "run.json", info)
    print(md)
    return {"out_dir": out_dir, "table": df}


def _size_mesh(sc, base, size: int, cache):
    """The mesh of about ``size`` vertices built from the base mesh (cached in
    ``cache``); returns ``(V, F, seconds to build or read)``."""
    base_path, V0, F0, _ = base
    mp = cache / f"{base_path.stem}_{size}.ply"
    t0 = time.perf_counter()
    if mp.is_file():
        V, F = read_mesh(mp)
    else:
        V, F = build_mesh(V0, F0, size, remesh=bool(sc.remesh))
        V, F = validate_mesh(V, F, name=f"{base_path.name} at {size}")
        write_mesh(mp, V, F)
    return V, F, time.perf_counter() - t0


def _size_handles(sc, base, V):
    """The handles and targets at one size (module docstring's rule, ``scaling.seed``)."""
    lm, center, axes = base[3]
    h, T, _, _ = axis_handles(V, lm, center, axes, n_per_group=int(sc.n_per_group),
                              region_radius=float(sc.region_radius), rotate_deg=float(sc.rotate_deg),
                              translate=float(sc.translate), seed=int(sc.seed))
    return h, T


def _sshade_row(V, F, h, T, sp: dict) -> tuple[float, dict]:
    """SShaDe's timed run with the checked parameters ``sp`` under the memory probe:
    the seconds of compilation it still reported (0 after the warm-up) and its columns
    of the table row (times in seconds, compilation excluded)."""

    with PeakMemory() as pm:
        t0 = time.perf_counter()
        Vd, si = deform(V, F, h, T, return_info=True, **sp)
        total = time.perf_counter() - t0 - si["compile_s"]  # 0 after the warm-up
    k = int(sp["n_samplings"])
    row = {"n_low": si["n_low"], "k": k, "workers": si["workers"],
           "sshade_total_s": total, "setup_s": si["setup_s"],
           "remesh_s": si["remesh_s"] + si["project_s"], "lowres_arap_s": si["arap_s"],
           "transfer_s": si["transfer_s"], "lowres_iters_first": si["samplings"][0]["iterations"],
           "lowres_iters_mean_warm": float(np.mean([s["iterations"] for s in si["samplings"][1:]]))
           if k > 1 else math.nan,
           "peak_mem_mb": pm.peak_mb}
    m = deformation_metrics(V, Vd, F, h, T)
    row.update({f"sshade_{k_}": v for k_, v in m.items()})
    return si["compile_s"], row


def _elastic_row(V, F, h, T, ep: dict, budget_s: float, sshade_total_s: float) -> dict:
    """Full-resolution Elastic (spokes and rims) under ``ep`` (:func:`elastic_params`)
    and the time budget: its columns of the table row and the speed-up over SShaDe."""

    print(f"[scaling] {len(V)} vertices: full-res Elastic (budget {budget_s:g}s) ...", file=sys.stderr, flush=True)
    protocol = str(ep["protocol"])
    row = {"elastic_compile_s": warm_fullres("spokes_and_rims", protocol, len(V))}
    res = arap_deform(V, F, h, T, energy="spokes_and_rims", tol=float(ep["tol"]),
                      max_iter=None if ep["max_iter"] is None else int(ep["max_iter"]), time_budget_s=budget_s,
                      protocol=protocol, criterion=make_criterion(ep["etol"], ep["gtol"]))
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


def _markdown(df) -> str:
    cols = [("vertices", "Vertices", "{:.0f}"), ("n_low", "n_low", "{:.0f}"), ("k", "k", "{:.0f}"),
            ("remesh_s", "Remesh (s)", "{:.2f}"), ("lowres_arap_s", "Low-res ARAP (s)", "{:.2f}"),
            ("transfer_s", "Transfer (s)", "{:.2f}"), ("sshade_total_s", "SShaDe total (s)", "{:.2f}"),
            ("peak_mem_mb", "Peak mem (MB)", "{:.0f}"),
            ("sshade_volume_err_pct", "Vol (%)", "{:.2f}"), ("sshade_edge_err_pct", "EL (%)", "{:.2f}"),
            ("sshade_angle_err_deg", "FA (deg)", "{:.3f}"),
            ("elastic_precompute_s", "Elastic precompute (s)", "{:.2f}"),
            ("elastic_s_per_iter", "Elastic s/iter", "{:.3f}"), ("elastic_iters", "Elastic iters", "{:.0f}"),
            ("elastic_total_s", "Elastic total (s)", "{:.1f}"), ("speedup", "Speed-up", "{:.1f}x")]
    cols = [c for c in cols if c[0] in df.columns]
    lines = ["| " + " | ".join(c[1] for c in cols) + " |", "|" + "---:|" * len(cols)]
    for _, r in df.iterrows():
        cells = []
        for key, _, fmt in cols:
            v = r.get(key)
            if v is None or (isinstance(v, float) and math.isnan(v)):
                if key == "elastic_total_s" and "elastic_total_lower_bound_s" in r:
                    cells.append(f"> {r['elastic_total_lower_bound_s']:.0f} (not converged)")
                else:
                    cells.append("-")
            else:
                s = fmt.format(v)
                if key == "speedup" and r.get("speedup_is_lower_bound"):
                    s = "> " + s
                cells.append(s)
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


register_experiment("scaling", run_scaling)
