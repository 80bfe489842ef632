"""The ``cases`` experiment (the default): every method on every case, metrics, tables.

Run through ``python -m eval`` (:mod:`eval.app`); usage (from the repository root)::

    python -m eval dataset=faust dataset.root=../shared/data/faust_reg
    python -m eval experiment=ci dataset.root=DIR             # 2 cases, small settings
    python -m eval dataset.root=DIR methods=[ARAP,Elastic] out_dir=/tmp/run

Config: ``conf/config.yaml`` (+ ``conf/dataset/faust.yaml``, ``conf/experiment/*.yaml``).
For each case (:mod:`eval.datasets`, ``dataset.name`` looked up in its registry) and each method
(:mod:`eval.methods`) the
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
info values become cells through :func:`_info_columns` (safe names and values). Outputs in ``out_dir``
(default ``outputs/<experiment.name>/<date_time>``):
``cases.csv`` (rewritten after every case), ``table.csv``, ``table.md``, ``table.tex``
(:mod:`eval.tables`), ``breakdown.csv``, ``breakdown.md`` (per pose, per subject, the
paired SShaDe-Elastic comparison; :mod:`eval.breakdown`; with figures also
``breakdown.png``), ``run.json`` (:mod:`eval.runinfo`), ``eval.log``, Hydra's
``.hydra/`` folder and the result store ``runs/<case>/<method>.json`` (:mod:`eval.store`).
All tables and ``run.json`` are written atomically.

Result store and resume (issue 21): each (case, method) run is stored as soon as it
finishes, keyed by the method's definition, the case's identity and the guard/reference
options; the tables are built from the stored rows. ``resume=true`` with ``out_dir`` =
an earlier run's folder continues it (the claim keeps its files, :mod:`eval.outdir`):
only the pairs missing from the store, or stored under another key, run; a method added
later runs only its own cases. Without ``resume`` the store starts empty. The baselines
run on the cases ``dataset.baseline_cases`` selects (:mod:`eval.subset`; the rule is
stated in the table's title); the progress bar's remaining time is weighted by each
method's expected cost (:mod:`eval.progress`).

Exit status of ``python -m eval``: 0 on success (even if some method failed on some
case), 2 on a configuration or input error (one ``error: ...`` line on stderr).

Phases of :func:`run`: :func:`_setup` (methods, options, dataset, cases; every check
before any work), :func:`_start_runinfo`, :func:`_run_cases`, :func:`_finish` (tables,
``run.json``).
"""
from __future__ import annotations

import json
import logging
import math
import time
from pathlib import Path

import numpy as np

from sshade.checks import config_bool
from sshade.errors import SShaDeError
from sshade.guard import HANDLE_ERROR_MAX_PCT, check_timeout, handles_not_reached, run_method

from .. import datasets
from .. import methods as method_table
from ..breakdown import write_breakdown
from ..config_check import config_number
from ..figures import figures_options, write_case_figure
from ..meshview import view_options, write_case_view
from ..methods import method_spec
from ..metric_meshes import CaseMeshes
from ..metrics import deformation_metrics, ground_truth_metrics
from ..paths import abs_path
from ..progress import CostModel, default_cost_model, weighted_bar
from ..reference import energy_operators, method_energy, reference_metrics, reference_solution, sr_alpha, status_words
from ..runinfo import collect_runinfo, method_sources, write_runinfo
from ..store import ResultStore, case_identity, json_safe, pair_key
from ..subset import baseline_selection, check_baseline_cases, method_selections
from ..tables import compare, write_cases, write_tables
from .cases_plan import plan_runs, planned_root
from .common import as_list, sshade_spec
from .registry import register_experiment

__all__ = ["run", "sshade_params"]

log = logging.getLogger("eval")


def sshade_params(cfg) -> dict:
    """The parameters the ``SShaDe`` (and ``SShaDe+refine``) rows run with: the method
    config ``method.SShaDe`` (:func:`eval.experiments.common.sshade_spec`), the very
    definition :func:`eval.methods.make_methods` builds SShaDe from."""
    return sshade_spec(cfg)


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
    s = _setup(cfg)
    info = _start_runinfo(cfg, s)
    rows = _run_cases(cfg, s)
    return _finish(cfg, s, rows, info, t_start)


