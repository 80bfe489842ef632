"""The evaluator: every method on every case, metrics, tables (Hydra app).

Usage (from the repository root)::

    python -m eval dataset=faust dataset.root=../shared/data/faust_reg
    python -m eval experiment=ci dataset.root=DIR             # 2 cases, small settings
    python -m eval dataset.root=DIR methods=[ARAP,Elastic] out_dir=/tmp/run

Config: ``conf/config.yaml`` (+ ``conf/dataset/faust.yaml``, ``conf/experiment/*.yaml``).
For each case (:mod:`eval.datasets`) and each method (:mod:`eval.methods`) the
``deform`` call is timed with :func:`time.perf_counter` into ``time_s``, after the method's
optional ``warmup()`` has compiled its numba kernels (the seconds go to the ``compile_s``
column and to ``run.json``'s ``compile_s`` per method, never into ``time_s``;
:mod:`sshade.warmup`), the result is scored with
:func:`eval.metrics.deformation_metrics` and, when the case has a ground truth,
:func:`eval.metrics.ground_truth_metrics`. Every method runs through
:func:`sshade.guard.run_method` (issue 19): on read-only copies of the case, with the
optional ``timeout_s`` of each call, its output checked
(:func:`sshade.mesh.validate.validate_deformed`) before any metric. A method that fails on a
case (our methods: :class:`~sshade.errors.SShaDeError`; a plug-in: any exception,
``SystemExit`` included, :func:`sshade.method.is_plugin`; a time-out; a refused output)
gets its message in the ``error`` column and the run goes on; so does a result whose
handle error exceeds ``handle_error_max_pct`` (% of the diagonal; its metrics stay in
the row). Ctrl-C stops the run. A case mesh with several connected components is
deformed component by component (:func:`sshade.components.deform_components`). Method
info values become cells through :func:`_info_columns` (safe names and values). Outputs in ``out_dir`` (default ``outputs/<experiment.name>/<date_time>``):
``cases.csv`` (rewritten after every case), ``table.csv``, ``table.md``, ``table.tex``
(:mod:`eval.tables`), ``run.json`` (:mod:`eval.runinfo`), ``eval.log`` and Hydra's
``.hydra/`` folder. All tables and ``run.json`` are written atomically.

Exit status: 0 on success (even if some method failed on some case), 2 on a
configuration or input error (one ``error: ...`` line on stderr).
"""
from __future__ import annotations

import json
import logging
import math
import sys
import time
from pathlib import Path

import numpy as np

from sshade.errors import SShaDeError

from sshade.confdir import config_dir

__all__ = ["CONF_DIR", "run", "main"]

CONF_DIR = config_dir()  # conf/ of a source checkout, else the installed package data

log = logging.getLogger("eval")


def _abs(path) -> Path:
    """Resolve ``path`` against the directory the command was started from."""
    from hydra.utils import to_absolute_path
    return Path(to_absolute_path(str(Path(str(path)).expanduser()))).resolve()


def _dataset_root(cfg) -> Path:
    from omegaconf import OmegaConf
    ds = cfg.get("dataset")
    if ds is None:
        raise SShaDeError("no dataset configured; pass dataset=faust dataset.root=DIR")
    if OmegaConf.is_missing(ds, "root") or ds.get("root") in (None, ""):
        raise SShaDeError("dataset.root is not set: pass dataset.root=DIR, a folder with FAUST "
                          "registrations tr_reg_XYZ.ply (e.g. dataset.root=../shared/data/faust_reg)")
    root = _abs(ds.root)
    if str(ds.get("name", "")) == "defaust" and _build_wanted(root, ds):
        _build_defaust(root, ds)
    if not root.is_dir():
        hint = ""
        if str(ds.get("name", "")) == "defaust":
            hint = (f"; the evaluator builds a DeFAUST only into the default folder {DEFAULT_DEFAUST_ROOT} "
                    f"or with dataset.build.enabled=true (python -m defaust out=DIR builds one)")
        raise SShaDeError(f"dataset.root does not exist or is not a folder: {root}{hint}")
    return root


#: The only folder the evaluator builds the embedded DeFAUST into on its own
#: (``dataset.build.enabled: auto``), relative to where the command runs.
DEFAULT_DEFAUST_ROOT = "data/defaust"


