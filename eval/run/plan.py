"""The evaluator's plan, up front: what a run is about to do, and about how long.
Floor 0 of eval/ (eval/run/, the ground floor, tests/test_layering.py); notes: docs/implementation.md.

Before any work the main job (:mod:`eval.experiments.cases.cases_experiment`, through
:mod:`eval.experiments.cases.case_plan`) logs one ``plan:`` line, e.g. ::

    plan: building DeFAUST (once, into data/defaust): 10 subjects x ~160 s on 1 worker, about 27 min;
    then 46 runs: ARAP 4 x ~78 s, Elastic 4 x ~75 s, ARAP-SR 4 x ~51 s,
    SShaDe 40 x ~9 s; references: up to 12 to compute, ~51 s each; about 50 min in all."""
from __future__ import annotations

import math
import os

from sshade.cores import available_cores

from .machine_speed import speed_words
from .progress import PRIOR_VERTICES, size_factor

__all__ = ["BUILD_S_PER_SUBJECT", "BUILD_START_S", "REFERENCE_S_PER_VERTEX", "SR_REFERENCE_S_PER_VERTEX",
           "REFERENCE_EXPONENT", "SR_REFERENCE_EXPONENT", "reference_s", "make_plan",
           "build_stage", "render_plan", "render_actuals", "add_actuals", "duration_words", "busy_words"]

#: Seconds to build one DeFAUST subject (ANNY rest mesh at 150k-200k vertices and its 4
#: poses) on a 2-core machine, two subjects at once, and the seconds each worker spends once
#: before its first subject (the ANNY model's preprocessing; the builder's numba kernels
#: compiled on a fresh machine), in the build probe's reference seconds
#: (:data:`eval.run.machine_speed.PROBE_REFERENCE_S`): fitted to builds with 2 workers of 2
#: subjects in 87.3 s and of 8 in about 352 s (numba's cache warm), and a fresh clone's 2 in
#: 117.7 s (benchmarks/records/machine_speed.md, "The solvers' probe"), then the subjects'
#: share times 0.8 for the sparse skinning blend and the finer self-intersection grid (2
#: subjects on 2 workers: 65.1 s against 80.1 s, the same bytes; benchmarks/records/
#: defaust_build_speed.md). A parallel build takes rounds of ``workers`` subjects.
BUILD_S_PER_SUBJECT = 68.0
BUILD_START_S = 10.0
#: Seconds per vertex of a deep reference solve (ARAP spokes or spokes-and-rims, continued
#: from the method's converged result, then its second-order probe), in the probe's reference
#: seconds: 91.5 s, the mean of DeFAUST's 4 spokes references (88-174 s, each probe finding
#: a lower energy) and 4 spokes-and-rims references (37-49 s) at 169k vertices, on a 2-core
#: EPYC whose machine probe read x0.9 (benchmarks/records/command_times.md, 2026-12-02; 47 s before
#: the probe).
REFERENCE_S_PER_VERTEX = 5.4e-4
#: The same for ARAP-SR's energy (Anderson-accelerated block descent, continued from the
#: method's converged result; not probed): 388 s, the mean of DeFAUST's 4 (214-478 s,
#: 513-1,098 iterations) in the same run.
SR_REFERENCE_S_PER_VERTEX = 2.3e-3
#: How those seconds grow with the vertices ``n`` about :data:`eval.run.progress.PRIOR_VERTICES`,
#: as ``n ** p`` (linear per vertex below that overestimated small meshes ninefold): fitted to
#: the rates above and FAUST's 6890-vertex references of the same code (mean 1.21 s ARAP's
#: two energies, 3.49 s ARAP-SR in the probe's reference seconds, a machine probe reading x0.91;
#: command_times.md, 2026-12-02).
REFERENCE_EXPONENT = 1.35
SR_REFERENCE_EXPONENT = 1.47