class _Setup:
    """What :func:`_setup` prepared: ``methods``, ``names``, ``specs`` (each method's
    resolved definition), ``guard``, ``refs``, ``root``, ``out_dir``, ``name``
    (dataset), ``cases``, ``base`` (indices of the cases the baselines run on, None =
    all) and ``base_rule`` (that rule in words), ``own`` (method name -> (indices or
    None, rule in words) for the methods ``method_cases`` gives a rule of their own),
    ``store`` and ``resume``; ``meshes``: the metrics' kept rest and ground-truth meshes
    (:class:`~eval.metric_meshes.CaseMeshes`); ``build``: the dataset's build stage when one ran
    (:func:`eval.experiments.cases_plan.planned_root`), ``plan``: the runs'
    :class:`~eval.experiments.cases_plan.PlanRecord` once logged."""

    def __init__(self, **kw):
        self.__dict__.update(kw)

    def runs_on(self, ci: int, m) -> bool:
        """Baselines take minutes per high-res case: they run on the cases
        ``dataset.baseline_cases`` selects (:func:`eval.subset.baseline_selection`;
        SShaDe on all), except a method ``method_cases`` gives its own rule
        (:func:`eval.subset.method_selections`)."""
        if m.name in self.own:
            sel = self.own[m.name][0]
            return sel is None or ci in sel
        return self.base is None or ci in self.base or m.name == "SShaDe"


def _method_specs(cfg, methods) -> list[dict]:
    """Each method's resolved definition (what its result depends on; :mod:`eval.store`):
    ours from :func:`eval.methods.method_spec`, a plug-in's ``_target_`` mapping as given."""
    from omegaconf import OmegaConf
    items = cfg.get("methods")
    items = [n for n in items.replace(",", " ").split() if n] if isinstance(items, str) else as_list(items)
    out = []
    for it, m in zip(items, methods):
        if OmegaConf.is_config(it) or isinstance(it, dict):
            spec = OmegaConf.to_container(it, resolve=True) if OmegaConf.is_config(it) else dict(it)
        else:
            spec = method_spec(cfg, str(it))
        out.append({"class": f"{type(m).__module__}.{type(m).__qualname__}", "name": m.name, **json_safe(spec)})
    return out


def _setup(cfg) -> _Setup:
    """Every method built and checked, the guard and reference options, the dataset's
    root (may build DeFAUST) and cases, the baseline subset, the result store (emptied
    unless ``resume``), before any method runs."""
    methods = method_table.make_methods(cfg)  # every method's parameters are checked before any work
    specs = _method_specs(cfg, methods)
    guard = _guard_options(cfg)  # timeout_s, handle_error_max_pct
    base_spec = (cfg.get("dataset") or {}).get("baseline_cases", None)
    check_baseline_cases(base_spec)
    refs = _References(cfg)  # config checked here too
    resume = config_bool(cfg, "resume", default=False)
    meshes = config_bool(cfg, "store.meshes", default=False)
    # fail fast, before the heavier imports; a DeFAUST build is planned (logged) first (eval/experiments/cases_plan.py)
    mc = cfg.get("method_cases")
    root, build = planned_root(cfg, methods, refs, lambda cs, base: _Setup(
        base=base, own=method_selections(cs, mc, [x.name for x in methods])).runs_on)
    out_dir = abs_path(cfg.out_dir)
    ds = cfg.dataset
    name = str(ds.get("name", "faust"))
    cases = datasets.load_cases(name, root, **datasets.dataset_options(ds))
    base, base_rule = baseline_selection(cases, base_spec)
    names = [m.name for m in methods]  # checked when built; a plug-in cannot rename its row later
    own = method_selections(cases, cfg.get("method_cases"), names)
    log.info("%d case(s) from %s; methods %s; baselines on %s%s; output %s", len(cases), root, names, base_rule,
             "".join(f"; {n} on {rule}" for n, (_, rule) in own.items()), out_dir)
    store = ResultStore(out_dir, meshes=meshes)
    if not resume:
        n = store.clear()
        if n:
            log.info("resume=false: removed %d stored run(s) of an earlier run in %s", n, store.root)
    return _Setup(methods=methods, names=names, specs=specs, guard=guard, refs=refs, root=root, out_dir=out_dir,
                  name=name, cases=cases, base=base, base_rule=base_rule, own=own, store=store, resume=resume,
                  build=build, meshes=CaseMeshes())