def _build_wanted(root: Path, ds) -> bool:
    """``dataset.build.enabled``: ``auto`` (default) builds only when ``root`` is
    :data:`DEFAULT_DEFAUST_ROOT`; ``true`` builds into any folder (the builder still
    refuses a folder holding another build or other files); ``false`` never builds.
    A user's own folder (e.g. a DeFAUST built from their FAUST scans, or a typo) is
    therefore read, never written, unless they ask for a build."""
    enabled = (ds.get("build", {}) or {}).get("enabled", "auto")
    if isinstance(enabled, str) and enabled.strip().lower() == "auto":
        return root == _abs(DEFAULT_DEFAUST_ROOT)
    if not isinstance(enabled, bool):
        raise SShaDeError(f"dataset.build.enabled must be auto, true or false, got {enabled!r}")
    return enabled


def _build_defaust(root: Path, ds) -> None:
    """Build (or finish, or verify) the DeFAUST dataset at ``root`` before evaluating
    (``dataset.build.enabled``). Resumable: complete, checksum-valid items are skipped."""
    from omegaconf import OmegaConf

    from defaust.cli import compose_config
    from defaust.cli import run as build_run
    extra = ds.get("build", {}).get("overrides") or []
    extra = OmegaConf.to_container(extra) if OmegaConf.is_config(extra) else list(extra)
    logging.getLogger("defaust").setLevel(logging.INFO)
    bcfg = compose_config([f"out={root}", *[str(x) for x in extra]])
    build_run(bcfg)


def _metric_functions():
    try:
        from .metrics import deformation_metrics, ground_truth_metrics
    except ImportError as e:
        raise SShaDeError(f"eval.metrics is not available ({e})") from None
    return deformation_metrics, ground_truth_metrics


_SKIP = object()

#: Info keys whose values feed the tables (eval.tables.stop_lines): kept under their
#: name only with a value of the expected type, else renamed ``info_<key>``.
_TYPED_INFO = {
    "iterations": lambda v: v is None or (isinstance(v, (int, float)) and not isinstance(v, bool)),
    "converged": lambda v: v is None or isinstance(v, (bool, int, float)),
    "protocol": lambda v: v is None or isinstance(v, str),
}
#: Column names of the summary tables an info key must not take (eval.tables.summarize).
_RESERVED = ("n_cases", "n_failed", "warnings", "error", "method", "case")


def _scalar(v):
    """Method info value -> a CSV cell (issue 19: no value may break cases.csv or a
    table): bools, ints (beyond int64: as float, or left empty when not finite), finite
    floats (NaN/inf: empty), strings on one line (at most 200 characters), flat
    lists/arrays of such scalars as JSON (NaN -> null; e.g. SShaDe's per-sampling
    seeds); nested structures (per-sampling dicts) and other objects are left out
    (their sums are separate info keys)."""
    if isinstance(v, np.generic):
        v = v.item()
    if v is None or isinstance(v, bool):
        return v
    if isinstance(v, int):
        if abs(v) < 2 ** 63:
            return v
        try:
            v = float(v)
        except OverflowError:
            return None
    if isinstance(v, float):
        return v if math.isfinite(v) else None
    if isinstance(v, str):
        return " ".join(v.split())[:200]
    if isinstance(v, np.ndarray) and v.ndim == 1:
        v = v.tolist()
    if isinstance(v, (list, tuple)):
        items = [_scalar(x) if x is None or isinstance(x, (bool, int, float, str, np.generic)) else _SKIP for x in v]
        return _SKIP if any(x is _SKIP for x in items) else json.dumps(items)
    return _SKIP


def _info_columns(info, taken) -> dict:
    """The cells of a method's ``info`` for its row: keys made safe column names
    (letters, digits, ``_``; at most 64 characters; non-string keys by their text),
    values by :func:`_scalar`; a key clashing with ``taken`` (the row's columns), a
    summary column or a typed key with a value of another type (:data:`_TYPED_INFO`)
    becomes ``info_<key>``; ``compile_s`` (already in the row) is left out."""
    import re
    out: dict = {}
    for k, v in info.items():
        key = re.sub(r"[^A-Za-z0-9_]+", "_", k if isinstance(k, str) else str(k)).strip("_")[:64]
        v = _scalar(v)
        if not key or k == "compile_s" or v is _SKIP:
            continue
        if key in taken or key in _RESERVED or not _TYPED_INFO.get(key, lambda _: True)(v):
            key = f"info_{key}"
        if key not in taken and key not in out:
            out[key] = v
    return out


