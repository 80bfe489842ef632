"""The ``cases`` experiment's pairs as one SLURM job array (``cluster=slurm``), through submitit.
Floor 4 of eval/ (eval/experiments/, tests/test_layering.py); notes: docs/experiments.md.

One array task per case with runs to do (its methods in table order, its reference
computed once), each pair stored in the run's result store as it finishes
(:func:`eval.experiments.cases.pair.run_and_store`); this process waits for every task
(:func:`harness.slurm_jobs.wait_for_jobs`), reports how each ended, and reads the
records back from the store. Example::

    python -m eval dataset=faust dataset.root=DIR cluster=slurm cluster.partition=cpu"""
from __future__ import annotations

import contextlib
import logging
import os
import signal
import sys
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path, PurePosixPath
from typing import Any

from eval import method_config as method_table
from eval.experiments.cases.case_jobs import WorkerSetup
from eval.experiments.cases.case_references import CaseReferences
from eval.experiments.cases.pair import run_and_store, run_pair
from eval.metrics.meshes import CaseMeshes
from eval.run.jsonsafe import json_safe
from eval.run.outdir import resume_command
from eval.run.paths import abs_path
from eval.run.result_store import ResultStore
from harness.checks import config_number
from harness.jobs import THREAD_VARIABLES
from harness.slurm_jobs import JobOutcome, killed_message, slurm_states, wait_for_jobs
from sshade.cores import CORES_VARIABLE, available_cores
from sshade.errors import SShaDeError

__all__ = ["EXECUTORS", "ClusterOptions", "cluster_options", "CaseTask", "TaskEnd", "run_case_task",
           "missing_record", "run_case_array"]

log = logging.getLogger("eval")

#: ``cluster.executor``: submitit's SLURM executor, or its local one (every task a process
#: on this machine: the same path without a cluster, for checks).
EXECUTORS = ("slurm", "local")


@dataclass(frozen=True)
class ClusterOptions:
    """The ``cluster`` section (``conf/cluster/slurm.yaml`` says what each key does), checked."""

    executor: str
    partition: str | None
    account: str | None
    qos: str | None
    timeout_min: int
    cpus_per_task: int
    mem_gb: float | None
    array_parallelism: int
    setup: tuple[str, ...]
    additional_parameters: Mapping
    folder: str
    poll_s: float
    grace_polls: int
    unreachable_s: float


def _text(values: Mapping, key: str, *, allow_none: bool = True) -> str | None:
    """``values[key]``: a non-empty string (or None when allowed); SShaDeError naming ``cluster.<key>``."""
    v = values.get(key)
    if v is None and allow_none:
        return None
    if not isinstance(v, str) or not v.strip():
        raise SShaDeError(f"cluster.{key} must be a non-empty string{' or null' if allow_none else ''}, got {v!r}")
    return v