def _start_runinfo(cfg, s: _Setup) -> dict:
    """``run.json`` with status ``running``: the resolved config, the seeds (dataset,
    SShaDe, each case's, the dataset's own, e.g. a DeFAUST build's), each method's source
    file with its sha256 and git state (:func:`eval.runinfo.method_sources`)."""
    from omegaconf import OmegaConf

    config = OmegaConf.to_container(cfg, resolve=True)
    config["dataset"]["root"] = str(s.root)
    seeds = {"dataset": cfg.dataset.get("seed"), "sshade": cfg.get("sshade", {}).get("seed"),
             "cases": {c.name: getattr(c, "seed", None) for c in s.cases}}
    d = datasets.find_dataset(s.name)
    if d is not None and d.seeds is not None:
        seeds.update(d.seeds(s.root))
    info = collect_runinfo(config, seeds=seeds, extra={"status": "running", "out_dir": str(s.out_dir),
                                                       "method_sources": method_sources(s.methods)})
    write_runinfo(s.out_dir / "run.json", info)
    return info


def _pair_keys(cfg, s: _Setup, ci: int, case) -> list[tuple[str, dict]]:
    """The store keys (:func:`eval.store.pair_key`) of every method on case ``ci``: the
    method's definition, the case's identity, the guard and reference options."""
    ident = case_identity(case, dataset=s.name, root=s.root, seed=cfg.dataset.get("seed"))
    extra = {"guard": s.guard, "reference": s.refs.settings(s.refs.covers(ci, s.cases, s.base))}
    return [pair_key(spec, ident, extra) for spec in s.specs]


def _run_cases(cfg, s: _Setup) -> list[dict]:
    """Every (case, method) run (:func:`_run_one`) not already in the result store
    (``resume``; :mod:`eval.store`), each stored as soon as it finishes, with a progress
    bar weighted by each method's expected cost (:mod:`eval.progress`); ``cases.csv``
    rewritten after each case, the optional figures. Returns the rows of every pair, in
    (case, method) order, as stored (an interrupted and resumed run gives the rows of an
    uninterrupted one)."""
    import pandas as pd
    from tqdm.contrib.logging import logging_redirect_tqdm

    fig_on, fig_left = figures_options(cfg)  # figures.enabled / max_cases; missing key = off
    view_left, max_faces = view_options(cfg)  # report.view_cases: 3D views of the first cases (eval/meshview.py)
    methods, names, cases = s.methods, s.names, s.cases
    plan = {ci: [mi for mi, m in enumerate(methods) if s.runs_on(ci, m)] for ci in range(len(cases))}
    keys = {ci: _pair_keys(cfg, s, ci, c) for ci, c in enumerate(cases)}
    cost = default_cost_model(methods)  # measured per-method priors (eval/progress.py)
    done: dict = {}  # (ci, mi) -> stored record
    for ci, mis in plan.items():
        for mi in mis if s.resume else ():
            rec = s.store.load(cases[ci].name, names[mi], keys[ci][mi][0])
            if rec is not None:
                done[ci, mi] = rec
                cost.observe(names[mi], len(cases[ci].V), rec["row"].get("time_s"))
    todo = [(ci, mi) for ci, mis in plan.items() for mi in mis if (ci, mi) not in done]
    if s.resume:
        log.info("resume: %d run(s) restored from %s, %d to run", len(done), s.store.root, len(todo))
    s.plan = plan_runs(s, todo, len(done), cost)  # the plan, before any run (eval/experiments/cases_plan.py)
    bar = weighted_bar(sum(cost.estimate(names[mi], len(cases[ci].V)) for ci, mi in todo), len(todo))
    rows: list[dict] = []
    with logging_redirect_tqdm(), bar:
        for ci, case in enumerate(cases):
            s.refs.start_case(ci, case, s.refs.covers(ci, cases, s.base))
            deformed, unknown = {}, []  # method -> deformed vertices, for the optional figure
            for mi in plan[ci]:
                if (ci, mi) in done:
                    want = (fig_on and fig_left > 0) or view_left > 0
                    deformed[names[mi]] = s.store.load_mesh(done[ci, mi]) if want else None
                    if deformed[names[mi]] is None and not done[ci, mi]["row"].get("error"):
                        unknown.append(names[mi])  # restored without its mesh (store.meshes=false)
                    continue
                bar.set_postfix_str(f"{todo.index((ci, mi)) + 1}/{len(todo)} runs: {case.name} {names[mi]}")
                done[ci, mi], deformed[names[mi]] = _run_stored(s, ci, mi, keys[ci][mi], cost, bar)
                bar.total = bar.n + sum(cost.estimate(names[mj], len(cases[cj].V))
                                        for cj, mj in todo[todo.index((ci, mi)) + 1:]) + 1e-9
                bar.refresh()
            rows = [done[cj, mj]["row"] for cj in range(ci + 1) for mj in plan[cj]]
            write_cases(pd.DataFrame(rows), s.out_dir)  # partial results survive a crash
            if fig_on and fig_left > 0 and unknown:
                fig_left -= 1
                log.info("%s: figure not redrawn (restored runs of %s have no stored mesh; store.meshes=true keeps "
                         "them)", case.name, ", ".join(unknown))
            elif fig_on and fig_left > 0:  # out_dir/figures/<case>.png (eval/figures.py)
                fig_left -= 1
                write_case_figure(case, {n: deformed.get(n) for n in names}, s.out_dir / "figures",
                                  # "not run", not "failed"
                                  not_run=[n for m, n in zip(methods, names) if not s.runs_on(ci, m)])
            if view_left > 0:  # out_dir/report/<case>.js, for index.html (eval/report.py)
                view_left -= 1
                write_case_view(case, {n: deformed.get(n) for n in names}, s.out_dir, max_faces=max_faces,
                                not_run=[n for m, n in zip(methods, names) if not s.runs_on(ci, m)], stored=unknown)
    return rows