#: dataset.name -> the config keys passed to its case builder (eval.datasets.load_cases).
_DATASET_KEYS = {
    "faust": ("subjects", "poses", "n_per_landmark", "neighbourhood", "static_threshold", "seed", "limit"),
    "defaust": ("subjects", "resolution", "limit"),
    "shapes": ("files", "vertex_range", "cache", "n_per_group", "region_radius", "rotate_deg", "translate",
               "seed", "limit"),
}


def run(cfg) -> dict:
    """Run the evaluation described by ``cfg`` (an OmegaConf DictConfig).

    Returns
    -------
    dict with ``out_dir`` (Path), ``paths`` (name -> Path of the written files),
    ``n_cases``, ``n_errors`` and ``summary`` (per-method DataFrame).

    Raises
    ------
    SShaDeError on a configuration or input problem (missing dataset.root, no cases,
    unknown method, ...), before any method runs.
    """
    t_start = time.perf_counter()
    from .methods import make_methods
    methods = make_methods(cfg)  # every method's parameters are checked before any work
    guard = _guard_options(cfg)  # timeout_s, handle_error_max_pct
    refs = _References(cfg, (cfg.get("dataset") or {}).get("baseline_cases", None))  # config checked here too
    root = _dataset_root(cfg)  # fail fast, before the heavier imports (may build DeFAUST)

    import pandas as pd
    from omegaconf import OmegaConf
    from tqdm import tqdm
    from tqdm.contrib.logging import logging_redirect_tqdm

    from .datasets import load_cases
    from .runinfo import collect_runinfo, write_runinfo
    from .tables import compare, write_cases, write_tables

    out_dir = _abs(cfg.out_dir)
    _metric_functions()  # eval.metrics importable, before any work
    ds = cfg.dataset
    name = str(ds.get("name", "faust"))
    opts = {k: ds.get(k) for k in _DATASET_KEYS.get(name, _DATASET_KEYS["faust"]) if k in ds}
    for k in ("subjects", "poses", "files", "vertex_range"):
        if opts.get(k) is not None and OmegaConf.is_config(opts[k]):
            opts[k] = OmegaConf.to_container(opts[k])
    if opts.get("cache") is not None:
        opts["cache"] = _abs(opts["cache"])
    cases = load_cases(name, root, **opts)
    log.info("%d case(s) from %s; methods %s; output %s", len(cases), root,
             [m.name for m in methods], out_dir)

    config = OmegaConf.to_container(cfg, resolve=True)
    config["dataset"]["root"] = str(root)
    seeds = {"dataset": ds.get("seed"), "sshade": cfg.get("sshade", {}).get("seed"),
             "cases": {c.name: getattr(c, "seed", None) for c in cases}}
    if name == "defaust":
        from defaust.dataset import read_manifest
        seeds["defaust_manifest_seed"] = read_manifest(root).get("parameters", {}).get("seed")
    n_base = ds.get("baseline_cases", None)  # full-res baselines only on the first N cases
    info = collect_runinfo(config, seeds=seeds, extra={"status": "running", "out_dir": str(out_dir)})
    write_runinfo(out_dir / "run.json", info)

    rows: list[dict] = []
    compile_s: dict[str, float] = {}  # method -> seconds of warm-up/compilation (run.json)
    from .figures import figures_options, write_case_figure
    fig_on, fig_left = figures_options(cfg)  # figures.enabled / max_cases; missing key = off
    def runs_on(ci: int, m) -> bool:  # baselines take minutes per high-res case: run on a subset
        return n_base is None or ci < int(n_base) or m.name == "SShaDe"

    names = [m.name for m in methods]  # checked when built; a plug-in cannot rename its row later
    n_runs = sum(runs_on(ci, m) for ci in range(len(cases)) for m in methods)
    bar = tqdm(total=n_runs, desc="runs", unit="run", file=sys.stderr, dynamic_ncols=True)
    with logging_redirect_tqdm(), bar:
        for ci, case in enumerate(cases):
            deformed = {}  # method -> deformed vertices, for the optional figure
            refs.start_case(ci, case)
            for m, m_name in zip(methods, names):
                if not runs_on(ci, m):
                    continue
                bar.set_postfix_str(f"{case.name} {m_name}")
                row, deformed[m_name] = _run_one(m, m_name, case, refs, guard)
                if "compile_s" in row:
                    compile_s[m_name] = compile_s.get(m_name, 0.0) + row["compile_s"]
                rows.append(row)
                bar.update(1)
            write_cases(pd.DataFrame(rows), out_dir)  # partial results survive a crash
            if fig_on and fig_left > 0:  # out_dir/figures/<case>.png (eval/figures.py)
                fig_left -= 1
                write_case_figure(case, {n: deformed.get(n) for n in names}, out_dir / "figures",
                                  not_run=[n for m, n in zip(methods, names) if not runs_on(ci, m)])  # "not run", not "failed"

    df = pd.DataFrame(rows)
    exp = cfg.get("experiment", {}).get("name", name)
    title = f"{exp}: {len(cases)} {name} case(s)"
    paths = write_tables(df, out_dir, title=title)
    summ = compare(df).main  # every method on the same cases (eval.tables.compare)
    n_err = int((df["error"].astype(str).str.len() > 0).sum())
    info.update(status="done", n_cases=len(cases), n_rows=len(df), n_errors=n_err,
                wall_s=round(time.perf_counter() - t_start, 3), compile_s={k: round(v, 3) for k, v in compile_s.items()},
                outputs={k: Path(v).name for k, v in paths.items()})
    paths["run_json"] = write_runinfo(out_dir / "run.json", info)
    print(Path(paths["table_md"]).read_text())
    print(f"wrote {', '.join(Path(p).name for p in paths.values())} to {out_dir}")
    return {"out_dir": out_dir, "paths": paths, "n_cases": len(cases), "n_errors": n_err, "summary": summ}