def cluster_options(values) -> ClusterOptions | None:
    """The ``cluster`` section's plain values checked and typed; the ``cases``
    experiment's own options (:func:`eval.experiments.register_experiment`).

    Parameters
    ----------
    values : mapping of every key of :class:`ClusterOptions` (``conf/cluster/slurm.yaml``),
        or None (no ``cluster``: the pairs run here).

    Returns
    -------
    :class:`ClusterOptions`, or None for ``values`` None.

    Raises
    ------
    SShaDeError naming the first absent or bad key (``folder`` must be a relative path
    inside out_dir).
    """
    if values is None:
        return None
    if not isinstance(values, Mapping):
        raise SShaDeError(f"cluster must be a mapping (cluster=slurm), got {values!r}")
    missing = [k for k in ClusterOptions.__dataclass_fields__ if k not in values]
    if missing:
        raise SShaDeError(f"cluster.{missing[0]} is not set (cluster=slurm sets every key)")
    if values["executor"] not in EXECUTORS:
        raise SShaDeError(f"cluster.executor must be one of {list(EXECUTORS)}, got {values['executor']!r}")
    cfg = {"cluster": dict(values)}
    folder = PurePosixPath(str(_text(values, "folder", allow_none=False)))
    if folder.is_absolute() or ".." in folder.parts or str(folder) in ("", "."):
        raise SShaDeError(f"cluster.folder must be a folder inside out_dir (a relative path), got {str(folder)!r}")
    setup = values["setup"] or ()
    extra = values["additional_parameters"] or {}
    if not isinstance(setup, (list, tuple)) or not all(isinstance(x, str) for x in setup):
        raise SShaDeError(f"cluster.setup must be a list of shell lines or null, got {setup!r}")
    if setup and values["executor"] == "local":  # a shell between this process and the task: Ctrl-C would miss it
        raise SShaDeError("cluster.setup is for SLURM tasks; the local executor's tasks take this process's "
                          "environment (set it before the command)")
    if not isinstance(extra, Mapping) or not all(isinstance(k, str) for k in extra):
        raise SShaDeError(f"cluster.additional_parameters must be a mapping of sbatch options, got {extra!r}")
    return ClusterOptions(
        executor=values["executor"], partition=_text(values, "partition"), account=_text(values, "account"),
        qos=_text(values, "qos"), timeout_min=config_number(cfg, "cluster.timeout_min", min=1),
        cpus_per_task=config_number(cfg, "cluster.cpus_per_task", min=1, max=4096),
        mem_gb=config_number(cfg, "cluster.mem_gb", kind=float, min=0.001, allow_none=True),
        array_parallelism=config_number(cfg, "cluster.array_parallelism", min=1),
        setup=tuple(setup), additional_parameters=dict(extra), folder=folder.as_posix(),
        poll_s=config_number(cfg, "cluster.poll_s", kind=float, min=0.01),
        grace_polls=config_number(cfg, "cluster.grace_polls", min=1, max=1000),
        unreachable_s=config_number(cfg, "cluster.unreachable_s", kind=float, min=0))


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
    store = ResultStore(abs_path(setup.out_dir), meshes=setup.store_meshes)
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


def _thread_caps(options: ClusterOptions) -> dict:
    """The environment that caps a task's threads at ``cpus_per_task``
    (:data:`harness.jobs.THREAD_VARIABLES`, :data:`sshade.cores.CORES_VARIABLE`)."""
    return {v: str(options.cpus_per_task) for v in (*THREAD_VARIABLES, CORES_VARIABLE)}


@contextlib.contextmanager
def _local_launch(options: ClusterOptions, log_path: Path):
    """Meanwhile, what a local task's process inherits: the thread caps
    (:func:`_thread_caps`) in the environment, and stdout / stderr to ``log_path`` (its
    controller's messages, e.g. when cancelled, go there, not to this command's output)."""
    values = _thread_caps(options)
    old = {k: os.environ.get(k) for k in values}
    log_path.parent.mkdir(parents=True, exist_ok=True)
    sys.stdout.flush()
    sys.stderr.flush()
    saved = [os.dup(1), os.dup(2)]
    try:
        os.environ.update(values)
        with open(log_path, "ab") as fh:
            os.dup2(fh.fileno(), 1)
            os.dup2(fh.fileno(), 2)
        yield
    finally:
        os.dup2(saved[0], 1)
        os.dup2(saved[1], 2)
        for fd in saved:
            os.close(fd)
        for k, v in old.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


def _executor(options: ClusterOptions, folder: Path):
    """submitit's executor for ``options`` writing its scripts and logs in ``folder``; a
    SLURM task's threads capped by its script (:func:`_thread_caps`), a local task's by
    the environment it inherits (no shell in between: a cancel reaches it)."""
    import submitit

    cap = [f"export {k}={v}" for k, v in _thread_caps(options).items()]
    ex = submitit.AutoExecutor(folder=str(folder / "%j"), cluster=options.executor)
    params: dict = {"timeout_min": options.timeout_min, "cpus_per_task": options.cpus_per_task,
                    "name": "sshade-table"}
    if options.mem_gb is not None:
        params["mem_gb"] = options.mem_gb
    if options.executor == "slurm":
        params.update(slurm_array_parallelism=options.array_parallelism, slurm_setup=[*cap, *options.setup],
                      slurm_additional_parameters=dict(options.additional_parameters))
        params.update({f"slurm_{k}": getattr(options, k) for k in ("partition", "account", "qos")
                       if getattr(options, k) is not None})
    ex.update_parameters(**params)
    return ex


