"""The ``cases`` experiment's plan at work (the plan itself: :mod:`eval.run.plan`).

:func:`planned_root` stands for :func:`eval.datasets.dataset_root` in the experiment's
setup: when the dataset's preparation has long work ahead (a DeFAUST build,
:func:`eval.datasets.dataset_outlook`) it logs the plan first (the build, and the runs
and references estimated on the cases the build will make), then prepares the dataset
and times it. :func:`plan_runs` logs the plan of the runs once the pairs to run are known
(exact counts; the references found cached or not), before any method runs, and returns a
:class:`PlanRecord`, whose :meth:`PlanRecord.finish` logs each stage's actual time beside
its estimate and gives the ``plan`` entry of ``run.json``.
"""
from __future__ import annotations

import logging
import time
from pathlib import Path
from types import SimpleNamespace

from eval import datasets
from eval.experiments.cases.case_jobs import job_count
from eval.metrics.reference import reference_path
from eval.metrics.reference_scores import method_energy, sr_alpha
from eval.run.machine_speed import PROBE_MIN_PLAN_S, machine_speed
from eval.run.plan import add_actuals, build_stage, busy_words, make_plan, render_actuals, render_plan
from eval.run.progress import default_cost_model
from eval.run.spec import DatasetSpec
from eval.run.subset import baseline_selection, take_sample
from sshade.errors import SShaDeError

__all__ = ["planned_root", "plan_speed", "plan_runs", "PlanRecord"]

log = logging.getLogger("eval")


def _is_sr_energy(energy: str) -> bool:
    """Whether ``energy`` is ARAP-SR's (:func:`eval.metrics.reference_scores.sr_alpha`): the plan's
    rate for its references (:func:`eval.run.plan.make_plan`)."""
    return sr_alpha(energy) is not None


def planned_root(ds: DatasetSpec | None, jobs: int | None, methods, refs, runs_on) -> tuple[Path, dict | None]:
    """``(root, build)``: :func:`eval.datasets.dataset_root` of dataset ``ds``, with the plan
    logged first when the dataset has a build ahead; ``build`` is that build's stage
    (:func:`eval.run.plan.build_stage`, with ``actual_s``) or None when nothing was built.

    ``jobs``: the run's ``jobs`` (None: ``auto``); ``methods``: the built methods;
    ``refs``: the experiment's reference options (an object with ``settings(in_base) ->
    {"on": bool, ...}``); ``runs_on(cases, base)``: a predicate ``(ci, m) -> bool``,
    whether method ``m`` runs on case ``ci`` of ``cases`` given the baseline subset
    ``base`` (built once, so per-method rules are computed once).

    Raises
    ------
    SShaDeError from the outlook or the preparation (before any run).
    """
    out = datasets.dataset_outlook(ds)
    if out is None:
        return datasets.dataset_root(ds), None
    cases, _ = take_sample([SimpleNamespace(subject=s, pose=p, n_vertices=out["n_vertices"]) for s, p in out["cases"]],
                           ds.sample, ds.sample_seed)
    base, _ = baseline_selection(cases, ds.baseline_cases) if cases else (None, "")
    names = [m.name for m in methods]
    runs = runs_on(cases, base)
    pairs = [(ci, mi) for ci in range(len(cases)) for mi, m in enumerate(methods) if runs(ci, m)]
    on, need = set(pairs), []
    for ci, c in enumerate(cases):
        if refs.covers(ci, cases, base):
            energies = dict.fromkeys(method_energy(m) for mi, m in enumerate(methods) if (ci, mi) in on)
            need += [(c.n_vertices, e, None) for e in energies]
    speed = plan_speed(methods, [(names[mi], cases[ci].n_vertices) for ci, mi in pairs], build=out["subjects"] > 0)
    f, fb = speed["factor"], speed["build_factor"]
    build = build_stage(out["subjects"], workers=out["workers"], s_per_subject=out["s_per_subject"] * fb,
                        start_s=out.get("start_s", 0.0) * fb, what="DeFAUST", root=_short(out["root"]))
    cost = default_cost_model(methods, speed=f)
    est = sum(cost.estimate(names[mi], cases[ci].n_vertices) for ci, mi in pairs)
    try:
        jobs = job_count(jobs, cases=len({ci for ci, _ in pairs}), estimate_s=est)
    except SShaDeError:
        jobs = 1  # an invalid value is refused at the door (eval.config_check), before any work
    plan = make_plan(cases, names, pairs, cost, build=build, references=need, jobs=jobs, is_sr_energy=_is_sr_energy)
    plan["speed"] = speed
    log.info(render_plan(plan))
    t0 = time.perf_counter()
    root = datasets.dataset_root(ds)
    build["actual_s"] = round(time.perf_counter() - t0, 3)
    return root, build