def _run_stored(s: _Setup, ci: int, mi: int, key: tuple[str, dict], cost: CostModel, bar):
    """One pair run (:func:`_run_one`), timed into ``cost`` and ``bar``, and stored
    (:meth:`eval.store.ResultStore.save`; a store that cannot be written is logged and the
    run goes on). Returns ``(record, U)``."""
    case, m, name = s.cases[ci], s.methods[mi], s.names[mi]
    t0 = time.perf_counter()
    row, U, info = _run_one(m, name, case, s.refs, s.guard, s.meshes)
    wall = time.perf_counter() - t0
    c = row.get("compile_s")  # a one-off (numba compilation): not a cost of the later runs
    cost.observe(name, len(case.V), wall - (c if isinstance(c, (int, float)) and c == c else 0.0))
    bar.total = max(bar.total, bar.n + wall)  # a run longer than estimated never overfills the bar
    bar.update(wall)
    rec = {"row": json_safe(row), "info": json_safe(info), "case": case.name, "method": name}
    try:
        s.store.save(case.name, name, key[0], key[1], row, info, U)
    except OSError as e:
        log.warning("%s %s: result not stored (%s); a resume will run it again", case.name, name, e)
    return rec, U


def _finish(cfg, s: _Setup, rows, info, t_start) -> dict:
    """Tables (:func:`eval.tables.write_tables`; the title states the baseline rule) and
    breakdowns (:func:`eval.breakdown.write_breakdown`, with its figure when figures
    are enabled) from the stored rows, ``run.json`` with status ``done``, the Markdown
    table on stdout; the return value of :func:`run`."""
    import pandas as pd

    df = pd.DataFrame(rows)
    compile_s: dict[str, float] = {}  # method -> seconds of warm-up/compilation (run.json)
    for r in rows:
        if isinstance(r.get("compile_s"), (int, float)):
            compile_s[r["method"]] = compile_s.get(r["method"], 0.0) + r["compile_s"]
    exp = cfg.get("experiment", {}).get("name", s.name)
    title = f"{exp}: {len(s.cases)} {s.name} case(s)"
    if s.base is not None and any(not s.runs_on(ci, m) for ci in range(len(s.cases)) for m in s.methods
                                  if m.name not in s.own):
        title += f"; full-resolution baselines on {s.base_rule}"
    title += "".join(f"; {n} on {rule}" for n, (sel, rule) in s.own.items() if sel is not None)
    paths = write_tables(df, s.out_dir, title=title)
    paths.update(write_breakdown(df, s.out_dir, figure=figures_options(cfg)[0]))
    summ = compare(df).main  # every method on the same cases (eval.tables.compare)
    n_err = int((df["error"].astype(str).str.len() > 0).sum())
    info.update(status="done", n_cases=len(s.cases), n_rows=len(df), n_errors=n_err,
                wall_s=round(time.perf_counter() - t_start, 3),
                compile_s={k: round(v, 3) for k, v in compile_s.items()},
                outputs={k: Path(v).name for k, v in paths.items()}, plan=s.plan.finish(s.refs.computed_s))
    paths["run_json"] = write_runinfo(s.out_dir / "run.json", info)
    print(Path(paths["table_md"]).read_text())
    print(f"wrote {', '.join(Path(p).name for p in paths.values())} to {s.out_dir}")
    return {"out_dir": s.out_dir, "paths": paths, "n_cases": len(s.cases), "n_errors": n_err, "summary": summ}


