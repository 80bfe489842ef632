"""The ``cases`` experiment (the default): every method on every case, metrics, tables.
Floor 4 of eval/ (eval/experiments/, tests/test_layering.py); notes: docs/implementation.md.

Run through ``python -m eval`` (:mod:`eval.app`); usage (from the repository root)::

    python -m eval dataset=faust dataset.root=../shared/data/faust_reg
    python -m eval experiment=ci dataset.root=DIR             # 2 cases, small settings
    python -m eval dataset.root=DIR methods=[ARAP,Elastic] out_dir=/tmp/run

Exit status of ``python -m eval``: 0 on success (even if some method failed on some
case), 2 on a configuration or input error (one ``error: ...`` line on stderr)."""
from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field
from pathlib import Path

from eval import datasets
from eval import method_config as method_table
from eval.experiments.cases.case_array import CaseTask, TaskEnd, run_case_array
from eval.experiments.cases.case_jobs import WorkerSetup, describe, job_count, run_case_jobs
from eval.experiments.cases.case_outputs import CaseOutputs
from eval.experiments.cases.case_plan import plan_runs, plan_speed, planned_root
from eval.experiments.cases.case_references import CaseReferences
from eval.experiments.cases.case_restore import keep_reproduced, leave_pending, named_change, restore
from eval.experiments.cases.pair import run_and_store
from eval.experiments.cases.reference_cutoff import scored_against
from eval.experiments.experiment_registry import register_experiment
from eval.metrics.meshes import CaseMeshes
from eval.present.breakdown import write_breakdown
from eval.run.code_identity import code_identity
from eval.run.compared import compared_rows, read_compared, run_settings
from eval.run.jsonsafe import json_safe
from eval.run.paths import abs_path
from eval.run.pending_rows import OTHER_CASE_DATA, STOP_AFTER_ENV, stop_after_s
from eval.run.progress import CostModel, default_cost_model, weighted_bar
from eval.run.result_store import ResultStore, case_identity, pair_key
from eval.run.runinfo import collect_runinfo, method_sources, write_runinfo
from eval.run.spec import EvalSpec
from eval.run.stale_rows import CommitTrees, RowState
from eval.run.subset import baseline_selection, method_selections, take_sample
from eval.tables import compare, write_tables
from harness.method_registry import method_meta
from harness.slurm_array import cluster_options
from sshade.errors import SShaDeError

__all__ = ["run"]

log = logging.getLogger("eval")


