"""Non-rigid isometric deformations on TOSCA (paper §4.2): ``python -m eval experiment=tosca``.
Floor 4 of eval/ (eval/experiments/, tests/test_layering.py); notes: docs/implementation.md.

For every TOSCA class (files ``NAMEk.off`` in ``tosca.root``, vertices 1:1 within a
class) pose 0 is the rest pose M and every other pose M' one case: M is remeshed to
``n_low`` vertices, the low-res mesh is taken into the pose through the
correspondence and M is rebuilt in that pose with the per-triangle LRFs, averaged over
``n_samplings`` samplings (:func:`sshade.isometric.isometric_transfer`). SShaDe's
parameters (``n_low``, ``n_samplings``, ``seed``, ``gradient``, ``anchor``, ``transfer``,
``average``, ``workers``) come from the method config ``method.SShaDe`` (the ``sshade``
section; ``conf/experiment/tosca.yaml`` sets the paper's ``sshade.n_low: 6000``,
``sshade.n_samplings: 10`` and ``sshade.average: proximity``; :attr:`eval.run.spec.EvalSpec.sshade`)."""
from __future__ import annotations

import logging
import math
import re
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from types import SimpleNamespace
from typing import Any, ClassVar, Optional  # OmegaConf 2.3 reads typing's generics

import numpy as np
from omegaconf import MISSING

from eval.config_schema import section_reader
from eval.experiments.common import as_list, transfer_params
from eval.experiments.experiment_registry import register_experiment
from eval.metrics.measures import chamfer, ground_truth_metrics, hausdorff
from eval.present.figures import safe_figure, tosca_figure
from eval.present.measures import columns
from eval.present.meshview import write_case_view
from eval.run.paths import abs_path
from eval.run.runinfo import collect_runinfo, finish_run, write_runinfo
from eval.run.spec import EvalSpec, FigureOptions, ReportOptions
from eval.tables import ok_mask
from harness.checks import check_fields, checked_field
from sshade.errors import SShaDeError
from sshade.files import atomic_write
from sshade.isometric import isometric_transfer
from sshade.mesh.io import read_mesh
from sshade.pipeline import SShaDe, auto_n_low
from sshade.sampling import sampling_seeds

__all__ = ["ToscaConfig", "PAPER_TOSCA", "discover_tosca", "gt_stretch_pct", "group_table",
           "markdown_table", "run_tosca", "transfer_n_low"]

log = logging.getLogger(__name__)

#: Paper §4.2, mean over the TOSCA dataset (without wolf and gorilla).
PAPER_TOSCA = {"hausdorff": 5.66e-3, "chamfer": 3.76e-8}

_NAME = re.compile(r"^([A-Za-z_]+?)(\d+)\.off$", re.IGNORECASE)

#: (column, Markdown header, format) of the summary tables.
TOSCA_COLUMNS = columns("tosca")


def discover_tosca(root) -> dict[str, dict[int, Path]]:
    """TOSCA files ``NAMEk.off`` in ``root``, grouped by class.

    Parameters
    ----------
    root : str or Path, a folder.

    Returns
    -------
    dict class name -> dict pose index -> path, both sorted.

    Raises
    ------
    SShaDeError if ``root`` is not a folder or holds no ``NAMEk.off`` file.
    """
    root = Path(root)
    if not root.is_dir():
        raise SShaDeError(f"tosca.root does not exist or is not a folder: {root} "
                          "(pass tosca.root=DIR, a folder of TOSCA NAMEk.off files, e.g. ../shared/data/tosca)")
    found: dict[str, dict[int, Path]] = {}
    for p in sorted(root.iterdir()):
        m = _NAME.match(p.name)
        if m and p.is_file():
            found.setdefault(m.group(1), {})[int(m.group(2))] = p
    if not found:
        raise SShaDeError(f"no TOSCA meshes (NAMEk.off, e.g. cat0.off) found in {root}")
    return {c: dict(sorted(found[c].items())) for c in sorted(found)}