def _guard_options(cfg) -> dict:
    """``timeout_s`` (positive seconds or null: the limit of each method call,
    :func:`sshade.guard.run_method`) and ``handle_error_max_pct`` (positive, % of the
    bounding-box diagonal, or null: the largest handle error of a successful run) of
    the config, checked; SShaDeError naming the key."""
    hmax = cfg.get("handle_error_max_pct", HANDLE_ERROR_MAX_PCT)
    if hmax is not None:
        try:
            hmax = check_timeout(hmax, "handle_error_max_pct")
        except SShaDeError:
            raise SShaDeError(f"handle_error_max_pct must be a positive number (% of the bounding-box diagonal) "
                              f"or null for no limit, got {hmax!r}") from None
    return {"timeout_s": check_timeout(cfg.get("timeout_s", None), "timeout_s"), "handle_error_max_pct": hmax}


def _run_one(m, name: str, case, refs, guard: dict, meshes: CaseMeshes | None = None):
    """One (case, method) run: :func:`sshade.guard.run_method`, the metrics (what they need
    of the rest mesh and the ground truth kept in ``meshes`` for the next pairs on them,
    :mod:`eval.metric_meshes`), the method's info; returns ``(row, U, info)`` (``U`` None
    and ``info`` empty when the method failed). A failure (the
    method's, or a handle error above ``guard['handle_error_max_pct']``: its metrics
    stay in the row) is the row's ``error``; the run goes on."""
    row = {"case": case.name, "subject": case.subject, "pose": case.pose, "method": name,
           "n_vertices": len(case.V), "n_faces": len(case.F), "n_handles": len(case.handles),
           "n_static": int(case.static.sum()), "n_dynamic": int((~case.static).sum()),
           "case_seed": getattr(case, "seed", None), "n_handles_dropped": getattr(case, "n_dropped", None), "error": ""}
    try:
        r = run_method(m, case.V, case.F, case.handles, case.targets, timeout_s=guard["timeout_s"])
        row["compile_s"], row["time_s"] = r.compile_s, r.seconds  # compilation: never inside time_s
        for w in r.warnings:  # e.g. sshade.deform.LowResSkippedWarning: logged and recorded
            log.warning("%s %s: %s", case.name, name, w)
        if r.warnings:
            row["warnings"] = " | ".join(" ".join(w.split()) for w in r.warnings)
        meshes = meshes or CaseMeshes()
        row.update(deformation_metrics(case.V, r.U, case.F, case.handles, case.targets,
                                       rest=meshes.rest(case.V, case.F)))
        row.update(refs.metrics(m, r.U))
        if getattr(case, "V_gt", None) is not None:
            row.update(ground_truth_metrics(r.U, case.F, case.V_gt, target=meshes.target(case.V_gt, case.F)))
    except SShaDeError as e:  # the method failed (sshade.guard.MethodFailure), or a metric refused its result
        row["error"] = " ".join(str(e).split()) or type(e).__name__
        log.warning("%s %s failed: %s", case.name, name, row["error"])
        return row, None, {}
    row.update(_info_columns(r.info, row))
    row["error"] = handles_not_reached(row.get("handle_err_pct"), guard["handle_error_max_pct"]) or ""
    if row["error"]:
        log.warning("%s %s failed: %s", case.name, name, row["error"])
    log.info("%s %-8s %7.2fs  vol %.2f%%  EL %.2f%%  FA %.3f deg", case.name, name, row["time_s"],
             row.get("volume_err_pct", math.nan), row.get("edge_err_pct", math.nan),
             row.get("angle_err_deg", math.nan))
    return row, r.U, r.info