def run(spec: EvalSpec) -> dict:
    """Run the evaluation described by ``spec`` (the checked config, :func:`eval.config_check.check_config`).

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
    stop = stop_after_s()  # python -m eval.reproduce --budget: checked before any work
    if stop is not None and not (spec.output.resume and spec.jobs == 1):
        raise SShaDeError(f"{STOP_AFTER_ENV} needs resume=true (the pairs it leaves keep their stored rows) and "
                          "jobs=1 (the pairs start one by one in this process)")
    s = _setup(spec)
    s.deadline = None if stop is None else t_start + stop
    info = _start_runinfo(spec, s)
    rows = _run_cases(spec, s)
    return _finish(spec, s, rows, info, t_start)


@dataclass
class CaseSelection:
    """Which cases each method runs on: ``base`` (indices of the cases the baselines run
    on, None = all, :func:`eval.run.subset.baseline_selection`) and ``own`` (method name
    -> (indices or None, rule in words) for the methods ``method_cases`` gives a rule of
    their own, :func:`eval.run.subset.method_selections`)."""

    base: set | None
    own: dict

    def runs_on(self, ci: int, m) -> bool:
        """Baselines take minutes per high-res case: they run on the cases
        ``dataset.baseline_cases`` selects, a method whose file says ``cases: all``
        (:func:`harness.method_registry.method_meta`) on all, except a method ``method_cases``
        gives its own rule."""
        if m.name in self.own:
            sel = self.own[m.name][0]
            return sel is None or ci in sel
        return self.base is None or ci in self.base or method_meta(m.name)["cases"] == "all"


@dataclass
class _Setup:
    """What :func:`_setup` prepared before any method runs; ``jobs``, ``plan`` and
    ``resumed`` are set by :func:`_run_cases` once the runs to do are known."""

    methods: list                 # the built methods, in table order
    names: list[str]              # their names (row labels)
    specs: list[dict]             # each method's resolved definition (eval/run/result_store.py)
    codes: list[dict]             # each method's code identity, {with reference columns: identity} (code_identity.py)
    guard: dict                   # timeout_s, handle_error_max_pct (eval.run.spec.GuardOptions)
    refs: CaseReferences          # the reference columns' options and cache
    root: Path                    # the dataset's root
    out_dir: Path
    name: str                     # the dataset's name
    cases: list                   # its cases
    selection: CaseSelection      # which cases each method runs on
    base_rule: str                # dataset.baseline_cases in words
    sample_rule: str              # dataset.sample in words ("" without one)
    store: ResultStore
    resume: bool
    build: dict | None            # the dataset's build stage when one ran (plan.planned_root)
    seed: object = None           # dataset.seed (the cases' identity in the store)
    compared: list = field(default_factory=list)  # rows of earlier runs (compare_with; eval/run/compared.py)
    meshes: CaseMeshes = field(default_factory=CaseMeshes)  # the metrics' kept rest / ground-truth meshes
    jobs: int = 1
    plan: object = None           # plan.PlanRecord once logged
    resumed: dict | None = None   # restored / recomputed counts for run.json
    deadline: float | None = None  # perf_counter time after which no pair starts (pending_rows.STOP_AFTER_ENV)
    left: dict = field(default_factory=dict)  # (case, method) left at the deadline -> (why, commit, other data)
    cutoff: dict = field(default_factory=dict)  # (ci, mi) -> stored record kept if its reference is reproduced

    @property
    def base(self) -> set | None:
        return self.selection.base

    @property
    def own(self) -> dict:
        return self.selection.own

    def runs_on(self, ci: int, m) -> bool:
        """:meth:`CaseSelection.runs_on`."""
        return self.selection.runs_on(ci, m)


def _method_specs(entries, methods) -> list[dict]:
    """Each method's resolved definition (what its result depends on; :mod:`eval.run.result_store`):
    its entry's (:class:`eval.run.spec.MethodSpec`: ours as :func:`eval.config_check.method_definition`
    resolves it, a plug-in's ``_target_`` mapping as given), plus the method's ``key_extra``
    mapping when it has one (``inputs``: what else its rows depend on, e.g. the files
    :class:`eval.exchange.scored.ScoredResults` reads)."""
    out = []
    for e, m in zip(entries, methods):
        out.append({"class": f"{type(m).__module__}.{type(m).__qualname__}", "name": m.name,
                    **json_safe(dict(e.definition))})
        inputs = getattr(m, "key_extra", None)  # e.g. the digest of a scored results folder
        if isinstance(inputs, dict):
            out[-1]["inputs"] = json_safe(inputs)
    return out


def _setup(spec: EvalSpec) -> _Setup:
    """Every method built and checked, the guard and reference options, the dataset's
    root (may build DeFAUST) and cases, the baseline subset, the result store (emptied
    unless ``resume``), before any method runs."""
    methods = method_table.make_methods(spec.methods)  # every method's parameters are checked before any work
    specs = _method_specs(spec.methods, methods)
    ds = spec.dataset
    refs = CaseReferences(spec.reference)
    # fail fast, before the heavier imports; a DeFAUST build is planned (logged) first
    # (eval/experiments/cases/case_plan.py)
    mc = spec.method_cases
    root, build = planned_root(ds, spec.jobs, methods, refs, lambda cs, base: CaseSelection(
        base, method_selections(cs, mc, [x.name for x in methods])).runs_on)
    out_dir = abs_path(spec.output.out_dir)
    cases, sample_rule = take_sample(datasets.load_cases(ds.name, root, ds.options), ds.sample, ds.sample_seed)
    base, base_rule = baseline_selection(cases, ds.baseline_cases)
    names = [m.name for m in methods]  # checked when built; a plug-in cannot rename its row later
    own = method_selections(cases, mc, names)
    log.info("%d case(s) from %s; %s; methods %s; baselines on %s%s; output %s", len(cases), root, sample_rule,
             names, base_rule,
             "".join(f"; {n} on {rule}" for n, (_, rule) in own.items()), out_dir)
    compared = _compared(spec, cases, ds, out_dir)  # read and checked before any method runs
    # once each, for its rows with and without reference columns (eval/run/code_identity.py),
    # after the checks above: a refused dataset or folder is said without this work
    codes = [{on: code_identity(m, sp, references=on) for on in (True, False)} for m, sp in zip(methods, specs)]
    store = ResultStore(out_dir, meshes=spec.output.store_meshes, annotate=scored_against(refs, methods))
    store.check_links()  # a link in runs/ would take a resume's records outside out_dir
    if not spec.output.resume:
        n = store.clear()
        if n:
            log.info("resume=false: removed %d stored run(s) of an earlier run in %s", n, store.root)
    return _Setup(methods=methods, names=names, specs=specs, codes=codes, guard=spec.guard.as_dict(), refs=refs,
                  root=root, out_dir=out_dir, name=ds.name, cases=cases, selection=CaseSelection(base, own),
                  base_rule=base_rule, sample_rule=sample_rule if ds.sample is not None else "", store=store,
                  resume=spec.output.resume, build=build, seed=ds.seed, compared=compared)


def _compared(spec: EvalSpec, cases, ds, out_dir: Path) -> list:
    """The runs named by ``compare_with`` (folders relative to the launch directory; one
    named twice is read once), read and checked against ``cases`` of dataset ``ds`` and
    this run's settings (:func:`eval.run.compared.read_compared`); SShaDeError naming the
    folder when one is this run's own folder or cannot be compared."""
    out, seen = [], set()
    settings = run_settings(spec.record())
    for it in spec.output.compare_with:
        folder = abs_path(it)
        if folder == out_dir:
            raise SShaDeError(f"compare_with: {folder} is this run's own folder; name earlier runs")
        if folder.resolve() in seen:
            log.info("compare_with %s: named twice, read once", it)
            continue
        seen.add(folder.resolve())
        out.append(read_compared(folder, it, cases, dataset=ds.name, seed=ds.seed, settings=settings))
        log.info("compare_with %s: %d record(s) of %s%s", it, len(out[-1].rows), ", ".join(out[-1].methods),
                 f"; no record of {len(out[-1].missing)} case(s)" if out[-1].missing else "")
    return out