def gt_stretch_pct(V0: np.ndarray, V1: np.ndarray, F: np.ndarray) -> float:
    """Mean relative edge-length change ``|l1 / l0 - 1|`` over the edges of F, in %."""
    E = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
    E = E[E[:, 0] < E[:, 1]]  # each interior edge once (consistently oriented mesh)
    l0 = np.linalg.norm(V0[E[:, 0]] - V0[E[:, 1]], axis=1)
    l1 = np.linalg.norm(V1[E[:, 0]] - V1[E[:, 1]], axis=1)
    ok = l0 > 0
    return float(100.0 * np.mean(np.abs(l1[ok] / l0[ok] - 1.0)))


def group_table(df, by: str, columns, *, all_label: str = "all (mean over cases)"):
    """Per-group means of ``columns`` over successful rows, plus an overall row.

    Parameters
    ----------
    df : DataFrame with an ``error`` column (empty string = success) and ``by``.
    by : grouping column. columns : numeric columns to average.

    Returns
    -------
    DataFrame with ``by``, ``n_cases`` (successful), ``n_failed`` and the means.
    """
    import pandas as pd

    ok = ok_mask(df)  # NaN-safe: no fillna("") on an all-empty error column read back as float64
    cols = [c for c in columns if c in df.columns]

    def row(sel, label):
        good = df[sel & ok]
        r = {by: label, "n_cases": int(len(good)), "n_failed": int((sel & ~ok).sum())}
        for c in cols:
            v = pd.to_numeric(good[c], errors="coerce").dropna()
            r[c] = float(v.mean()) if len(v) else math.nan
        return r

    rows = [row(df[by] == g, g) for g in dict.fromkeys(df[by])]
    rows.append(row(pd.Series(True, index=df.index), all_label))
    return pd.DataFrame(rows, columns=[by, "n_cases", "n_failed", *cols])


def markdown_table(table, first: tuple[str, str], columns) -> str:
    """Markdown of ``table``: ``first`` = (column, header); ``columns`` as TOSCA_COLUMNS.
    Missing or NaN cells print as ``-``."""
    cols = [c for c in columns if c[0] in table.columns]
    lines = ["| " + " | ".join([first[1], *[h for _, h, _ in cols]]) + " |",
             "|" + "|".join(["---"] + ["---:"] * len(cols)) + "|"]
    for _, r in table.iterrows():
        cells = [str(r[first[0]])]
        for c, _, fmt in cols:
            v = r.get(c)
            try:
                ok = v is not None and math.isfinite(float(v))
            except (TypeError, ValueError):
                ok = False
            cells.append(fmt.format(float(v)) if ok else "-")
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def transfer_n_low(n_low, n_vertices: int) -> int:
    """``n_low`` for a mesh of ``n_vertices``: the int itself, or for ``"auto"``/None
    :func:`sshade.pipeline.auto_n_low` (as :func:`sshade.deform` does).

    Raises
    ------
    SShaDeError on a value that is neither an integer nor ``"auto"``.
    """
    if n_low is None or (isinstance(n_low, str) and n_low.strip().lower() == "auto"):
        return auto_n_low(int(n_vertices))
    try:
        return int(n_low)
    except (TypeError, ValueError):
        raise SShaDeError(f"sshade.n_low must be an integer or auto, got {n_low!r}") from None


@dataclass
class ToscaConfig:
    """The ``tosca`` section (conf/experiment/tosca.yaml), typed and checked: ``root`` (a
    folder of NAMEk.off files, as given), ``min_vertices`` (classes below are excluded; 0:
    none), ``classes`` (a name or a list; None: all present), ``poses`` (target pose
    indices, an integer or a list; None: all but 0). Made by
    :func:`eval.config_schema.typed_section` at the door, whose ``OmegaConf.to_object``
    runs :meth:`__post_init__`: SShaDeError naming the key for ``min_vertices`` below 0,
    ``poses`` not integers or ``classes`` not names; both become tuples."""

    root: Optional[str] = MISSING
    min_vertices: Optional[int] = checked_field(int, min=0, allow_none=True, default=None)
    classes: Any = None
    poses: Any = checked_field(list[int], allow_none=True, default=None)

    REQUIRED: ClassVar[dict] = {"root": "DIR (a folder of TOSCA NAMEk.off files)"}

    def __post_init__(self):
        if self.root in (None, ""):
            raise SShaDeError(f"tosca.root is not set: pass tosca.root={self.REQUIRED['root']}")
        check_fields(self, "tosca")
        self.min_vertices = self.min_vertices or 0
        poses, classes = self.poses, as_list(self.classes)
        if classes is not None and not all(isinstance(c, str) and c for c in classes):
            raise SShaDeError(f"tosca.classes must be a class name or a list of names, got {self.classes!r}")
        self.classes = None if classes is None else tuple(classes)
        self.poses = None if poses is None else tuple(poses)