def _guard_options(cfg) -> dict:
    """``timeout_s`` (positive seconds or null: the limit of each method call,
    :func:`sshade.guard.run_method`) and ``handle_error_max_pct`` (positive, % of the
    bounding-box diagonal, or null: the largest handle error of a successful run) of
    the config, checked; SShaDeError naming the key."""
    from sshade.guard import HANDLE_ERROR_MAX_PCT, check_timeout
    hmax = cfg.get("handle_error_max_pct", HANDLE_ERROR_MAX_PCT)
    if hmax is not None:
        try:
            hmax = check_timeout(hmax, "handle_error_max_pct")
        except SShaDeError:
            raise SShaDeError(f"handle_error_max_pct must be a positive number (% of the bounding-box diagonal) "
                              f"or null for no limit, got {hmax!r}") from None
    return {"timeout_s": check_timeout(cfg.get("timeout_s", None), "timeout_s"), "handle_error_max_pct": hmax}


def _run_one(m, name: str, case, refs, guard: dict):
    """One (case, method) run: :func:`sshade.guard.run_method`, the metrics, the method's
    info; returns ``(row, U)`` (``U`` None when the method failed). A failure (the
    method's, or a handle error above ``guard['handle_error_max_pct']``: its metrics
    stay in the row) is the row's ``error``; the run goes on."""
    from sshade.guard import handles_not_reached, run_method
    from .metrics import deformation_metrics, ground_truth_metrics
    row = {"case": case.name, "subject": case.subject, "pose": case.pose, "method": name,
           "n_vertices": len(case.V), "n_faces": len(case.F), "n_handles": len(case.handles),
           "n_static": int(case.static.sum()), "n_dynamic": int((~case.static).sum()),
           "case_seed": getattr(case, "seed", None), "error": ""}
    try:
        r = run_method(m, case.V, case.F, case.handles, case.targets, timeout_s=guard["timeout_s"])
        row["compile_s"], row["time_s"] = r.compile_s, r.seconds  # compilation: never inside time_s
        for w in r.warnings:  # e.g. sshade.deform.LowResSkippedWarning: logged and recorded
            log.warning("%s %s: %s", case.name, name, w)
        if r.warnings:
            row["warnings"] = " | ".join(" ".join(w.split()) for w in r.warnings)
        row.update(deformation_metrics(case.V, r.U, case.F, case.handles, case.targets))
        row.update(refs.metrics(m, r.U))
        if getattr(case, "V_gt", None) is not None:
            row.update(ground_truth_metrics(r.U, case.F, case.V_gt))
    except SShaDeError as e:  # the method failed (sshade.guard.MethodFailure), or a metric refused its result
        row["error"] = " ".join(str(e).split()) or type(e).__name__
        log.warning("%s %s failed: %s", case.name, name, row["error"])
        return row, None
    row.update(_info_columns(r.info, row))
    row["error"] = handles_not_reached(row.get("handle_err_pct"), guard["handle_error_max_pct"]) or ""
    if row["error"]:
        log.warning("%s %s failed: %s", case.name, name, row["error"])
    log.info("%s %-8s %7.2fs  vol %.2f%%  EL %.2f%%  FA %.3f deg", case.name, name, row["time_s"],
             row.get("volume_err_pct", math.nan), row.get("edge_err_pct", math.nan),
             row.get("angle_err_deg", math.nan))
    return row, r.U