def _start_runinfo(spec: EvalSpec, s: _Setup) -> dict:
    """``run.json`` with status ``running``: the resolved config, the seeds (dataset,
    SShaDe, each case's, the dataset's own, e.g. a DeFAUST build's), each method's source
    file with its sha256 and git state (:func:`eval.run.runinfo.method_sources`)."""
    config = spec.record()
    config["dataset"]["root"] = str(s.root)
    seeds = {"dataset": s.seed, "sshade": (config.get("sshade") or {}).get("seed"),
             "cases": {c.name: getattr(c, "seed", None) for c in s.cases}}
    d = datasets.find_dataset(s.name)
    if d is not None and d.seeds is not None:
        seeds.update(d.seeds(s.root))
    extra = {"status": "running", "out_dir": str(s.out_dir), "method_sources": method_sources(s.methods),
             "code": code_identity(None)}
    if d is not None and d.provenance is not None:
        extra["dataset_build"] = d.provenance(s.root)
    info = collect_runinfo(config, seeds=seeds, extra=extra)
    write_runinfo(s.out_dir / "run.json", info)
    return info


def _pair_keys(s: _Setup, ci: int, case) -> list[tuple[str, dict]]:
    """The store keys (:func:`eval.run.result_store.pair_key`) of every method on case ``ci``: the
    method's definition, the case's identity, the guard and reference options, and the
    identity of the code that computes the row (:func:`eval.run.code_identity.code_identity`; the
    reference columns' code only where the case has them)."""
    ident = case_identity(case, dataset=s.name, seed=s.seed)
    on = s.refs.covers(ci, s.cases, s.base)
    extra = {"guard": s.guard, "reference": s.refs.settings(on)}
    return [pair_key(spec, ident, extra, code[on]) for spec, code in zip(s.specs, s.codes)]


