"""Pose transfer on FAUST (paper §4.3): ``python -m eval experiment=pose_transfer``.
Floor 4 of eval/ (eval/experiments/, tests/test_layering.py); notes: docs/implementation.md.

The paper poses hand-edited TOSCA meshes, which have no ground truth. Here the edited
shape is another FAUST subject: the registrations (``tr_reg_XYZ.ply``, subject and pose from ``XYZ``,
:func:`eval.datasets.faust.discover_faust`) are in 1:1 correspondence,
share one face array and are aligned in space, and subject b in pose p is the ground
truth of "subject b put in the pose of subject a's pose p"."""
from __future__ import annotations

import logging
import math
import sys
import time
from dataclasses import dataclass
from typing import Any, ClassVar, Optional  # OmegaConf 2.3 reads typing's generics

import numpy as np
from omegaconf import MISSING

from eval.config_schema import section_reader
from eval.datasets.faust import discover_faust
from eval.experiments.common import transfer_params
from eval.experiments.experiment_registry import register_experiment
from eval.experiments.tosca import gt_stretch_pct, markdown_table, transfer_n_low
from eval.metrics.measures import ground_truth_metrics
from eval.present.figures import pose_transfer_figure, safe_figure
from eval.present.measures import columns, measure_column
from eval.run.paths import abs_path
from eval.run.runinfo import collect_runinfo, finish_run, write_runinfo
from eval.run.spec import EvalSpec, FigureOptions
from harness.checks import check_fields, checked_field
from sshade.errors import SShaDeError
from sshade.files import atomic_write
from sshade.isometric import pose_transfer, rigid_align
from sshade.mesh.io import read_mesh
from sshade.pipeline import SShaDe
from sshade.sampling import sampling_seeds

__all__ = ["PoseTransferConfig", "run_pose_transfer", "METRICS"]

log = logging.getLogger(__name__)

#: metric keys of :func:`eval.metrics.measures.ground_truth_metrics`.
METRICS = ("gt_vertex_mean_pct", "gt_vertex_max_pct", "hausdorff", "chamfer")

#: (prefix in cases.csv, label in the tables).
METHODS = (("", "SShaDe pose transfer"), ("naive_", "naive: M' + (S - M)"),
           ("identity_", "identity: S, no transfer"), ("mprime_", "M': source subject in the target pose"),
           ("truth_", "ground truth (b pose p)"))

_COLUMNS = columns("pose_transfer")


@dataclass
class PoseTransferConfig:
    """The ``pose_transfer`` section (conf/experiment/pose_transfer.yaml), typed and checked:
    ``root`` (FAUST registrations, as given), ``subjects`` (None: all with a pose 0),
    ``poses`` (target poses; None: all but 0), each an integer or a list, ``align`` (move S
    rigidly onto M first). Made by :func:`eval.config_schema.typed_section` at the door,
    whose ``OmegaConf.to_object`` runs :meth:`__post_init__`: SShaDeError naming the key for
    ``subjects`` or ``poses`` not integers; both become tuples."""

    root: Optional[str] = MISSING
    subjects: Any = checked_field(list[int], allow_none=True, default=None)
    poses: Any = checked_field(list[int], allow_none=True, default=None)
    align: bool = True

    REQUIRED: ClassVar[dict] = {"root": "DIR (a folder of FAUST registrations tr_reg_XYZ.ply)"}

    def __post_init__(self):
        if self.root in (None, ""):
            raise SShaDeError(f"pose_transfer.root is not set: pass pose_transfer.root={self.REQUIRED['root']}")
        check_fields(self, "pose_transfer")
        self.subjects = None if self.subjects is None else tuple(self.subjects)
        self.poses = None if self.poses is None else tuple(self.poses)