def busy_words(load: float | None = None, cores: int | None = None) -> str:
    """``""`` on an idle machine, else the sentence that says the plan's times assume one:
    busy when the 1-minute load average, less this process, is above half the cores this
    process may use (``load``, ``cores``: as measured now when None).

    >>> busy_words(0.9, 2), busy_words(3.2, 2)[:40]
    ('', 'the machine is busy (load average 3.2 on')
    """
    if load is None:
        try:
            load = os.getloadavg()[0]
        except (AttributeError, OSError):  # pragma: no cover - no load average on this OS
            return ""
    cores = cores or available_cores()
    if load - 1.0 <= 0.5 * cores:
        return ""
    return (f"the machine is busy (load average {load:.1f} on {cores} cores before this run): the times above "
            "are an idle machine's and will be longer")


def duration_words(seconds: float, *, about: bool = False) -> str:
    """``seconds`` in words: ``"0.4 s"``, ``"45 s"``, ``"12 min"``, ``"1.5 h"``; ``about``
    prefixes ``~`` (not to 0).

    >>> duration_words(0.44, about=True), duration_words(44.6), duration_words(700, about=True), duration_words(5400)
    ('~0.4 s', '45 s', '~12 min', '1.5 h')
    >>> duration_words(0, about=True), duration_words(100)
    ('0 s', '100 s')
    """
    s = max(float(seconds), 0.0)
    if s == 0:
        text = "0 s"
    elif s < 9.95:
        text = f"{s:.1f} s"
    elif s < 120:
        text = f"{s:.0f} s"
    elif s < 90 * 60:
        text = f"{s / 60:.0f} min"
    else:
        text = f"{s / 3600:.1f} h"
    return f"~{text}" if about and text != "0 s" else text


def _n_vertices(case) -> int:
    n = getattr(case, "n_vertices", None)
    return int(n) if n is not None else len(case.V)


def build_stage(subjects: int, *, workers: int = 1, s_per_subject: float = BUILD_S_PER_SUBJECT,
                start_s: float = 0.0, what: str = "DeFAUST", root: str = "") -> dict:
    """The ``build`` stage: ``subjects`` to build, in rounds of ``workers`` (>= 1; others
    count as 1), ``s_per_subject`` each, after ``start_s`` seconds of each worker's start-up
    (nothing when there is no subject to build).

    >>> build_stage(10, workers=4, s_per_subject=56.0)["seconds"]
    168.0
    >>> build_stage(4, workers=2, start_s=BUILD_START_S)["seconds"]
    146.0
    """
    w = int(workers) if isinstance(workers, int) and not isinstance(workers, bool) and workers >= 1 else 1
    n = max(int(subjects), 0)
    seconds = (float(start_s) + math.ceil(n / w) * float(s_per_subject)) if n else 0.0
    return {"stage": "build", "what": str(what), "root": str(root), "count": n, "workers": w,
            "s_per_subject": float(s_per_subject), "start_s": float(start_s), "seconds": round(seconds, 6)}


def _runs_stage(cases, names, pairs, cost, restored: int, jobs: int) -> dict:
    per: dict[str, dict] = {}
    per_case: dict[int, float] = {}
    for ci, mi in pairs:
        name = names[mi]
        d = per.setdefault(name, {"count": 0, "seconds": 0.0, "basis": _basis(cost, name)})
        d["count"] += 1
        t = float(cost.estimate(name, _n_vertices(cases[ci])))
        d["seconds"] += t
        per_case[ci] = per_case.get(ci, 0.0) + t
    for d in per.values():
        d["each_s"] = d["seconds"] / d["count"]
    order = [n for n in dict.fromkeys(names) if n in per]
    total = sum(d["seconds"] for d in per.values())
    return {"stage": "runs", "count": len(pairs), "restored": int(restored), "jobs": jobs,
            "seconds": _wall(total, per_case.values(), jobs), "methods": {n: per[n] for n in order}}


def _wall(total: float, items, jobs: int) -> float:
    """Wall seconds of work ``total`` (the sum of ``items``, whole cases) on ``jobs``
    workers: the larger of ``total / jobs`` and the longest item."""
    return max(total / jobs, max(items, default=0.0)) if jobs > 1 else total


def _basis(cost, name: str) -> str:
    f = getattr(cost, "basis", None)
    return f(name) if callable(f) else "prior"