def run_tosca(spec: EvalSpec) -> dict:
    """Run the TOSCA experiment of ``spec.experiment.options`` (:class:`ToscaConfig`, see
    conf/experiment/tosca.yaml).

    Every class of ``root`` with at least ``min_vertices`` vertices (paper: wolf is
    excluded), the ``classes`` and ``poses`` selected. SShaDe's ``n_low`` (paper: 6000),
    ``n_samplings`` (paper: 10), ``seed``, ``gradient``, ``workers``: :attr:`eval.run.spec.EvalSpec.sshade`.
    Outputs go to ``spec.output.out_dir``. The dataset is not used.

    Returns
    -------
    dict: ``out_dir``, ``paths`` (name -> Path), ``cases`` (DataFrame), ``table``
    (DataFrame), ``n_cases``, ``n_errors``.

    Raises
    ------
    SShaDeError on a missing/empty root, an unknown class in ``classes``, a class
    without pose 0, or no case left to run, before any transfer.
    """
    t_start = time.perf_counter()
    opts = spec.experiment.options
    root = abs_path(opts.root)
    found = discover_tosca(root)
    out_dir = abs_path(spec.output.out_dir)
    sp = transfer_params(spec.sshade)
    k, seed = int(sp["n_samplings"]), int(sp["seed"])
    rests, excluded, jobs = _tosca_jobs(opts, root, found)
    log.info("%d TOSCA case(s) from %s (classes %s; excluded %s); n_low=%s k=%d; output %s",
             len(jobs), root, sorted(rests), sorted(excluded), sp["n_low"], k, out_dir)

    config = spec.record()
    config["tosca"]["root"] = str(root)
    info = collect_runinfo(config, seeds={"tosca": seed, "sampling_seeds": sampling_seeds(seed, k)},
                           extra={"status": "running", "out_dir": str(out_dir), "excluded": excluded,
                                  "paper": PAPER_TOSCA})
    write_runinfo(out_dir / "run.json", info)
    df = _run_tosca_cases(spec.figures, spec.report, jobs, rests, found, sp, out_dir)
    return _tosca_tables(df, sp, excluded, info, out_dir, t_start)


def _tosca_jobs(opts: ToscaConfig, root, found):
    """The selected classes' rest poses (read and validated; classes below
    ``tosca.min_vertices`` excluded) and the (class, pose) cases; returns
    ``(rests, excluded, jobs)``."""
    classes = None if opts.classes is None else list(opts.classes)
    if classes is not None:
        unknown = [c for c in classes if c not in found]
        if unknown:
            raise SShaDeError(f"tosca.classes: {unknown} not found in {root} (present: {sorted(found)})")
        found = {c: found[c] for c in classes}
    poses = None if opts.poses is None else list(opts.poses)
    min_v = opts.min_vertices
    rests, excluded, jobs = {}, {}, []
    for c, files in found.items():
        if 0 not in files:
            raise SShaDeError(f"TOSCA class {c!r} has no rest pose {c}0.off in {root}")
        V0, F0 = read_mesh(files[0])
        if len(V0) < min_v:
            excluded[c] = f"{len(V0)} vertices < tosca.min_vertices={min_v}"
            log.info("excluding %s: %s", c, excluded[c])
            continue
        rests[c] = (V0, F0)
        for p in files:
            if p != 0 and (poses is None or p in poses):
                jobs.append((c, p))
    if not jobs:
        raise SShaDeError(f"no TOSCA case to run in {root} (classes {sorted(found)}, excluded {excluded}, "
                          f"poses {poses})")
    return rests, excluded, jobs