def plan_speed(methods, runs, *, build: bool = False, again: bool = False) -> dict:
    """:func:`eval.run.machine_speed.machine_speed` for a plan: probed when a build is
    ahead or behind (``build``, ``again``: the runs probed again after it) or when the
    ``runs`` (a list of ``(method name, vertex count)``) of ``methods`` take
    :data:`~eval.run.machine_speed.PROBE_MIN_PLAN_S` or more at the priors; otherwise the
    readings this process has, else the priors as they are."""
    prior = default_cost_model(methods)
    long = build or again or sum(prior.estimate(name, n) for name, n in runs) >= PROBE_MIN_PLAN_S
    return machine_speed(build=build, again=again, probe=long)


def _short(path) -> str:
    """``path`` relative to the working directory when it is below it."""
    try:
        return str(Path(path).relative_to(Path.cwd()))
    except ValueError:
        return str(path)


class PlanRecord:
    """A logged plan and the clock of its runs: ``plan`` (:func:`eval.run.plan.make_plan`),
    ``t0`` (when the runs started)."""

    def __init__(self, plan: dict):
        self.plan, self.t0 = plan, time.perf_counter()

    def finish(self, references_s: float = 0.0) -> dict:
        """The plan with each stage's actual seconds (:func:`eval.run.plan.add_actuals`),
        logged beside the estimates; for ``run.json``. ``references_s``: the seconds spent
        computing references, summed over the worker processes; with ``jobs`` of them side
        by side the references stage is that sum over ``jobs`` (as the plan counts it), the
        runs the wall time since :attr:`t0` less it."""
        jobs = max(int(next((s.get("jobs", 1) for s in self.plan["stages"] if s["stage"] == "runs"), 1)), 1)
        runs, refs = time.perf_counter() - self.t0, float(references_s) / jobs
        out = add_actuals(self.plan, {"runs": max(runs - refs, 0.0), "references": refs})
        log.info(render_actuals(out))
        return out


def plan_runs(s, todo, restored: int, cost, *, speed: dict, jobs: int = 1) -> PlanRecord:
    """Log the plan of the runs about to start (before the first) and return its record.

    ``s``: the experiment's setup (``cases``, ``methods``, ``names``, ``base``, ``refs``
    with ``covers(ci, cases, base)``, ``cache``, ``max_iter``, ``time_budget_s``; ``build``:
    the build stage of :func:`planned_root` or None); ``todo``: the ``(ci, mi)`` pairs
    to run; ``restored``: pairs restored from the store; ``cost``: the cost model;
    ``jobs``: worker processes running whole cases side by side
    (:mod:`eval.experiments.cases.case_jobs`); ``speed``: what calibrated ``cost``
    (:func:`plan_speed`).
    """
    need = []
    for ci in dict.fromkeys(ci for ci, _ in todo):
        c = s.cases[ci]
        if not s.refs.covers(ci, s.cases, s.base):
            continue
        for e in dict.fromkeys(method_energy(s.methods[mi]) for cj, mi in todo if cj == ci):
            _, path = reference_path(c.V, c.F, c.handles, c.targets, energy=e, cache_dir=s.refs.cache,
                                     max_iter=s.refs.max_iter, time_budget_s=s.refs.time_budget_s)
            need.append((len(c.V), e, path.is_file()))
    build = getattr(s, "build", None)
    plan = make_plan(s.cases, s.names, todo, cost, build=build, references=need, restored=restored, jobs=jobs,
                     is_sr_energy=_is_sr_energy)
    plan["speed"] = speed
    log.info(render_plan(plan, head="plan, the cases built" if build is not None else "plan"))
    busy = busy_words()
    if busy:
        plan["busy"] = busy
        log.warning("plan: %s", busy)
    return PlanRecord(plan)