def _run_cases(spec: EvalSpec, s: _Setup) -> list[dict]:
    """Every (case, method) run (:func:`eval.experiments.cases.pair.run_pair`) not already in
    the result store (``resume``; :mod:`eval.run.result_store`), each stored as soon as it finishes,
    with a progress bar weighted by each method's expected cost (:mod:`eval.run.progress`);
    in this process, or whole cases in ``jobs`` worker processes
    (:mod:`eval.experiments.cases.case_jobs`), or one task per case of a SLURM job array
    (``cluster``, :mod:`eval.experiments.cases.case_array`); ``cases.csv`` rewritten after each case, the
    optional figures and 3D views of the first cases. Returns the rows of every pair, in
    (case, method) order, as stored (an interrupted and resumed run, or one with other
    ``jobs``, gives the rows of an uninterrupted one)."""
    from tqdm.contrib.logging import logging_redirect_tqdm

    methods, names, cases = s.methods, s.names, s.cases
    plan = {ci: [mi for mi, m in enumerate(methods) if s.runs_on(ci, m)] for ci in range(len(cases))}
    keys = {ci: _pair_keys(s, ci, c) for ci, c in enumerate(cases)}
    # measured per-method priors (eval/run/progress.py), scaled to this machine (machine_speed.py),
    # probed again after a build of minutes (a VM's speed moves over tens of seconds)
    # (not probed for a plan of seconds: case_plan.plan_speed)
    built = s.build is not None and s.build.get("count", 0) > 0
    speed = plan_speed(methods, [(names[mi], len(cases[ci].V)) for ci, mis in plan.items() for mi in mis], again=built)
    cost = default_cost_model(methods, speed=speed["factor"])
    done = restore(s, plan, keys, cost) if s.resume else {}  # (ci, mi) -> stored record
    todo = [(ci, mi) for ci, mis in plan.items() for mi in mis if (ci, mi) not in done]
    est = {p: cost.estimate(names[p[1]], len(cases[p[0]].V)) for p in todo}
    array = spec.experiment.options  # the cluster section (case_array.py); None: the pairs run here
    n_cases = len({ci for ci, _ in todo})
    s.jobs = (job_count(spec.jobs, cases=n_cases, estimate_s=sum(est.values())) if array is None
              else max(1, min(array.array_parallelism, n_cases)))
    s.plan = plan_runs(s, todo, len(done), cost, jobs=s.jobs, speed=speed)  # the plan, before any run (case_plan.py)
    out = CaseOutputs(spec.figures, spec.report, s, plan, done, rerun=spec.figures.rerun_restored and array is None)
    bar = weighted_bar(sum(est.values()), len(todo))
    if array is not None and s.deadline is not None:
        raise SShaDeError(f"{STOP_AFTER_ENV} starts the pairs one by one in this process: not with a cluster section")
    with logging_redirect_tqdm(), bar:
        if array is not None:
            _run_in_array(spec, s, todo, keys, est, cost, bar, done, out)
        elif s.jobs > 1:
            _run_in_jobs(spec, s, todo, keys, est, cost, bar, done, out)
        else:
            for ci in range(len(cases)):
                s.refs.start_case(ci, cases[ci], s.refs.covers(ci, cases, s.base))
                fresh = {}
                for mi in plan[ci]:
                    if (ci, mi) not in done and s.deadline is not None and time.perf_counter() >= s.deadline:
                        leave_pending(s, ci, mi, keys[ci][mi], done)
                    elif (ci, mi) in s.cutoff and keep_reproduced(s, ci, mi, keys[ci][mi], done):
                        bar.retotal(bar.total - est[ci, mi])
                    elif (ci, mi) not in done:
                        bar.set_postfix_str(f"{todo.index((ci, mi)) + 1}/{len(todo)} runs: {cases[ci].name} "
                                            f"{names[mi]}")
                        done[ci, mi], fresh[mi] = _run_stored(s, ci, mi, keys[ci][mi], cost, bar)
                        bar.retotal(bar.n + sum(est[p] for p in todo[todo.index((ci, mi)) + 1:]))
                        bar.refresh()
                out.case_done(ci, fresh)
    out.redraw(s.deadline)  # the outputs waiting for reruns of restored runs (figures.rerun_restored)
    return out.rows(len(cases))