def _run_tosca_cases(figures: FigureOptions, report: ReportOptions, jobs, rests, found, sp: dict, out_dir):
    """Every case (:func:`_tosca_case`), ``cases.csv`` rewritten after each, the
    optional figures and 3D views (:func:`eval.present.meshview.write_case_view`; one per class,
    its first pose); returns the cases' DataFrame."""
    import pandas as pd
    from tqdm import tqdm
    from tqdm.contrib.logging import logging_redirect_tqdm

    rows: list[dict] = []
    fig_on, fig_left = figures.enabled, figures.max_cases  # one figure per class (first pose), at most max_cases
    n_view, max_faces = report.views, report.max_faces  # one 3D view per class (first pose), at most view_cases
    drawn: set[str] = set()
    viewed: set[str] = set()
    with logging_redirect_tqdm():
        for c, p in tqdm(jobs, desc="tosca", unit="case", file=sys.stderr, dynamic_ncols=True):
            V0, F0 = rests[c]
            row, V1, Vp = _tosca_case(c, p, V0, F0, found[c][p], sp)
            if Vp is not None and fig_on and c not in drawn and len(drawn) < fig_left:
                drawn.add(c)
                safe_figure(f"{c}{p}", tosca_figure, V0, V1, Vp, F0, out_dir / "figures" / f"{c}{p}.png",
                            title=f"{c}{p}: d_H {row['hausdorff']:.2e}, d_C {row['chamfer']:.2e}")
            if Vp is not None and c not in viewed and len(viewed) < n_view:
                # rest, the true pose and SShaDe's rebuild; "distance to ground truth" is the
                # error map of the figure, "edge error" on the true pose shows where TOSCA's
                # pose is not isometric
                viewed.add(c)
                y_up = [[1.0, 0, 0], [0, 0, -1.0], [0, 1.0, 0]]  # (x, y, z) -> (x, z, -y): TOSCA z-up, the viewer y-up
                write_case_view(SimpleNamespace(name=f"{c}{p}", V=V0 @ y_up, F=F0, V_gt=V1 @ y_up),
                                {SShaDe.name: Vp @ y_up}, out_dir, max_faces=max_faces)
            rows.append(row)
            with atomic_write(out_dir / "cases.csv", "w", newline="") as fh:  # partial results survive a crash
                pd.DataFrame(rows).to_csv(fh, index=False)
    return pd.DataFrame(rows)


def _tosca_case(c: str, p: int, V0, F0, path, sp: dict):
    """One case: class ``c`` pose ``p`` (file ``path``) rebuilt from its rest pose
    ``(V0, F0)`` with SShaDe's parameters ``sp``; returns ``(row, V1, Vp)`` (the true
    and the predicted pose; ``Vp`` None when the case failed: its message in ``error``)."""

    k, seed = int(sp["n_samplings"]), int(sp["seed"])
    row = {"case": f"{c}{p}", "class": c, "pose": p, "n_vertices": len(V0), "n_faces": len(F0),
           "n_samplings": k, "seed": seed, "error": ""}
    V1 = Vp = None
    try:
        V1, F1 = read_mesh(path, validate=False)
        if len(V1) != len(V0):
            raise SShaDeError(f"{path.name} has {len(V1)} vertices, {c}0.off has {len(V0)}: "
                              "not in 1:1 correspondence")
        row["faces_rewound"] = int((F1 != F0).any(axis=1).sum()) if F1.shape == F0.shape else -1
        t0 = time.perf_counter()
        Vp, ti = isometric_transfer(V0, F0, V1, n_low=transfer_n_low(sp["n_low"], len(V0)), n_samplings=k,
                                    seed=seed, gradient=str(sp.get("gradient") or "normalized"),
                                    **{k: sp[k] for k in ("anchor", "transfer", "average") if sp.get(k)},
                                    workers=sp.get("workers"))
        row["time_s"] = time.perf_counter() - t0
        row.update({key: ti[key] for key in ("n_low", "remesh_s", "project_s", "transfer_s",
                                             "n_flipped", "workers")})
        row.update(ground_truth_metrics(Vp, F0, V1))
        row["rest_hausdorff"] = hausdorff(V0, F0, V1, F0)
        row["rest_chamfer"] = chamfer(V0, F0, V1, F0)
        row["gt_stretch_pct"] = gt_stretch_pct(V0, V1, F0)
        log.info("%s%d  %.2fs  d_H %.3e  d_C %.3e  vertex mean %.4f%% max %.3f%%", c, p, row["time_s"],
                 row["hausdorff"], row["chamfer"], row["gt_vertex_mean_pct"], row["gt_vertex_max_pct"])
    except SShaDeError as e:
        row["error"] = str(e) or type(e).__name__
        log.warning("%s%d failed: %s", c, p, row["error"])
        Vp = None
    return row, V1, Vp