def _states(options: ClusterOptions, jobs: list) -> Callable:
    """``(job ids) -> {id: state}`` for :func:`harness.slurm_jobs.wait_for_jobs`: SLURM's
    (:func:`harness.slurm_jobs.slurm_states`), or the local processes' (``RUNNING`` while alive)."""
    if options.executor == "slurm":
        return slurm_states
    by_id = {str(j.job_id): j for j in jobs}
    return lambda ids: {i: by_id[i].state for i in ids}


@contextlib.contextmanager
def _sigterm_interrupts():
    """SIGTERM raises KeyboardInterrupt meanwhile (in the main thread), as Ctrl-C does."""
    def raise_interrupt(signum, frame):
        raise KeyboardInterrupt

    try:
        old = signal.signal(signal.SIGTERM, raise_interrupt)
    except ValueError:  # not the main thread: SIGTERM keeps its handler
        yield
        return
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, old)


def _cancel(jobs: list, ended: set, options: ClusterOptions) -> None:
    """Cancel every job not in ``ended`` (``scancel`` through submitit; a local task gets
    SIGINT), logging one line; a failure to cancel is logged, never raised."""
    left = [j for i, j in enumerate(jobs) if i not in ended]
    for j in left:
        try:
            j.cancel(check=False)
        except Exception as e:  # noqa: BLE001 -- cancelling goes on for the others
            log.warning("could not cancel array task %s: %s", j.job_id, e)
    t_end = time.monotonic() + 10.0  # a local task's controller ends it (SIGINT, then SIGKILL after 1 s)
    while options.executor == "local" and any(j.state == "RUNNING" for j in left) and time.monotonic() < t_end:
        time.sleep(0.1)
    if left:
        log.warning("interrupted: cancelled %d array task(s) without result: %s", len(left),
                    " ".join(str(j.job_id) for j in left))


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
    try:
        with _local_launch(options, folder / "local.log") if options.executor == "local" else contextlib.nullcontext():
            jobs = _executor(options, folder).map_array(run_case_task, [setup] * len(tasks), tasks)
    except Exception as e:  # noqa: BLE001 -- sbatch missing, refused, a bad sbatch option
        raise SShaDeError(f"cluster: submitting the array failed: {' '.join(str(e).split())[-600:]}") from None
    log.info("submitted %d array task(s) (%s, one per case): %s; logs in %s", len(jobs), options.executor,
             " ".join(str(j.job_id) for j in jobs), folder)
    ends, ref_s, lost = set(), [0.0], []

    def report(i: int, outcome: JobOutcome) -> None:
        ends.add(i)
        jid, t = str(jobs[i].job_id), tasks[i]
        hint = f"log: {Path(jobs[i].paths.stderr).relative_to(abs_path(setup.out_dir)).as_posix()}"
        end = _task_end(t, outcome, jid, store=store, names=names, cores=options.cpus_per_task, log_hint=hint)
        if outcome.kind == "result" and isinstance(outcome.value, dict):
            ref_s[0] += float(outcome.value.get("references_s") or 0.0)
        gone = [names[mi] for mi, _, _ in t.pairs if "key" not in end.records[mi]]
        lost.extend(f"{t.case.name} {n}" for n in gone)
        say = log.info if end.status == "done" and not gone else log.warning
        say("array task %d/%d (case %s, job %s): %s%s%s", i + 1, len(jobs), t.case.name, jid, end.status,
            f": {end.message}" if end.message else "", f"; {len(gone)} pair(s) without record: {', '.join(gone)}"
            if gone else f"; {len(t.pairs)} pair(s) stored")
        on_end(end)

    try:
        with _sigterm_interrupts():
            wait_for_jobs(jobs, states=_states(options, jobs), poll_s=options.poll_s, grace_polls=options.grace_polls,
                          unreachable_s=options.unreachable_s, report=report)
    except KeyboardInterrupt:
        _cancel(jobs, ends, options)
        raise
    if lost:
        log.warning("%d pair(s) have no record (their array task did not store them): %s; their rows are errors, "
                    "to run them again: %s", len(lost), "; ".join(lost), resume_command(setup.out_dir))
    return ref_s[0]
