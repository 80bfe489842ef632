"""The ``cases`` experiment's pairs as one SLURM job array (``cluster=slurm``), through submitit.
Floor 4 of eval/ (eval/experiments/, tests/test_layering.py); notes: docs/implementation.md.

One array task per case with runs to do (its methods in table order, its reference
computed once), each pair stored in the run's result store as it finishes
(:func:`eval.experiments.cases.pair.run_and_store`); this process waits for every task
(:func:`harness.slurm_jobs.wait_for_jobs`), reports how each ended, and reads the
records back from the store. Example::

    python -m eval dataset=faust dataset.root=DIR cluster=slurm cluster.partition=cpu"""
from __future__ import annotations

import functools
import logging
import sys
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from eval import method_config as method_table
from eval.experiments.cases.case_jobs import WorkerSetup
from eval.experiments.cases.case_references import CaseReferences
from eval.experiments.cases.pair import run_and_store, run_pair
from eval.experiments.cases.reference_cutoff import scored_against
from eval.metrics.meshes import CaseMeshes
from eval.run.jsonsafe import json_safe
from eval.run.outdir import resume_command
from eval.run.paths import abs_path
from eval.run.result_store import ResultStore
from harness.slurm_array import ClusterOptions, run_array
from harness.slurm_jobs import JobOutcome, killed_message
from sshade.cores import available_cores
from sshade.errors import SShaDeError

__all__ = ["CaseTask", "TaskEnd", "run_case_task", "missing_record", "run_case_array"]

log = logging.getLogger("eval")

@dataclass(frozen=True)
class CaseTask:
    """One array task: case ``ci`` (the case itself), its ``pairs`` to run ``(mi, key,
    key_fields)`` in table order (:func:`eval.run.result_store.pair_key`), whether it has
    reference columns (``ref_on``) and whether the task returns the deformed meshes
    (``want_meshes``: the first cases' figures and 3D views)."""

    ci: int
    case: Any
    pairs: tuple
    ref_on: bool
    want_meshes: bool = False


@dataclass
class TaskEnd:
    """How a task ended, as reported: ``status`` ``done``, ``failed`` (it raised) or
    ``killed`` (no result: OOM, time limit, node lost, cancelled, kill -9), ``message``
    (the error, empty when done), ``records`` (method index -> record: read from the store,
    or a failed row for a pair without one, :func:`missing_record`) and ``fresh`` (method
    index -> deformed vertices the task returned)."""

    ci: int
    status: str
    message: str = ""
    records: dict = field(default_factory=dict)
    fresh: dict = field(default_factory=dict)


def run_case_task(setup: WorkerSetup, task: CaseTask) -> dict:
    """In an array task: the methods of ``task.pairs`` on its case, each stored as it
    finishes (:func:`eval.experiments.cases.pair.run_and_store`; a method's failure is its
    row's ``error``, as in this process), with the ``eval`` log on stderr (the task's log).

    Parameters
    ----------
    setup : the methods' entries, reference options, guard, out_dir, ``store.meshes``.
    task : the case and its pairs.

    Returns
    -------
    dict ``{"ci", "stored": [method index, ...], "references_s", "meshes": {mi: (n, 3) or None}}``
    (meshes only when ``task.want_meshes``).

    Raises
    ------
    SShaDeError when the methods cannot be built (the task then fails; its pairs stay unstored).
    """
    lg = logging.getLogger("eval")
    if not lg.handlers:
        h = logging.StreamHandler(sys.stderr)
        h.setFormatter(logging.Formatter("%(asctime)s %(levelname)s %(message)s"))
        lg.addHandler(h)
        lg.setLevel(logging.INFO)
    methods = method_table.make_methods(setup.methods)
    refs = CaseReferences(setup.reference)
    store = ResultStore(abs_path(setup.out_dir), meshes=setup.store_meshes, annotate=scored_against(refs, methods))
    refs.start_case(task.ci, task.case, task.ref_on)
    meshes, stored, out = CaseMeshes(), [], {}
    for mi, key, fields in task.pairs:
        m = methods[mi]
        _, U, _, _ = run_and_store(m, m.name, task.case, refs, dict(setup.guard), meshes, store, key, fields,
                                   extra={"cores": available_cores()})
        stored.append(mi)
        if task.want_meshes:
            out[mi] = U
    return {"ci": task.ci, "stored": stored, "references_s": refs.computed_s, "meshes": out}


class _Missing:
    """Stands in for a method whose pair has no record after its task ended: fails with
    ``message``, so that its row is the one :func:`eval.experiments.cases.pair.run_pair`
    writes for any failed run."""

    def __init__(self, name: str, message: str):
        self.name, self.message = name, message

    def deform(self, V, F, handles, targets):
        raise SShaDeError(self.message)