def run_pose_transfer(spec: EvalSpec) -> dict:
    """Run the FAUST pose-transfer experiment of ``spec.experiment.options``
    (:class:`PoseTransferConfig`, see conf/experiment/pose_transfer.yaml): every ordered
    pair of the selected subjects, every selected target pose. SShaDe's ``n_low``,
    ``n_samplings``, ``seed``, ``gradient``, ``workers``: :attr:`eval.run.spec.EvalSpec.sshade`. Outputs
    go to ``spec.output.out_dir``. The dataset is not used.

    Returns
    -------
    dict: ``out_dir``, ``paths``, ``cases`` (DataFrame), ``table`` (DataFrame, one row
    per method), ``n_cases``, ``n_errors``.

    Raises
    ------
    SShaDeError on a missing root or one without FAUST registrations, a selected
    subject without its files, or no (pair, pose) case, before any transfer.
    """
    t_start = time.perf_counter()
    opts = spec.experiment.options
    root, files = _pose_transfer_root(opts)
    out_dir = abs_path(spec.output.out_dir)
    jobs = _pose_transfer_jobs(opts, root, files)
    sp = transfer_params(spec.sshade)
    k, seed = int(sp["n_samplings"]), int(sp["seed"])
    log.info("%d pose-transfer case(s) from %s; n_low=%s k=%d; output %s", len(jobs), root, sp["n_low"], k,
             out_dir)
    F, V = _read_meshes(files, jobs)

    config = spec.record()
    config["pose_transfer"]["root"] = str(root)
    info = collect_runinfo(config, seeds={"pose_transfer": seed, "sampling_seeds": sampling_seeds(seed, k)},
                           extra={"status": "running", "out_dir": str(out_dir)})
    write_runinfo(out_dir / "run.json", info)
    rows = _run_pose_transfer_cases(spec.figures, jobs, F, V, sp, opts.align, out_dir)
    return _pose_transfer_tables(rows, sp, opts.align, info, out_dir, t_start)


def _pose_transfer_root(opts: PoseTransferConfig):
    """``(root, files)``: ``pose_transfer.root`` resolved and its registrations
    (:func:`eval.datasets.faust.discover_faust`)."""
    root = abs_path(opts.root)
    if not root.is_dir():
        raise SShaDeError(f"pose_transfer.root does not exist or is not a folder: {root} "
                          "(pass pose_transfer.root=DIR, e.g. ../shared/data/faust_reg)")
    return root, discover_faust(root)


def _pose_transfer_jobs(opts: PoseTransferConfig, root, files) -> list[tuple[int, int, int]]:
    """The cases ``(a, b, p)``: ordered pairs of selected subjects with a pose 0 and
    the target poses present for both."""
    present = sorted({s for s, p in files if p == 0})
    subjects = None if opts.subjects is None else list(opts.subjects)
    if subjects is None:
        subjects = present
    else:
        subjects = [int(s) for s in subjects]
        miss = [s for s in subjects if s not in present]
        if miss:
            raise SShaDeError(f"pose_transfer.subjects: no rest pose (pose 0) for subject(s) {miss} in {root} "
                              f"(subjects with pose 0: {present})")
    poses = None if opts.poses is None else list(opts.poses)
    jobs = [(a, b, p) for a in subjects for b in subjects if a != b
            for p in sorted({q for s, q in files if s == a and q != 0})
            if (b, p) in files and (poses is None or p in poses)]
    if not jobs:
        raise SShaDeError(f"no pose-transfer case in {root}: need two subjects with pose 0 and a common "
                          f"target pose (subjects {subjects}, poses {poses}, files {sorted(files)})")
    return jobs


def _read_meshes(files, jobs):
    """The meshes the cases use, read once: ``(F, V)`` with ``V[(subject, pose)]``; the
    shared face array is the first rest pose's (every file must have it)."""
    need = sorted({(a, 0) for a, _, _ in jobs} | {(b, 0) for _, b, _ in jobs} | {(a, p) for a, _, p in jobs}
                  | {(b, p) for _, b, p in jobs})
    _, F = read_mesh(files[need[0]])
    V: dict = {}
    for key in need:
        Vk, Fk = read_mesh(files[key], validate=False)
        if Fk.shape != F.shape or not np.array_equal(Fk, F):
            raise SShaDeError(f"{files[key].name}: its faces differ from {files[need[0]].name}'s; FAUST "
                              "registrations must share one face array")
        V[key] = Vk
    return F, V