class _References:
    """The ``reference`` config section at work: for the cases it selects
    (``reference.cases``: ``baseline`` = the cases the full-resolution baselines run on,
    ``dataset.baseline_cases``; ``all``; ``none``), the deep-converged full-resolution
    minimiser of the energy each method is compared with
    (:func:`eval.reference.method_energy`), computed once per (case, energy), cached in
    ``reference.cache`` and reused by later runs; :meth:`metrics` gives a row's
    ``ref_mean_pct``, ``ref_max_pct``, ``energy_gap`` columns (none outside the selection).
    The reference's own solve is not part of any method's ``time_s``."""

    def __init__(self, cfg, n_base):
        rc = cfg.get("reference", None) or {}
        self.mode = str(rc.get("cases", "baseline"))
        if self.mode not in ("baseline", "all", "none"):
            raise SShaDeError(f"reference.cases must be baseline, all or none, got {self.mode!r}")
        self.cache = _abs(rc.get("cache", "data/references"))
        from .config_check import config_number
        self.max_iter = config_number(cfg, "reference.max_iter", min=1, default=50000)
        self.time_budget_s = config_number(cfg, "reference.time_budget_s", kind=float, min=0, allow_none=True,
                                           default=3600)
        self.n_base = n_base
        self.case = None
        self.refs: dict = {}
        self.ops: dict = {}

    def start_case(self, ci: int, case) -> None:
        self.refs, self.ops = {}, {}
        on = self.mode == "all" or (self.mode == "baseline" and (self.n_base is None or ci < int(self.n_base)))
        self.case = case if on else None

    def metrics(self, method, Vd) -> dict:
        if self.case is None:
            return {}
        from sshade.arap import build_operators

        from .reference import method_energy, reference_metrics, reference_solution
        c, e = self.case, method_energy(method)
        if e not in self.refs:
            # a full-resolution solve of this very energy from the rigid fit (ARAP, Elastic
            # under the converged protocol) is on the deep solve's own path: continue from it
            same_path = getattr(method, "energy", None) == e and getattr(method, "protocol", None) == "converged"
            self.refs[e] = reference_solution(c.V, c.F, c.handles, c.targets, energy=e, cache_dir=self.cache,
                                              max_iter=self.max_iter, time_budget_s=self.time_budget_s,
                                              U0=Vd if same_path else None)
            self.ops[e] = build_operators(c.V, c.F, e)
            ref = self.refs[e]
            log.info("%s reference (%s): %s, %s iterations, %s", c.name, e,
                     "cached" if ref.info.get("cached") else f"computed in {ref.info.get('seconds')} s",
                     ref.info.get("iterations"), ref.info.get("status"))
        ref = self.refs[e]
        out = reference_metrics(c.V, Vd, c.F, ref, operators=self.ops[e])
        out.update(ref_energy_type=e, ref_status=ref.info.get("status"), ref_iterations=ref.info.get("iterations"))
        return out