def _run_in_jobs(spec: EvalSpec, s: _Setup, todo, keys, est, cost: CostModel, bar, done: dict, out) -> None:
    """``todo`` in ``s.jobs`` worker processes, whole cases each, the costliest first
    (:func:`eval.experiments.cases.case_jobs.run_case_jobs`); the cases without runs to do get
    their outputs (figures, views) here."""
    by_case = _by_case(todo)
    order = sorted(by_case, key=lambda ci: (-sum(est[ci, mi] for mi in by_case[ci]), ci))
    tasks = [(ci, s.cases[ci], [(mi, *keys[ci][mi]) for mi in by_case[ci]],
              s.refs.covers(ci, s.cases, s.base), out.wants_meshes(ci)) for ci in order]
    n_done = [0]

    def on_pair(ci, mi, wall, cost_s):
        cost.observe(s.names[mi], len(s.cases[ci].V), cost_s)
        n_done[0] += 1
        bar.set_postfix_str(f"{n_done[0]}/{len(todo)} runs: {s.cases[ci].name} {s.names[mi]}")
        bar.advance(wall)

    def on_case(ci, pairs):
        for mi, rec, _ in pairs:
            done[ci, mi] = rec
        out.case_done(ci, {mi: U for mi, _, U in pairs})

    log.info("%d case(s) with runs to do in %d worker processes (%s)", len(tasks), s.jobs, describe(s.jobs))
    s.refs.computed_s += run_case_jobs(_worker_setup(spec, s), tasks, jobs=s.jobs, on_pair=on_pair, on_case=on_case,
                                       names=s.names)
    for ci in range(len(s.cases)):
        if ci not in by_case:
            out.case_done(ci, {})


def _by_case(todo) -> dict:
    """``{ci: [mi, ...]}`` of the ``(ci, mi)`` pairs ``todo``, in their order."""
    by_case: dict = {}
    for ci, mi in todo:
        by_case.setdefault(ci, []).append(mi)
    return by_case


def _worker_setup(spec: EvalSpec, s: _Setup) -> WorkerSetup:
    """What a worker process or an array task builds its methods, references, guard and store from."""
    return WorkerSetup(methods=spec.methods, reference=spec.reference, guard=s.guard, out_dir=str(s.out_dir),
                       store_meshes=spec.output.store_meshes)