def reference_s(n_vertices: int, sr: bool = False, speed: float = 1.0) -> float:
    """Expected seconds of one deep reference solve on ``n_vertices`` vertices (ARAP-SR's
    energy when ``sr``): :data:`REFERENCE_S_PER_VERTEX` (:data:`SR_REFERENCE_S_PER_VERTEX`)
    at :data:`eval.run.progress.PRIOR_VERTICES`, grown as ``n ** p`` with
    :data:`REFERENCE_EXPONENT` (:data:`SR_REFERENCE_EXPONENT`), times ``speed`` (this
    machine's factor, :func:`eval.run.machine_speed.machine_speed`).

    >>> round(reference_s(168_864)), round(reference_s(6_890), 2), round(reference_s(6_890, sr=True), 2)
    (91, 1.21, 3.52)
    """
    rate, p = (SR_REFERENCE_S_PER_VERTEX, SR_REFERENCE_EXPONENT) if sr else (REFERENCE_S_PER_VERTEX, REFERENCE_EXPONENT)
    return rate * PRIOR_VERTICES * size_factor(n_vertices, p) * float(speed)


def _references_stage(references, jobs: int = 1, is_sr_energy=None, speed: float = 1.0) -> dict:
    cached = to_compute = unknown = 0
    seconds = 0.0
    for n_vertices, energy, is_cached in references:
        if is_cached:
            cached += 1
            continue
        sr = is_sr_energy is not None and bool(is_sr_energy(energy))
        seconds += reference_s(n_vertices, sr, speed)
        if is_cached is None:
            unknown += 1
        else:
            to_compute += 1
    n = cached + to_compute + unknown
    each = seconds / (n - cached) if n > cached else 0.0
    return {"stage": "references", "count": n, "cached": cached, "to_compute": to_compute, "unknown": unknown,
            "seconds": _wall(seconds, [each], jobs), "each_s": each}


def make_plan(cases, names, pairs, cost, *, build: dict | None = None, references=(), restored: int = 0,
              jobs: int = 1, is_sr_energy=None) -> dict:
    """The plan of a run.

    Parameters
    ----------
    cases : sequence of cases (objects with ``V`` (n, 3), or an int ``n_vertices``).
    names : sequence of str, the method names; ``pairs`` index it.
    pairs : sequence of ``(ci, mi)``, the (case, method) pairs about to run.
    cost : an :class:`eval.run.progress.CostModel` (``estimate(name, n_vertices)`` seconds;
        ``basis(name)`` if it has one; its ``speed``, if it has one, scales the references'
        seconds as it does the priors').
    build : None (nothing to build) or a :func:`build_stage` dict (an ``actual_s`` in it:
        already done).
    references : sequence of ``(n_vertices, energy, cached)``, one per reference the runs
        need; ``cached`` True, False or None (not known yet: the cases are not built).
    restored : int, pairs restored from the result store (resume), not run again.
    jobs : int >= 1, worker processes running whole cases side by side
        (:mod:`eval.experiments.cases.case_jobs`): the runs' and references' wall time is the
        larger of their sum / ``jobs`` and the costliest case (each run's estimate stays
        the cost model's, measured on the whole machine).
    is_sr_energy : None (no energy is ARAP-SR's) or a callable ``energy -> bool`` telling
        ARAP-SR's energies, whose references cost :data:`SR_REFERENCE_S_PER_VERTEX` per
        vertex (the caller's, from :func:`eval.metrics.reference_scores.sr_alpha`:
        the plan knows no energy names).

    Returns
    -------
    dict ``{"stages": [build?, runs, references], "total_s": float}``; every stage has
    ``stage``, ``count`` and ``seconds`` (estimated), ``total_s`` their sum.

    Raises
    ------
    IndexError when a pair indexes outside ``cases`` or ``names``.

    Examples
    --------
    >>> from types import SimpleNamespace as C
    >>> from eval.run.progress import CostModel
    >>> p = make_plan([C(n_vertices=1000)] * 2, ["A", "S"], [(0, 0), (0, 1), (1, 1)],
    ...               CostModel({"S": "const"}, prior_const_s=2.0))
    >>> [(s["stage"], s["count"], s["seconds"]) for s in p["stages"]], p["total_s"]
    ([('runs', 3, 5.0), ('references', 0, 0.0)], 5.0)
    """
    stages = [dict(build)] if build is not None else []
    jobs = max(int(jobs), 1)
    stages.append(_runs_stage(cases, names, pairs, cost, restored, jobs))
    stages.append(_references_stage(references, jobs, is_sr_energy, float(getattr(cost, "speed", 1.0))))
    return {"stages": stages, "total_s": sum(s["seconds"] for s in stages if "actual_s" not in s)}