#: experiment.kind -> "module:function" running that experiment from the config.
EXPERIMENTS = {
    "cases": "eval.app:run",                         # methods x dataset cases (FAUST, DeFAUST)
    "scaling": "eval.scaling:run_scaling",           # issue 4 scaling benchmark
    "tosca": "eval.isometric:run_tosca",             # paper §4.2 non-rigid isometric (TOSCA)
    "pose_transfer": "eval.pose_transfer:run_pose_transfer",  # paper §4.3 pose transfer
    "convergence": "eval.convergence:run_convergence",  # time to accuracy of the ARAP solvers
}


def run_experiment(cfg, *, fresh: bool = False):
    """Dispatch on ``experiment.kind`` (default ``cases``); see :data:`EXPERIMENTS`.

    Every number of the config is checked first (:func:`eval.config_check.check_config`),
    then the experiment runs in its claimed output folder ``cfg.out_dir``
    (:func:`eval.outdir.claimed_run`: new, empty, or an earlier evaluator output, else
    refused before any work; ``fresh``: ``out_dir`` is the default dated name, which gets
    a suffix rather than being reused).

    Raises
    ------
    SShaDeError for a bad config value or an unknown ``experiment.kind`` (before any
    work), :class:`eval.outdir.OutputDirError` for a folder it may not write into.
    """
    import importlib

    from .config_check import check_config
    from .outdir import claimed_run
    check_config(cfg)  # every number of the config, before any work (also for sweep jobs)
    kind = str(cfg.get("experiment", {}).get("kind", "cases"))
    if kind not in EXPERIMENTS:
        raise SShaDeError(f"unknown experiment.kind {kind!r}; choose among {sorted(EXPERIMENTS)}")
    mod, fn = EXPERIMENTS[kind].split(":")
    with claimed_run(cfg, fresh=fresh):
        return getattr(importlib.import_module(mod), fn)(cfg)


def _pin_out_dir(cfg) -> bool:
    """Pin ``out_dir`` once. In a multirun (``python -m eval -m``) it is the job's folder
    Hydra made (``hydra.sweep.dir/subdir``); in a single run it is ``out_dir`` resolved
    once (a ``${now:...}`` in it cannot name two folders). Returns True when ``out_dir``
    is the config's default (not given on the command line): a fresh name."""
    from hydra.core.hydra_config import HydraConfig
    from hydra.types import RunMode
    from omegaconf import open_dict
    if not HydraConfig.initialized():
        return False
    hc = HydraConfig.get()
    with open_dict(cfg):
        if hc.mode == RunMode.MULTIRUN and hc.runtime.output_dir:
            cfg.out_dir = str(hc.runtime.output_dir)
            return False
        cfg.out_dir = str(cfg.out_dir)
    given = {str(o).lstrip("+~").split("=", 1)[0] for o in hc.overrides.task}
    return "out_dir" not in given


def _main(cfg) -> None:
    """Hydra task of ``python -m eval``: run the experiment; a bad config or input, an
    OSError (``error: ...``, status 2) or Ctrl-C (``interrupted``, 130) ends the process
    through :func:`sshade.clirun.run_command`."""
    from sshade.clirun import run_command

    fresh = _pin_out_dir(cfg)
    rc = run_command(lambda: run_experiment(cfg, fresh=fresh), where=cfg.get("out_dir"))
    if rc:
        raise SystemExit(rc)


def main() -> None:
    """Console entry point (``python -m eval``): Hydra parses the overrides.

    The command line is composed and every config value checked
    (:func:`eval.config_check.check_config`) before Hydra makes the run folder; a bad
    one gives one ``error: ...`` line and exit status 2, Ctrl-C ``interrupted`` and 130
    (:func:`sshade.clirun.hydra_main`).
    """
    from sshade.clirun import hydra_main
    from .config_check import check_config
    argv = sys.argv[1:]
    if any(a in ("-m", "--multirun") for a in argv) and not any("hydra.callbacks.sweep_aggregate" in a for a in argv):
        # a multirun claims its hydra.sweep.dir like eval.sweep does (eval.sweep.claim_sweep_dir)
        argv = [*argv, "++hydra.callbacks.sweep_aggregate._target_=eval.sweep.AggregateSweepCallback"]
    hydra_main(_main, CONF_DIR, argv=argv, check=check_config)