def missing_record(case, name: str, message: str, cores: int | None = None) -> dict:
    """The record (``row``, ``info``, ``case``, ``method``) of method ``name`` on ``case``
    when its array task ended without storing it: a failed row (``error`` = ``message``),
    never stored, so that ``resume=true`` submits the pair again.

    Parameters
    ----------
    case : the evaluator case. name : the method's row label. message : the row's error.
    cores : the task's cores (the ``cores`` column of the array's rows).

    Returns
    -------
    dict, as :func:`eval.experiments.cases.pair.run_and_store` returns records (no ``key``).
    """
    row, _, _ = run_pair(_Missing(name, message), name, case, None, {"timeout_s": None, "handle_error_max_pct": None})
    row["cores"] = cores
    return {"row": json_safe(row), "info": {}, "case": case.name, "method": name}


def _task_end(task: CaseTask, outcome: JobOutcome, job_id: str, *, store: ResultStore, names: list,
              cores: int, log_hint: str) -> TaskEnd:
    """:class:`TaskEnd` of ``task`` from its ``outcome``: each pair's record read from
    ``store`` (:meth:`eval.run.result_store.ResultStore.lookup`), a failed row for each pair
    without one (:func:`missing_record`, naming how the task ended and its log)."""
    if outcome.kind == "result":
        status, msg = "done", ""
    elif outcome.kind == "error":
        last = str(outcome.value).strip().splitlines()[-1:] or ["error"]
        status, msg = "failed", f"array task {job_id} failed: {last[0]}"
    else:
        status, msg = "killed", f"array task {killed_message(outcome.state, job_id)}"
    end = TaskEnd(task.ci, status, msg)
    if outcome.kind == "result" and isinstance(outcome.value, dict):
        end.fresh = {mi: U for mi, U in (outcome.value.get("meshes") or {}).items() if U is not None}
    for mi, key, fields in task.pairs:
        found = store.lookup(task.case.name, names[mi], key, fields)
        if found.record is not None:
            end.records[mi] = found.record
            continue
        why = msg or f"array task {job_id} ended without storing this pair ({found.why})"
        end.records[mi] = missing_record(task.case, names[mi], f"{why}; no record of this pair ({log_hint})", cores)
    return end


def run_case_array(setup: WorkerSetup, tasks: list, options: ClusterOptions, *, store: ResultStore, names: list,
                   on_end: Callable) -> float:
    """Run ``tasks`` as one job array (:func:`run_case_task` each) and wait for every task.

    Each task's end is logged (done; failed with its error; killed with SLURM's last
    state) and handed to ``on_end`` with its pairs' records as stored; a pair without a
    record (its task killed or failed) gets a failed row, never stored (``resume=true``
    submits it again), and the pairs without record are listed at the end with the
    command that continues the run. Ctrl-C or SIGTERM cancels the tasks without result.

    Parameters
    ----------
    setup : what each task builds its methods, references, guard and store from.
    tasks : :class:`CaseTask` list, in submission order.
    options : the ``cluster`` section. store : the run's result store (``setup.out_dir``).
    names : the methods' names, by index. on_end : called ``on_end(TaskEnd)`` as each task ends.

    Returns
    -------
    float, the seconds the tasks that finished spent computing references.

    Raises
    ------
    SShaDeError when the array cannot be submitted (no ``sbatch``, refused by SLURM);
    KeyboardInterrupt after cancelling the array.
    """
    folder = abs_path(setup.out_dir) / options.folder
    ref_s, lost = [0.0], []

    def report(i: int, outcome: JobOutcome, job) -> None:
        jid, t = str(job.job_id), tasks[i]
        hint = f"log: {Path(job.paths.stderr).relative_to(abs_path(setup.out_dir)).as_posix()}"
        end = _task_end(t, outcome, jid, store=store, names=names, cores=options.cpus_per_task, log_hint=hint)
        if outcome.kind == "result" and isinstance(outcome.value, dict):
            ref_s[0] += float(outcome.value.get("references_s") or 0.0)
        gone = [names[mi] for mi, _, _ in t.pairs if "key" not in end.records[mi]]
        lost.extend(f"{t.case.name} {n}" for n in gone)
        say = log.info if end.status == "done" and not gone else log.warning
        say("array task %d/%d (case %s, job %s): %s%s%s", i + 1, len(tasks), t.case.name, jid, end.status,
            f": {end.message}" if end.message else "", f"; {len(gone)} pair(s) without record: {', '.join(gone)}"
            if gone else f"; {len(t.pairs)} pair(s) stored")
        on_end(end)

    run_array(functools.partial(run_case_task, setup), tasks, options, folder, name="sshade-table", what="one per case",
              report=report)
    if lost:
        log.warning("%d pair(s) have no record (their array task did not store them): %s; their rows are errors, "
                    "to run them again: %s", len(lost), "; ".join(lost), resume_command(setup.out_dir))
    return ref_s[0]