def _build_words(b: dict) -> str:
    where = f" into {b['root']}" if b.get("root") else ""
    if "actual_s" in b:
        return f"{b['what']} built{where} ({b['count']} subject(s), {duration_words(b['actual_s'])})"
    if not b["count"]:
        return f"{b['what']}{where} complete"
    workers = f"{b['workers']} worker" + ("s" if b["workers"] != 1 else "")
    start = f" after {duration_words(b['start_s'], about=True)} of start-up" if b.get("start_s") else ""
    return (f"building {b['what']} (once{',' + where if where else ''}): {b['count']} subject(s) x "
            f"{duration_words(b['s_per_subject'], about=True)} on {workers}{start}, "
            f"about {duration_words(b['seconds'])}")


def _runs_words(r: dict, then: bool) -> str:
    items = []
    for name, d in r["methods"].items():
        note = " (a guess, not measured yet)" if d["basis"] == "guess" else ""
        items.append(f"{name} {d['count']} x {duration_words(d['each_s'], about=True)}{note}")
    restored = f" ({r['restored']} restored from the store)" if r.get("restored") else ""
    side = f", {r['jobs']} at a time" if r.get("jobs", 1) > 1 else ""
    head = f"{'then ' if then else ''}{r['count']} run(s){restored}{side}"
    return f"{head}: {', '.join(items)}" if items else head


def _refs_words(f: dict) -> str:
    if not f["count"]:
        return "references: none"
    if f["unknown"]:
        return f"references: up to {f['unknown']} to compute, {duration_words(f['each_s'], about=True)} each"
    if f["to_compute"]:
        return (f"references: {f['cached']} cached, {f['to_compute']} to compute, "
                f"{duration_words(f['each_s'], about=True)} each")
    return f"references: {f['cached']} cached, 0 to compute"


def render_plan(plan: dict, *, head: str = "plan") -> str:
    """The plan on one line, ``head: stage; stage; ...; about T in all.`` (module
    docstring); a finished build stage reads as done and is not in the total; a plan with
    a ``speed`` entry (:func:`eval.run.machine_speed.machine_speed`) says what calibrated it."""
    parts = []
    by = {s["stage"]: s for s in plan["stages"]}
    b = by.get("build")
    if b is not None:
        parts.append(_build_words(b))
    parts.append(_runs_words(by["runs"], then=b is not None and "actual_s" not in b and b["count"] > 0))
    parts.append(_refs_words(by["references"]))
    speed = f" ({speed_words(plan['speed'])})" if plan.get("speed") else ""
    return f"{head}: {'; '.join(parts)}; about {duration_words(plan['total_s'])} in all{speed}."


def add_actuals(plan: dict, actual: dict) -> dict:
    """A copy of ``plan`` with ``actual_s`` (seconds) on each stage named in ``actual``
    (stage -> seconds; a build stage keeps the one it has) and ``actual_total_s``."""
    out = {**plan, "stages": [dict(s) for s in plan["stages"]]}
    for s in out["stages"]:
        if s["stage"] in actual and "actual_s" not in s:
            s["actual_s"] = round(float(actual[s["stage"]]), 3)
    out["actual_total_s"] = round(sum(s.get("actual_s", 0.0) for s in out["stages"]), 3)
    return out


def render_actuals(plan: dict) -> str:
    """One line: each stage's actual time beside its estimate (a plan from
    :func:`add_actuals`), e.g. ``time per stage: runs 3 s (planned ~5 s); ...``."""
    parts = [f"{s['stage']} {duration_words(s.get('actual_s', 0.0))} "
             f"(planned {duration_words(s['seconds'], about=True)})" for s in plan["stages"]]
    total = sum(s["seconds"] for s in plan["stages"])
    return (f"time per stage: {'; '.join(parts)}; in all {duration_words(plan.get('actual_total_s', 0.0))} "
            f"(planned {duration_words(total, about=True)})")