class _References:
    """The ``reference`` config section at work: for the cases it selects
    (``reference.cases``: ``baseline`` = the cases the full-resolution baselines run on,
    ``dataset.baseline_cases``; ``all``; ``none``; or a rule of its own, ``per_pose`` or
    an integer, as for ``dataset.baseline_cases``), the deep-converged full-resolution
    minimiser of the energy each method is compared with
    (:func:`eval.reference.method_energy`), computed once per (case, energy), cached in
    ``reference.cache`` and reused by later runs; :meth:`metrics` gives a row's
    ``ref_mean_pct``, ``ref_max_pct``, ``energy_gap`` columns (none outside the selection).
    The reference's own solve is not part of any method's ``time_s``."""

    def __init__(self, cfg):
        rc = cfg.get("reference", None) or {}
        self.mode = str(rc.get("cases", "baseline")).strip()
        if self.mode not in ("baseline", "all", "none"):
            try:  # a case rule of its own, as dataset.baseline_cases (eval/subset.py)
                self.rule = check_baseline_cases(self.mode)
            except SShaDeError:
                raise SShaDeError(f"reference.cases must be baseline, all, none, per_pose or an integer >= 0, "
                                  f"got {self.mode!r}") from None
        self._sel = None  # (cases, indices) of the own rule, computed once per case list
        self.cache = abs_path(rc.get("cache", "data/references"))
        self.max_iter = config_number(cfg, "reference.max_iter", min=1, default=50000)
        self.time_budget_s = config_number(cfg, "reference.time_budget_s", kind=float, min=0, allow_none=True,
                                           default=3600)
        self.case = None
        self.refs: dict = {}
        self.ops: dict = {}
        self.computed_s = 0.0  # seconds spent computing references (not read from the cache)

    def covers(self, ci: int, cases, base) -> bool:
        """Whether case ``ci`` of ``cases`` gets references: ``base`` is the baseline
        subset (indices, None = every case) that ``baseline`` follows; ``per_pose`` or an
        integer select as :func:`eval.subset.baseline_selection` does."""
        if self.mode in ("all", "none", "baseline"):
            return self.mode == "all" or (self.mode == "baseline" and (base is None or ci in base))
        if self._sel is None or self._sel[0] is not cases:
            self._sel = (cases, baseline_selection(cases, self.rule)[0])
        return self._sel[1] is None or ci in self._sel[1]

    def settings(self, on: bool) -> dict:
        """What of this section changes a row on a case (covered or not, :meth:`covers`):
        whether references are computed there and with which limits (:mod:`eval.store`)."""
        return {"on": True, "max_iter": self.max_iter, "time_budget_s": self.time_budget_s} if on else {"on": False}

    def start_case(self, ci: int, case, on: bool = True) -> None:
        """Case ``ci`` starts (``on``: :meth:`covers` it); earlier solutions dropped."""
        self.refs, self.ops = {}, {}
        self.case = case if on else None

    def metrics(self, method, Vd) -> dict:
        if self.case is None:
            return {}

        c, e = self.case, method_energy(method)
        if e not in self.refs:
            # a full-resolution solve of this very energy (ARAP, Elastic under the converged
            # protocol, from the rigid fit or their coarse start) is on the deep solve's own
            # path: continue from it
            # (ARAP-SR's converged protocol: the deep solve continues from its result and rotations)
            converged = getattr(method, "protocol", None) == "converged"
            same_path = converged and (getattr(method, "energy", None) == e or sr_alpha(e) is not None)
            self.refs[e] = reference_solution(c.V, c.F, c.handles, c.targets, energy=e, cache_dir=self.cache,
                                              max_iter=self.max_iter, time_budget_s=self.time_budget_s,
                                              U0=Vd if same_path else None,
                                              R0=getattr(method, "rotations", None) if same_path else None)
            self.ops[e] = energy_operators(c.V, c.F, e)
            ref = self.refs[e]
            if not ref.info.get("cached"):
                self.computed_s += float(ref.info.get("seconds") or 0.0)
            log.info("%s reference (%s): %s, %s iterations, %s", c.name, e,
                     "cached" if ref.info.get("cached") else f"computed in {ref.info.get('seconds')} s",
                     ref.info.get("iterations"), status_words(ref.info.get("status")))
        ref = self.refs[e]
        R = getattr(method, "rotations", None) if sr_alpha(e) is not None else None
        out = reference_metrics(c.V, Vd, c.F, ref, operators=self.ops[e], R0=R)
        out.update(ref_energy_type=e, ref_status=ref.info.get("status"), ref_iterations=ref.info.get("iterations"))
        return out


register_experiment("cases", run)