def _run_pose_transfer_cases(figures: FigureOptions, jobs, F, V, sp: dict, align: bool, out_dir) -> list[dict]:
    """Every case (:func:`_pose_transfer_case`), ``cases.csv`` rewritten after each,
    the figures of the first ``figures.max_cases``; returns the rows."""
    import pandas as pd
    from tqdm import tqdm
    from tqdm.contrib.logging import logging_redirect_tqdm

    rows: list[dict] = []
    fig_on, fig_left = figures.enabled, figures.max_cases  # the first figures.max_cases cases
    with logging_redirect_tqdm():
        for a, b, p in tqdm(jobs, desc="pose transfer", unit="case", file=sys.stderr, dynamic_ncols=True):
            row, Vs = _pose_transfer_case(a, b, p, F, V, sp, align)
            if Vs is not None and fig_on and fig_left > 0:
                fig_left -= 1
                safe_figure(row["case"], pose_transfer_figure, V[(a, 0)], V[(b, 0)], V[(a, p)], Vs, V[(b, p)], F,
                            out_dir / "figures" / f"s{a}-s{b}_p{p}.png",
                            title=f"subject {b} in subject {a}'s pose {p}: vertex error "
                                  f"{row['gt_vertex_mean_pct']:.2f}% (identity "
                                  f"{row['identity_gt_vertex_mean_pct']:.2f}%)")
            rows.append(row)
            with atomic_write(out_dir / "cases.csv", "w", newline="") as fh:
                pd.DataFrame(rows).to_csv(fh, index=False)
    return rows


def _pose_transfer_case(a: int, b: int, p: int, F, V: dict, sp: dict, align: bool):
    """One case: subject ``b`` put in subject ``a``'s pose ``p``, with the references
    (naive, identity, M'); returns ``(row, Vs)`` (``Vs`` None when it failed: its
    message in ``error``)."""

    k, seed = int(sp["n_samplings"]), int(sp["seed"])
    row = {"case": f"s{a}->s{b}_p{p}", "source": a, "subject": b, "pose": p, "n_vertices": len(V[(a, 0)]),
           "n_samplings": k, "seed": seed, "error": ""}
    try:
        M, S, Mp, gt = V[(a, 0)], V[(b, 0)], V[(a, p)], V[(b, p)]
        t0 = time.perf_counter()
        Vs, ti = pose_transfer(M, F, S, Mp, n_low=transfer_n_low(sp["n_low"], len(M)), n_samplings=k, seed=seed,
                               gradient=str(sp.get("gradient") or "normalized"), workers=sp.get("workers"),
                               **{k: sp[k] for k in ("anchor", "transfer", "average") if sp.get(k)},
                               align=align, return_info=True)
        row["time_s"] = time.perf_counter() - t0
        row.update({key: ti[key] for key in ("n_low", "remesh_s", "project_s", "transfer_s", "workers")})
        S_on_M = rigid_align(S, M) if align else S
        for prefix, X in (("", Vs), ("naive_", Mp + (S_on_M - M)), ("identity_", S), ("mprime_", Mp)):
            row.update({prefix + key: v for key, v in ground_truth_metrics(rigid_align(X, gt), F, gt).items()})
            row[prefix + "stretch_vs_S_pct"] = gt_stretch_pct(S, X, F)
        row["truth_stretch_vs_S_pct"] = gt_stretch_pct(S, gt, F)
        log.info("%s  %.2fs  vertex mean %.3f%% (naive %.3f%%, identity %.3f%%, M' %.3f%%)  d_H %.3e",
                 row["case"], row["time_s"], row["gt_vertex_mean_pct"], row["naive_gt_vertex_mean_pct"],
                 row["identity_gt_vertex_mean_pct"], row["mprime_gt_vertex_mean_pct"], row["hausdorff"])
    except SShaDeError as e:
        row["error"] = str(e) or type(e).__name__
        log.warning("%s failed: %s", row["case"], row["error"])
        return row, None
    return row, Vs