def _run_in_array(spec: EvalSpec, s: _Setup, todo, keys, est, cost: CostModel, bar, done: dict, out) -> None:
    """``todo`` as one job array, a task per case (:func:`eval.experiments.cases.case_array.run_case_array`):
    each task's records (or failed rows for the pairs it did not store) into ``done`` as it
    ends, then its case's outputs; the cases without runs to do get theirs at the end."""
    by_case = _by_case(todo)
    tasks = [CaseTask(ci, s.cases[ci], tuple((mi, *keys[ci][mi]) for mi in mis), s.refs.covers(ci, s.cases, s.base),
                      out.wants_meshes(ci)) for ci, mis in by_case.items()]

    def on_end(end: TaskEnd) -> None:
        for mi, rec in end.records.items():
            done[end.ci, mi] = rec
            if "key" in rec:  # stored: a measured run
                cost.observe(s.names[mi], len(s.cases[end.ci].V), rec["row"].get("time_s"))
        bar.advance(sum(est[end.ci, mi] for mi in by_case[end.ci]))
        out.case_done(end.ci, end.fresh)

    if spec.jobs != 1:
        log.info("cluster: %d task(s), each running its case's pairs in turn (jobs is not used)", len(tasks))
    s.refs.computed_s += run_case_array(_worker_setup(spec, s), tasks, spec.experiment.options, store=s.store,
                                        names=s.names, on_end=on_end)
    for ci in range(len(s.cases)):
        if ci not in by_case:
            out.case_done(ci, {})


def _run_stored(s: _Setup, ci: int, mi: int, key: tuple[str, dict], cost: CostModel, bar):
    """One pair run and stored (:func:`eval.experiments.cases.pair.run_and_store`), timed into
    ``cost`` and ``bar``. Returns ``(record, U)``."""
    case, name = s.cases[ci], s.names[mi]
    rec, U, wall, cost_s = run_and_store(s.methods[mi], name, case, s.refs, s.guard, s.meshes, s.store, *key)
    cost.observe(name, len(case.V), cost_s)
    bar.advance(wall)  # a run longer than estimated never overfills the bar, nor sends it back
    return rec, U


def _data_mark(info: dict, left: dict) -> str:
    """The title's mark of a run's data (``run.json``'s ``dataset_build``, updated in
    place): its build's own mark, and the count of rows left pending from a run on other
    case data (``left``: :attr:`_Setup.left`), recorded as ``rows_on_other_data``, so a
    run on the canonical build does not vouch for the rows it did not make."""
    build = info.get("dataset_build")
    n = sum(1 for v in left.values() if v[2])
    if not isinstance(build, dict):
        return f"{n} pending row(s) made {OTHER_CASE_DATA} than this run's" if n else ""
    if n:
        words = f"{n} pending row(s) made {OTHER_CASE_DATA} than this build's"
        build.update(rows_on_other_data=n, mark=f"{build['mark']}; {words}" if build.get("mark") else words)
    return build.get("mark") or ""