def _tosca_tables(df, sp: dict, excluded: dict, info: dict, out_dir, t_start: float) -> dict:
    """``table.csv`` / ``table.md`` (per-class means, the paper's row), ``run.json``
    finished (:func:`eval.run.runinfo.finish_run`); the return value of :func:`run_tosca`."""
    import pandas as pd

    n_low, k, seed, gradient = sp["n_low"], int(sp["n_samplings"]), int(sp["seed"]), str(sp.get("gradient"))
    cols = [c for c, _, _ in TOSCA_COLUMNS if c not in ("n_cases", "n_failed")] + \
        ["rest_chamfer", "remesh_s", "project_s", "transfer_s"]
    table = group_table(df, "class", cols)
    paper = {"class": "paper (§4.2, all TOSCA classes)", "n_cases": math.nan, "n_failed": math.nan,
             "n_low": 6000, **PAPER_TOSCA}
    table = pd.concat([table, pd.DataFrame([paper])], ignore_index=True)
    paths = {"cases": out_dir / "cases.csv"}
    with atomic_write(out_dir / "table.csv", "w", newline="") as fh:
        table.to_csv(fh, index=False, float_format="%.6g")
    paths["table_csv"] = out_dir / "table.csv"
    n_err = int((df["error"].astype(str).str.len() > 0).sum())
    wall = time.perf_counter() - t_start
    title = (f"### TOSCA non-rigid isometric deformations (paper §4.2): n_low={n_low}, k={k}, seed={seed}, "
             f"gradient={gradient}, anchor={sp.get('anchor')}, transfer={sp.get('transfer')}, "
             f"average={sp.get('average')}")
    md = "\n".join([
        title, "",
        markdown_table(table, ("class", "Class"), TOSCA_COLUMNS),
        f"Paper (§4.2, mean over all its TOSCA classes): d_H = {PAPER_TOSCA['hausdorff']:.2e}, "
        f"d_C = {PAPER_TOSCA['chamfer']:.2e}.",
        "d_H, d_C: vertex-to-surface Hausdorff / Chamfer (paper §4.2), shapes centred and scaled into the "
        "unit sphere of the true pose. Vertex errors in % of the true pose's bounding-box diagonal. "
        "'d_H rest vs pose': the rest pose itself against the true pose. 'GT stretch': mean relative edge "
        "length change rest -> true pose (0 for an exact isometry). Time: wall seconds per case "
        f"(all {k} samplings, workers={table_workers(df)}).",
        f"Excluded: {', '.join(f'{c} ({r})' for c, r in excluded.items()) or 'none'}. "
        f"{len(df)} case(s), {n_err} failed, {wall:.1f} s in all.", ""])
    finish_run(out_dir, md, paths, info, n_cases=len(df), n_errors=n_err, wall_s=wall)
    return {"out_dir": out_dir, "paths": paths, "cases": df, "table": table, "n_cases": len(df), "n_errors": n_err}


def table_workers(df) -> str:
    """The worker counts used (for the table note)."""
    if "workers" not in df.columns:
        return "-"
    w = sorted({int(x) for x in df["workers"].dropna()})
    return ",".join(map(str, w)) or "-"


register_experiment("tosca", run_tosca,
                    options=section_reader("tosca", ToscaConfig, absent="use experiment=tosca"))