def _pose_transfer_tables(rows: list[dict], sp: dict, align: bool, info: dict, out_dir, t_start: float) -> dict:
    """``table.csv`` / ``table.md`` (one row per method, a per-case table), ``run.json``
    finished; the return value of :func:`run_pose_transfer`."""
    import pandas as pd

    n_low, k, seed, gradient = sp["n_low"], int(sp["n_samplings"]), int(sp["seed"]), str(sp.get("gradient"))
    df = pd.DataFrame(rows)
    ok = df["error"].astype(str).str.len() == 0
    good = df[ok]
    trows = []
    for prefix, label in METHODS:
        r = {"method": label, "n_cases": int(ok.sum()), "n_failed": int((~ok).sum())}
        for m in (*METRICS, "stretch_vs_S_pct"):
            c = prefix + m
            r[m] = float(good[c].mean()) if c in good.columns and len(good) else math.nan
        r["time_s"] = float(good["time_s"].mean()) if prefix == "" and len(good) else math.nan
        trows.append(r)
    table = pd.DataFrame(trows)
    paths = {"cases": out_dir / "cases.csv"}
    with atomic_write(out_dir / "table.csv", "w", newline="") as fh:
        table.to_csv(fh, index=False, float_format="%.6g")
    paths["table_csv"] = out_dir / "table.csv"

    per_case = pd.DataFrame([{"case": r["case"], **{f"{lab}": r.get(f"{pre}gt_vertex_mean_pct", math.nan)
                                                    for pre, lab in (("", SShaDe.name), ("naive_", "naive"),
                                                                     ("identity_", "identity"), ("mprime_", "M'"))},
                              "time_s": r.get("time_s", math.nan)} for r in rows])
    n_err = int((~ok).sum())
    wall = time.perf_counter() - t_start
    md = "\n".join([
        f"### FAUST pose transfer (paper §4.3): n_low={n_low}, k={k}, seed={seed}, gradient={gradient}, "
        f"anchor={sp.get('anchor')}, transfer={sp.get('transfer')}, average={sp.get('average')}", "",
        markdown_table(table, ("method", "Method"), _COLUMNS),
        "Mean over the cases. Every shape is first moved rigidly onto the ground truth (b pose p). Vertex "
        "errors in % of the ground truth's bounding-box diagonal; d_H, d_C: vertex-to-surface Hausdorff / "
        "Chamfer (paper §4.2 definitions) in the ground truth's unit sphere; stretch vs S: mean relative "
        "edge-length change from S (body kept; the ground truth's row is the change due to posing). Naive: "
        "M' + (S - M), S aligned on M; identity: S (subject b, pose 0) itself; M': subject a in the target "
        "pose. The ground truth is approximate (two subjects never hold pose p identically), so no method "
        f"reaches 0. {'S rigidly aligned onto M before the transfer. ' if align else ''}Time: wall seconds per "
        f"transfer (all {k} samplings). The paper reports no numbers for pose transfer (edited TOSCA meshes "
        "without ground truth, ~2 s per example).", "",
        "Per case, mean vertex error (% diag):", "",
        markdown_table(per_case, ("case", "Case (a->b, pose)"),
                       ((SShaDe.name, SShaDe.name, "{:.3f}"), ("naive", "Naive", "{:.3f}"),
                        ("identity", "Identity", "{:.3f}"), ("M'", "M'", "{:.3f}"),
                        measure_column("time_s"))),
        f"{len(df)} case(s), {n_err} failed, {wall:.1f} s in all.", ""])
    finish_run(out_dir, md, paths, info, n_cases=len(df), n_errors=n_err, wall_s=wall)
    return {"out_dir": out_dir, "paths": paths, "cases": df, "table": table, "n_cases": len(df), "n_errors": n_err}


register_experiment("pose_transfer", run_pose_transfer,
                    options=section_reader("pose_transfer", PoseTransferConfig, absent="use experiment=pose_transfer"))