def _finish(spec: EvalSpec, s: _Setup, rows, info, t_start) -> dict:
    """Tables (:func:`eval.tables.write_tables`; the title states the baseline rule) and
    breakdowns (:func:`eval.present.breakdown.write_breakdown`, with its figure when figures
    are enabled) from the stored rows, ``run.json`` with status ``done``, the Markdown
    table on stdout; the return value of :func:`run`."""
    import pandas as pd

    df = pd.DataFrame(rows)
    compile_s: dict[str, float] = {}  # method -> seconds of warm-up/compilation (run.json)
    for r in rows:
        if isinstance(r.get("compile_s"), (int, float)):
            compile_s[r["method"]] = compile_s.get(r["method"], 0.0) + r["compile_s"]
    exp = spec.experiment.name or s.name
    title = f"{exp}: {len(s.cases)} {s.name} case(s)" + (f"; {s.sample_rule}" if s.sample_rule else "")
    if s.base is not None and any(not s.runs_on(ci, m) for ci in range(len(s.cases)) for m in s.methods
                                  if m.name not in s.own):
        title += f"; full-resolution baselines on {s.base_rule}"
    title += "".join(f"; {n} on {rule}" for n, (sel, rule) in s.own.items() if sel is not None)
    title += _side_by_side(rows) + _presets(rows)
    mark = _data_mark(info, s.left)  # data other than its canonical build says so
    title += f"; {mark}" if mark else ""
    comp_rows = compared_rows(s.compared, s.names)
    pending = []
    if s.left:  # stopped early: the rows of the pairs left are marked pending
        log.warning("%s: %d stored row(s) left, marked pending in the tables (python -m eval.reproduce --check)",
                    STOP_AFTER_ENV, len(s.left))
        with CommitTrees() as trees:  # why each is stale: the modules changed since its commit
            left = {k: (named_change(s, *k, why, trees) + (f"; {OTHER_CASE_DATA} than this run's" if other else ""),
                        commit) for k, (why, commit, other) in s.left.items()}
        pending = [RowState(s.out_dir, r["case"], r["method"], (r["case"], r["method"]) in left,
                            *left.get((r["case"], r["method"]), ("", None))) for r in rows]
    paths = write_tables(df, s.out_dir, title=title, compared=pd.DataFrame(comp_rows) if comp_rows else None,
                         pending=pending)
    paths.update(write_breakdown(df, s.out_dir, figure=spec.figures.enabled))
    summ = compare(df).main  # every method on the same cases (eval.tables.compare)
    n_err = int((df["error"].astype(str).str.len() > 0).sum())
    info.update(status="done", n_cases=len(s.cases), n_rows=len(df), n_errors=n_err,
                wall_s=round(time.perf_counter() - t_start, 3), jobs=s.jobs,
                compile_s={k: round(v, 3) for k, v in compile_s.items()},
                outputs={k: Path(v).name for k, v in paths.items()}, plan=s.plan.finish(s.refs.computed_s),
                resumed=s.resumed, row_commits=_row_commits(s, info, len(df)),
                stopped=None if s.deadline is None else {"after_s": round(s.deadline - t_start, 3),
                                                         "left": len(s.left)})
    paths["run_json"] = write_runinfo(s.out_dir / "run.json", info)
    print(Path(paths["table_md"]).read_text())
    print(f"wrote {', '.join(Path(p).name for p in paths.values())} to {s.out_dir}")
    return {"out_dir": s.out_dir, "paths": paths, "n_cases": len(s.cases), "n_errors": n_err, "summary": summ}


def _row_commits(s: _Setup, info: dict, n_rows: int) -> dict:
    """``{commit: rows}``: the commits the table's rows came from (restored records keep
    the commit that computed them; the others are this run's, ``+dirty`` when it was)."""
    out = dict((s.resumed or {}).get("restored_commits") or {})
    git = info.get("git") if isinstance(info.get("git"), dict) else {}
    head = str(git.get("commit")) + ("+dirty" if git.get("dirty") else "")
    fresh = n_rows - sum(out.values())
    if fresh > 0:
        out[head] = out.get(head, 0) + fresh
    return out


def _presets(rows) -> str:
    """The title's words naming each method's preset (``preset`` column, e.g.
    Implicit-ARAP's), e.g. ``"; Implicit-ARAP: cpu preset"``: its row is that
    configuration, not the method's paper configuration."""
    got: dict[str, set] = {}
    for r in rows:
        if isinstance(r.get("preset"), str) and r["preset"]:
            got.setdefault(str(r["method"]), set()).add(r["preset"])
    return "".join(f"; {m}: {'/'.join(sorted(p))} preset" for m, p in sorted(got.items()))


def _side_by_side(rows) -> str:
    """The title's words for the rows timed in a worker beside others (``jobs`` > 1,
    their ``cores`` column), e.g. ``"; 46 of 46 runs side by side, 1 core each"``."""
    side = [r["cores"] for r in rows if isinstance(r.get("cores"), int)]
    if not side:
        return ""
    lo, hi = min(side), max(side)
    cores = f"{lo}" if lo == hi else f"{lo}-{hi}"
    return f"; {len(side)} of {len(rows)} runs side by side, {cores} core{'s' if hi != 1 else ''} each"


register_experiment("cases", run, section="cluster", options=cluster_options)
